"""Build the configured arm backend by name (``kinematic``, ``mujoco``, ``xarm``).

Backends are imported lazily so that the kinematic arm needs neither MuJoCo nor the xArm SDK.
"""

from __future__ import annotations

from ..config import Config
from ..planner.scene import Scene
from .base import Arm

BACKENDS = ("kinematic", "mujoco", "xarm")
JOINTED_BACKENDS = ("mujoco", "xarm")
"""Backends with joints (``Arm.kinematics``): the xArm-6 model, its bounds and singularities."""


def make_arm(backend: str, scene: Scene, cfg: Config) -> Arm:
    """A fresh arm of ``backend`` holding the TCP at ``scene.start`` (simulated arms) - raises
    ``ValueError`` for an unknown backend."""
    if backend == "kinematic":
        from .kinematic import KinematicArm

        return KinematicArm(scene.start, cfg.limits)
    if backend == "mujoco":
        from .mujoco_arm import MujocoArm

        return MujocoArm(scene, cfg)
    if backend == "xarm":
        from .xarm_arm import XArm

        return XArm(cfg)
    raise ValueError(f"unknown arm backend {backend!r} (one of {', '.join(BACKENDS)})")
