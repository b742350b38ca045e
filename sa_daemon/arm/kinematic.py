"""A gripper-only arm that integrates the commanded twist on SE(3): fast and exact, for evaluation."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..config import LimitsConfig
from ..geometry import FloatArray, Pose, integrate_pose
from .base import Arm, ArmState, commanded_twist

if TYPE_CHECKING:
    from ..config import Config
    from ..world.scene import Scene


class KinematicArm(Arm):
    """The TCP follows the commanded twist exactly, within the configured per-axis speed limits."""

    name = "kinematic"

    @classmethod
    def from_config(cls, scene: Scene, cfg: Config) -> KinematicArm:
        return cls(scene.start, cfg.limits)

    def __init__(self, start: Pose, limits: LimitsConfig | None = None) -> None:
        self._limits = limits or LimitsConfig()
        self._start = start
        self._pos = np.array(start.position)
        self._quat = np.array(start.quat_wxyz)
        self._twist = np.zeros(6)
        self._closed = False

    def read(self) -> ArmState:
        return ArmState(Pose(self._pos, self._quat), self._closed)

    def reset(self) -> bool:
        self._pos, self._quat = np.array(self._start.position), np.array(self._start.quat_wxyz)
        self._twist = np.zeros(6)
        self._closed = False
        return True

    def command_twist(self, twist: FloatArray) -> None:
        self._twist = commanded_twist(twist, self._limits)

    def command_gripper(self, closed: bool) -> None:
        """Open or close the gripper (instantly). Motion is not gated here: like the xArm, the arm moves
        whatever it holds; holding it still while the gripper is closed is the safety pipeline's stage."""
        self._closed = bool(closed)

    def step(self, dt: float) -> None:
        self._pos, self._quat = integrate_pose(self._pos, self._quat, self._twist, dt)
