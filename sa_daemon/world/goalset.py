"""An ordered set of goals packed into padded arrays for vectorised evaluation.

Goals own different numbers of grasp poses; the arrays are padded to ``(G, K_max, ...)`` with poses
1 km away (and identity orientation) so that any min-distance or min-value reduction ignores the padding
without a mask.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ..geometry import FloatArray, Pose, quat_angle
from .goals import Goal

PAD_DISTANCE_M = 1000.0

SAME_POINT_M = 1e-6
"""Grasp poses of one goal closer than this (m) are listings of one grasp point (:attr:`GoalSet.same_point`)."""


@dataclass(frozen=True, eq=False)
class GoalSet:
    """Goals in a fixed order with padded pose arrays and the high-level target of each goal."""

    goals: tuple[Goal, ...]

    def __post_init__(self) -> None:
        object.__setattr__(self, "goals", tuple(self.goals))
        if not self.goals:
            raise ValueError("a goal set needs at least one goal")

    def __len__(self) -> int:
        return len(self.goals)

    @cached_property
    def positions(self) -> FloatArray:
        """``(G, K, 3)`` grasp positions (m), padded far away."""
        k = max(len(g.poses) for g in self.goals)
        out = np.full((len(self.goals), k, 3), PAD_DISTANCE_M)
        for i, g in enumerate(self.goals):
            out[i, : len(g.poses)] = g.positions
        out.setflags(write=False)
        return out

    @cached_property
    def quats_wxyz(self) -> FloatArray:
        """``(G, K, 4)`` grasp orientations, padded with identity."""
        k = max(len(g.poses) for g in self.goals)
        out = np.zeros((len(self.goals), k, 4))
        out[..., 0] = 1.0
        for i, g in enumerate(self.goals):
            out[i, : len(g.poses)] = g.quats_wxyz
        out.setflags(write=False)
        return out

    @cached_property
    def pose_mask(self) -> np.ndarray:
        """``(G, K)``: which entries of the padded pose arrays are grasp poses (``False``: padding)."""
        k = max(len(g.poses) for g in self.goals)
        out = np.arange(k)[None, :] < np.array([len(g.poses) for g in self.goals])[:, None]
        out.setflags(write=False)
        return out

    @cached_property
    def same_point(self) -> np.ndarray:
        """``(G, K, K)``: which of a goal's grasp poses share a grasp point (position within ``SAME_POINT_M``)
        with which, padding with none: the scenes list each grasp at two yaws half a turn apart
        (``docs/scenes.md``), and a sphere's at several."""
        d = np.linalg.norm(self.positions[:, :, None, :] - self.positions[:, None, :, :], axis=-1)
        out = (d <= SAME_POINT_M) & self.pose_mask[:, :, None] & self.pose_mask[:, None, :]
        out.setflags(write=False)
        return out

    @cached_property
    def targets(self) -> tuple[str, ...]:
        """Distinct high-level targets in order of first appearance."""
        return tuple(dict.fromkeys(g.target for g in self.goals))

    @cached_property
    def target_index(self) -> np.ndarray:
        """``(G,)`` index into :attr:`targets` of each goal's high-level target."""
        pos = {t: i for i, t in enumerate(self.targets)}
        return np.array([pos[g.target] for g in self.goals], dtype=int)

    def target_mask(self, target: str) -> np.ndarray:
        """``(G,)`` bool: which goals belong to high-level ``target`` (all False if unknown)."""
        if target not in self.targets:
            return np.zeros(len(self.goals), dtype=bool)
        return self.target_index == self.targets.index(target)

    def _pose_distances(self, pose: Pose, rotation_weight_m_per_rad: float) -> FloatArray:
        """``(G, K)``: ``d_trans + w d_rot`` (m) from ``pose`` to every grasp pose (padding 1 km away)."""
        d = np.linalg.norm(self.positions - pose.position, axis=-1)
        return d + rotation_weight_m_per_rad * quat_angle(self.quats_wxyz, pose.quat_wxyz)

    def desired_indices(self, pose: Pose, rotation_weight_m_per_rad: float) -> np.ndarray:
        """Index of ``k_c`` (closest grasp pose, ``d_trans + w d_rot``) within each goal, ``(G,)``."""
        return np.argmin(self._pose_distances(pose, rotation_weight_m_per_rad), axis=-1)

    def desired_poses(self, pose: Pose, rotation_weight_m_per_rad: float,
                      lender_score: FloatArray | None = None) -> tuple[FloatArray, FloatArray]:
        """``k_c`` of every goal as arrays ``((G, 3), (G, 4))``.

        ``lender_score`` ``(G,)``: the copies resampling made of one high-level target all take the ``k_c`` of
        the copy with the lowest score (``intent.copy_reach``); ``None``: each goal its own."""
        return self.poses_at(self.desired_indices(pose, rotation_weight_m_per_rad), lender_score)

    def poses_at(self, k: np.ndarray, lender_score: FloatArray | None = None) -> tuple[FloatArray, FloatArray]:
        """Pose ``k[g]`` of every goal ``g`` as arrays ``((G, 3), (G, 4))``; ``k`` ``(G,)`` indices into each
        goal's poses.

        ``lender_score`` ``(G,)``: the copies of one high-level target all take the pose of the copy with the
        lowest score (``intent.copy_reach``); ``None``: each goal its own."""
        rows = np.arange(len(self.goals))
        if lender_score is not None:
            owner = rows.copy()
            for members in (np.flatnonzero(self.target_index == t) for t in range(len(self.targets))):
                owner[members] = members[np.argmin(np.asarray(lender_score)[members])]
            rows, k = owner, np.asarray(k)[owner]
        return self.positions[rows, k], self.quats_wxyz[rows, k]

    def desired_distances(self, pose: Pose, rotation_weight_m_per_rad: float) -> FloatArray:
        """``(G,)``: ``d_trans + w d_rot`` (m) from ``pose`` to each goal's ``k_c``."""
        return np.min(self._pose_distances(pose, rotation_weight_m_per_rad), axis=-1)

    def target_sums(self, probs: FloatArray) -> FloatArray:
        """``(len(targets),)``: each high-level target's probability (summed over its copies), in
        :attr:`targets` order."""
        return np.bincount(self.target_index, weights=probs, minlength=len(self.targets))

    def target_probabilities(self, probs: FloatArray) -> dict[str, float]:
        """Probability of each high-level target (summed over its copies), by name."""
        return {t: float(p) for t, p in zip(self.targets, self.target_sums(probs))}
