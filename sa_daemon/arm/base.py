"""The arm interface every backend implements (kinematic, MuJoCo, xArm).

Small on purpose: read the state, hold a base-frame twist until the next command, open or close the
gripper, and - for simulated arms - advance time. Units are SI (m/s, rad/s); conversion to a vendor's
units happens inside a driver only.
"""

from __future__ import annotations

import abc
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

import numpy as np

from ..geometry import FloatArray, Pose, as_twist

if TYPE_CHECKING:
    from ..config import Config, LimitsConfig
    from ..world.scene import Scene


@dataclass(frozen=True)
class ArmState:
    """What an arm reports: TCP ``pose`` (base frame), gripper state, a fault text or ``None``, and the
    joint positions (rad) of an arm that has joints (``None`` for the gripper-only kinematic arm)."""

    pose: Pose
    gripper_closed: bool
    fault: str | None = None
    joints: FloatArray | None = None


@runtime_checkable
class Kinematics(Protocol):
    """Joint-space kinematics of a serial arm's TCP, as the safety pipeline needs it.

    ``lower``/``upper`` are joint position bounds (rad), ``velocity_limit`` joint speed limits (rad/s).
    """

    lower: FloatArray
    upper: FloatArray
    velocity_limit: FloatArray

    def fk(self, q: FloatArray) -> Pose:
        """TCP pose (base frame) at joint positions ``q`` (rad)."""

    def jacobian(self, q: FloatArray) -> FloatArray:
        """6 x n TCP Jacobian mapping joint velocities (rad/s) to the base-frame twist [v (m/s); w (rad/s)]."""

    def joint_velocities(self, q: FloatArray, twist: FloatArray) -> FloatArray:
        """Joint velocities (rad/s) realising ``twist`` at ``q`` (damped least squares)."""


def speed_scales(twist: FloatArray, linear_mps: float, angular_radps: float, tcp_mps: float = math.inf
                 ) -> tuple[float, float]:
    """The factors (each in (0, 1]) by which the linear and the angular part of ``twist`` must be scaled
    so that no axis exceeds its limit (m/s, rad/s) and the linear part's norm does not exceed
    ``tcp_mps`` (m/s)."""
    t = np.asarray(twist, dtype=float)
    peak_lin, peak_ang = float(np.max(np.abs(t[:3]))), float(np.max(np.abs(t[3:])))
    speed = float(np.linalg.norm(t[:3]))
    lin = min(linear_mps / peak_lin if peak_lin > linear_mps else 1.0, tcp_mps / speed if speed > tcp_mps else 1.0)
    return lin, (angular_radps / peak_ang if peak_ang > angular_radps else 1.0)


def limit_twist(twist: FloatArray, linear_mps: float, angular_radps: float, tcp_mps: float = math.inf) -> FloatArray:
    """``twist`` with each part scaled by its :func:`speed_scales` factor, keeping each part's direction."""
    t = np.array(twist, dtype=float)
    lin, ang = speed_scales(t, linear_mps, angular_radps, tcp_mps)
    if lin < 1.0:
        t[:3] *= lin
    if ang < 1.0:
        t[3:] *= ang
    return t


def commanded_twist(twist: FloatArray, limits: LimitsConfig) -> FloatArray:
    """A backend's last guard on a commanded ``twist`` (m/s, rad/s): ``ValueError`` (the arm changes
    nothing) unless it is 6 finite numbers, then :func:`limit_twist` to the configured ``limits``."""
    return limit_twist(as_twist(twist), limits.linear_mps, limits.angular_radps, limits.tcp_mps)


class Arm(abc.ABC):
    """A robot arm driven by Cartesian twists."""

    name: str = "arm"
    #: Joint-space kinematics for the safety pipeline (singularity and joint-margin stages); ``None`` for
    #: an arm without joints.
    kinematics: Kinematics | None = None

    @classmethod
    @abc.abstractmethod
    def from_config(cls, scene: Scene, cfg: Config) -> Arm:
        """The arm for ``scene`` (a simulated arm starts at ``scene.start``) configured by ``cfg``: how the
        registry (``factory.py``) builds every backend."""

    @abc.abstractmethod
    def read(self) -> ArmState:
        """The latest state (never blocks)."""

    @abc.abstractmethod
    def command_twist(self, twist: FloatArray) -> None:
        """Hold ``twist`` (m/s, rad/s, base frame, 6 finite numbers) until the next command."""

    @abc.abstractmethod
    def command_gripper(self, closed: bool) -> None:
        """Close (``True``) or open the gripper."""

    def halt(self, timeout_s: float = 0.1) -> bool:
        """Stop for good before :meth:`close`: command zero, refuse moving commands from now on, and return
        ``True`` once no moving command can still reach the arm (``False`` if one was still in flight after
        ``timeout_s`` s). A stepped arm has nothing in flight; an arm with an I/O thread overrides this."""
        self.command_twist(np.zeros(6))
        return True

    def step(self, dt: float) -> None:
        """Advance a simulated arm by ``dt`` s under the held command (no-op for a real arm)."""

    #: ``True`` for arms that move in real time by themselves (the real xArm); simulated arms are stepped.
    realtime: bool = False

    def status(self) -> dict[str, Any]:
        """Driver diagnostics for the ``status`` command (connection, fault code, counters)."""
        return {}

    def reset(self) -> bool:
        """Put a simulated arm back in its start state: TCP at the scene's start pose, at rest, gripper
        open, objects where the scene puts them. Returns ``False`` for an arm that cannot (a real arm
        does not teleport); the caller then builds a fresh one. Cheap, unlike a rebuild (a MuJoCo model
        compiles in tens of ms), so the daemon can call it between tasks on the event loop."""
        return False

    def reset_fault(self) -> None:
        """Clear a latched fault and re-enable motion; called only on an explicit ``resume``."""

    def close(self) -> None:
        """Stop the arm and release its resources (connections, threads, viewers). Idempotent."""
