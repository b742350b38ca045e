"""Which grasp poses an arm with joints can really reach: inverse kinematics against the joint bounds.

The scene loader's :func:`~sa_daemon.world.grasps.is_reachable` is a sphere around the shoulder: right
for the gripper-only kinematic arm, too generous for the xArm-6, whose joint 5 stops at -1.69 rad. Some
side grasps inside the sphere (head-on, close to the table) would need it beyond that bound; a user
driving toward one ends at the joint margin (``joint_bound``) and never gets there. So for arms with
joints (MuJoCo, xArm) the goals keep only poses with an inverse-kinematics solution inside the bounds
less ``safety.joint_margin_rad``. The same filter serves the daemon and ``sa-daemon eval --arm mujoco``,
so planner, simulated user and arm agree on the goals.
"""

from __future__ import annotations

import logging
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from ..geometry import FloatArray, Pose
from ..world.goals import Goal
from ..world.scene import Scene

if TYPE_CHECKING:  # Pinocchio (about 50 MB resident) loads only for arms with joints
    from .kinematics import ArmKinematics

log = logging.getLogger(__name__)


def reaches(kin: ArmKinematics, pose: Pose, q_start: FloatArray, margin_rad: float) -> bool:
    """True if IK seeded at ``q_start`` puts the TCP at ``pose`` with every joint at least ``margin_rad``
    inside its bounds.

    Seeded at the start only, so the solution stays on the start's wrist branch: a pose reachable only
    by the other branch (joint 4 turned by pi, joint 5 mirrored) cannot be reached by driving from the
    start, since joint 5 meets its -1.69 rad bound on the way.
    """
    from .kinematics import IKError

    try:
        q = kin.ik(pose, q_start, tol_m=1e-4, tol_rad=1e-3)
    except IKError:
        return False
    return bool(np.all(q >= kin.lower + margin_rad) and np.all(q <= kin.upper - margin_rad))


def _restrict(scene: Scene, kin: ArmKinematics, margin_rad: float) -> tuple[list[Goal], list[Goal]]:
    """``(goals with their reachable poses only, goals with none)`` of ``scene``."""
    from .kinematics import start_configuration

    q_start = start_configuration(kin, scene.start)
    kept_goals: list[Goal] = []
    dropped: list[Goal] = []
    for g in scene.goals:
        kept = tuple(p for p in g.poses if reaches(kin, p, q_start, margin_rad))
        if not kept:
            dropped.append(g)
            continue
        if len(kept) < len(g.poses):
            log.info("%s: %d of %d grasp poses reachable by the arm", g.target, len(kept), len(g.poses))
        kept_goals.append(g if len(kept) == len(g.poses) else replace(g, poses=kept))
    return kept_goals, dropped


def reachable_scene(scene: Scene, kin: ArmKinematics, margin_rad: float) -> Scene:
    """``scene`` with each goal's poses restricted to those :func:`reaches` accepts.

    Raises ``ValueError`` naming the goal if one keeps no pose: that task cannot be done on this arm.
    """
    goals, dropped = _restrict(scene, kin, margin_rad)
    if dropped:
        raise ValueError(
            f"scene {scene.name!r}: no grasp pose of {dropped[0].target} is reachable by the xArm-6 within its joint "
            f"bounds less {margin_rad} rad (safety.joint_margin_rad)"
        )
    return replace(scene, goals=tuple(goals))


def reachable_goals(scene: Scene, kin: ArmKinematics, margin_rad: float) -> tuple[Scene, list[dict[str, str]]]:
    """``scene`` with each goal's poses restricted to the reachable ones, and goals with none dropped:
    ``(scene, [{"target": ..., "reason": ...}])`` (a live scene from a camera: some of its grasps may be
    out of reach; the rest can still be driven to). ``ValueError`` if no goal is left."""
    goals, dropped = _restrict(scene, kin, margin_rad)
    if not goals:
        raise ValueError(f"scene {scene.name!r}: no goal is reachable by the xArm-6")
    reasons = [{"target": g.target, "reason": f"none of its {len(g.poses)} grasp poses is reachable by the xArm-6 "
                f"within its joint bounds less {margin_rad} rad"} for g in dropped]
    return replace(scene, goals=tuple(goals)), reasons
