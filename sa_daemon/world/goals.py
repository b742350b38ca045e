"""Goals: a high-level target (object, grasp type) with its low-level target (a list of grasp poses).

Section III-A of the paper. A user's goal ``g = <o, theta_o, K>``; the desired pose ``k_c`` of a goal is the
grasp pose in ``K`` closest to the current gripper pose (translation plus weighted rotation distance).
After resampling (section III-G) several goals may share one high-level target, each with a disjoint
subset of its grasp poses; :attr:`Goal.target` names the shared target.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from enum import Enum
from functools import cached_property

import numpy as np

from ..geometry import FloatArray, Pose, quat_angle


class GraspType(str, Enum):
    """Grasp types, classified from the tool frame (z = approach, y = fingers' closing axis).

    * ``top``: approach within 30 deg of straight down; ``side``: within 30 deg of horizontal.
    * ``side_horizontal`` / ``side_vertical``: closing axis horizontal / vertical.
    * ``top_horizontal`` / ``top_vertical``: closing along the base y / x axis (left-right / fore-aft seen
      from the robot).
    """

    TOP = "top"
    SIDE = "side"
    TOP_HORIZONTAL = "top_horizontal"
    TOP_VERTICAL = "top_vertical"
    SIDE_HORIZONTAL = "side_horizontal"
    SIDE_VERTICAL = "side_vertical"

    @property
    def is_top(self) -> bool:
        return self.value.startswith("top")


def parse_target(text: str) -> tuple[str, GraspType]:
    """Split a task name ``"object:grasp_type"`` (e.g. ``"cup:top"``); raises ``ValueError`` if malformed."""
    obj, sep, kind = text.rpartition(":")
    if not sep or not obj:
        raise ValueError(f"task {text!r} must be 'object:grasp_type', e.g. 'cup:top'")
    try:
        return obj, GraspType(kind.strip())
    except ValueError:
        names = ", ".join(t.value for t in GraspType)
        raise ValueError(f"task {text!r}: unknown grasp type {kind!r} (one of {names})") from None


def target_object(target: str) -> str:
    """The object of a target name: ``"cup:top"`` -> ``"cup"`` (a name without a grasp type is its object)."""
    return target.partition(":")[0]


def object_probabilities(target_probabilities: Mapping[str, float]) -> dict[str, float]:
    """The belief summed per object: ``{"cup": p(cup:top) + p(cup:side), ...}`` from target probabilities
    keyed ``"object:grasp_type"`` (in their order of first appearance)."""
    out: dict[str, float] = {}
    for target, p in target_probabilities.items():
        obj = target_object(target)
        out[obj] = out.get(obj, 0.0) + float(p)
    return out


@dataclass(frozen=True, eq=False)
class Goal:
    """One goal: ``object`` name, ``grasp_type`` and its grasp ``poses`` (base frame, at least one)."""

    object: str
    grasp_type: GraspType
    poses: tuple[Pose, ...] = field(repr=False)

    def __post_init__(self) -> None:
        if not self.object or ":" in self.object:
            raise ValueError(f"object name {self.object!r} must be non-empty and contain no ':'")
        object.__setattr__(self, "grasp_type", GraspType(self.grasp_type))
        object.__setattr__(self, "poses", tuple(self.poses))
        if not self.poses:
            raise ValueError(f"goal {self.target} has no grasp poses")

    @property
    def target(self) -> str:
        """High-level target name, ``"object:grasp_type"``."""
        return f"{self.object}:{self.grasp_type.value}"

    @cached_property
    def positions(self) -> FloatArray:
        """Grasp positions, shape (K, 3), m."""
        a = np.stack([p.position for p in self.poses])
        a.setflags(write=False)
        return a

    @cached_property
    def quats_wxyz(self) -> FloatArray:
        """Grasp orientations, shape (K, 4), wxyz."""
        a = np.stack([p.quat_wxyz for p in self.poses])
        a.setflags(write=False)
        return a

    def pose_distances(self, pose: Pose, rotation_weight_m_per_rad: float) -> FloatArray:
        """Weighted distance (m) from ``pose`` to each grasp pose: ``d_trans + w * d_rot``."""
        d_t = np.linalg.norm(self.positions - pose.position, axis=-1)
        d_r = quat_angle(self.quats_wxyz, pose.quat_wxyz)
        return d_t + rotation_weight_m_per_rad * d_r

    def desired_pose(self, pose: Pose, rotation_weight_m_per_rad: float) -> Pose:
        """``k_c``: the grasp pose closest to the gripper ``pose`` (section III-A)."""
        return self.poses[int(np.argmin(self.pose_distances(pose, rotation_weight_m_per_rad)))]

    def with_poses(self, poses: tuple[Pose, ...]) -> Goal:
        """A copy of this high-level target owning only ``poses`` (used by redistribution)."""
        return Goal(self.object, self.grasp_type, poses)

    def to_dict(self) -> dict:
        """Plain form for snapshots and JSON."""
        return {
            "object": self.object,
            "grasp_type": self.grasp_type.value,
            "poses": [p.as_dict() for p in self.poses],
        }

    @classmethod
    def from_dict(cls, d: dict) -> Goal:
        return cls(d["object"], GraspType(d["grasp_type"]), tuple(Pose.from_dict(p) for p in d["poses"]))

    def __repr__(self) -> str:
        return f"Goal({self.target}, {len(self.poses)} poses)"
