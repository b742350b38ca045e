"""The one safety pipeline between the blended twist and every arm driver (MoveIt Servo's stages).

Stages, in order; each that changes the command adds its :class:`SafetyCode` to the result:

1. ``stopped``       - a latched stop (``stop`` command, e-stop button) holds the arm until ``resume``;
   ``stop_untested`` - with the start-up self-test required (``safety.stop_self_test``), the arm is held
   until a stop has been latched and resumed once, so the stop is known to work before anything moves.
2. ``arm_fault``     - the driver reports a fault: zero until it is cleared on ``resume``.
3. ``nan_refused``   - a twist with NaN/inf (or of the wrong shape) becomes zero.
4. ``stale_input``   - no fresh user input for ``safety.stale_command_s``: zero.
5. ``gripper_closed`` - the gripper is closed (as the arm reports it) or closing (commanded, not yet
   reported): zero, so the arm never drags what it holds. The pipeline's memory of its last output is
   then zero too, so when the gripper reopens the command restarts from rest under stage 7.
6. ``speed_limited`` - per-axis linear/angular limits, the whole part scaled so the direction is kept.
7. ``accel_limited`` - the change from the last output is scaled (direction of the change kept) so no
   axis accelerates beyond ``linear_accel_mps2``/``angular_accel_radps2``.
8. ``workspace_limited`` - per axis, the TCP may not cross the workspace box within one period.
9. ``singularity_slow``/``singularity_halt`` - when the Jacobian condition number ``k`` is above
   ``slow`` and the command moves toward the singularity, its component along the weakest direction
   ``u`` is scaled by ``1 - (k - slow) / (stop - slow)``, and removed at ``stop``; the rest of the
   command passes (MoveIt Servo scales the whole command, which also held the motion that would have
   carried the xArm's wrist across joint 5 = 0, and trapped users there: ``docs/arm.md``). The
   Jacobian's linear rows (m/rad) are divided by ``characteristic_length_m`` first:
   the condition number of a mixed-unit Jacobian depends on the unit of length, and at the xArm-6's
   0.3 m links this makes a well-conditioned pose read about 15. "Toward" is MoveIt Servo's test: the
   weakest output direction ``u`` of the Jacobian (its smallest singular value), signed so that a
   small joint step along ``J+ u`` raises ``k``; the command moves toward the singularity when its
   share along ``u`` (``u . t / |t|``, in the normalised twist space) exceeds
   ``singularity_share``. A command with (almost) no share along ``u`` needs none of the motion the
   singularity takes away, and passes: the xArm-6 crosses its wrist singularity (joint 5 = 0) in a
   vertical plane this way, pitching or translating, with small joint speeds. The dead band (MoveIt
   uses 0) keeps joystick noise from toggling the halt.
10. ``joint_bound``  - a joint within ``joint_margin_rad`` of a bound and moving toward it halts the
   command (and a joint speed above its limit scales the command).

Stages 1-5 zero the command at once (a stop is never softened by the acceleration limit) and
restart the next command from rest; stages 8-10 only reduce speeds (after stage 9 has removed the
part toward a singularity, the whole twist is scaled down again where that lengthened its linear part
beyond the speed limits or the workspace step). So every output is finite,
within the speed limits, never leaves the box, and changes by at most the acceleration limit from
the last output unless a zeroing or position stage says why it did not. Stages 9-10 apply to arms
with joints (``Arm.kinematics``); the kinematic arm has none.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum

import numpy as np

from ..arm.base import Kinematics, limit_twist, speed_scales
from ..config import LimitsConfig, SafetyConfig
from ..geometry import FloatArray, Pose


class SafetyCode(str, Enum):
    """What the pipeline did to a command; ordered from least to most severe."""

    OK = "ok"
    SPEED = "speed_limited"
    ACCEL = "accel_limited"
    WORKSPACE = "workspace_limited"
    SINGULARITY_SLOW = "singularity_slow"
    JOINT_SPEED = "joint_speed_limited"
    SINGULARITY_HALT = "singularity_halt"
    JOINT_BOUND = "joint_bound"
    GRIPPER = "gripper_closed"
    STALE = "stale_input"
    NAN = "nan_refused"
    ARM_FAULT = "arm_fault"
    STOPPED = "stopped"
    STOP_UNTESTED = "stop_untested"


_SEVERITY = {c: i for i, c in enumerate(SafetyCode)}
_JOINT_CODES = {SafetyCode.SINGULARITY_SLOW, SafetyCode.SINGULARITY_HALT, SafetyCode.JOINT_BOUND}
ZERO = np.zeros(6)


@dataclass(frozen=True)
class SafetyResult:
    """The twist to send (m/s, rad/s, base frame) and the codes of the stages that changed it."""

    twist: FloatArray
    codes: tuple[SafetyCode, ...]

    @property
    def status(self) -> SafetyCode:
        """The most severe code (``ok`` when no stage acted)."""
        return max(self.codes, key=_SEVERITY.__getitem__, default=SafetyCode.OK)

    def refuses(self, requested: FloatArray, fraction: float = 0.1) -> bool:
        """True when a joint stage (singularity, joint bound) let through less than ``fraction`` of the
        ``requested`` twist (m/s, rad/s; plain norms: "almost nothing moved" needs no unit balance).
        What a user sees as "the arm will not go there"."""
        if not set(self.codes) & _JOINT_CODES:
            return False
        asked = float(np.linalg.norm(requested))
        return asked > 0.0 and float(np.linalg.norm(self.twist)) < fraction * asked


class SafetyPipeline:
    """Filter each control tick's command. Holds the last output (for the acceleration limit) and the
    stop latch; ``dt`` is the control period (s)."""

    def __init__(
        self,
        cfg: SafetyConfig,
        limits: LimitsConfig,
        dt: float,
        kinematics: Kinematics | None = None,
    ) -> None:
        if not dt > 0:
            raise ValueError("dt must be positive (s)")
        self.cfg = cfg
        self.limits = limits
        self.dt = dt
        self.kinematics = kinematics
        self._last = ZERO.copy()
        self._stopped = False
        self._stop_tested = True
        self._lo = np.asarray(cfg.workspace_min_m, dtype=float)
        self._hi = np.asarray(cfg.workspace_max_m, dtype=float)
        self._amax = np.array([cfg.linear_accel_mps2] * 3 + [cfg.angular_accel_radps2] * 3)

    # -- the latch -------------------------------------------------------------------------------------

    @property
    def stopped(self) -> bool:
        return self._stopped

    @property
    def stop_tested(self) -> bool:
        """A stop has been latched and resumed since :meth:`require_stop_test` (or none is required)."""
        return self._stop_tested

    def require_stop_test(self) -> None:
        """Hold the arm (``stop_untested``) until a stop has been latched and then released by :meth:`resume`."""
        self._stop_tested = False

    def stop(self) -> None:
        """Latch a stop: every command is zero until :meth:`resume`."""
        self._stopped = True

    def resume(self) -> None:
        """Release the latch (the person's or carer's resume; releasing a latched stop passes the stop's
        self-test); the arm restarts from rest (acceleration-limited)."""
        if self._stopped:
            self._stop_tested = True
        self.restart()

    def restart(self) -> None:
        """Release the latch for a new task (no proof of anything); the arm restarts from rest."""
        self._stopped = False
        self._last = ZERO.copy()

    # -- the filter ------------------------------------------------------------------------------------

    def _zero(self, code: SafetyCode) -> SafetyResult:
        self._last = ZERO.copy()
        return SafetyResult(ZERO.copy(), (code,))

    def filter(
        self,
        twist: FloatArray,
        pose: Pose,
        input_fresh: bool = True,
        fault: bool = False,
        joints: FloatArray | None = None,
        gripper_closed: bool = False,
    ) -> SafetyResult:
        """Run every stage on ``twist`` at TCP ``pose`` (and joint positions ``joints``, rad);
        ``gripper_closed``: the gripper is closed or closing (stage 5)."""
        if self._stopped:
            return self._zero(SafetyCode.STOPPED)
        if not self._stop_tested:
            return self._zero(SafetyCode.STOP_UNTESTED)
        if fault:
            return self._zero(SafetyCode.ARM_FAULT)
        t = np.asarray(twist, dtype=float) if np.ndim(twist) == 1 else np.full(1, np.nan)
        if t.shape != (6,) or not np.all(np.isfinite(t)):
            return self._zero(SafetyCode.NAN)
        if not input_fresh:
            return self._zero(SafetyCode.STALE)
        if gripper_closed:
            return self._zero(SafetyCode.GRIPPER)
        codes: list[SafetyCode] = []
        out = limit_twist(t, self.limits.linear_mps, self.limits.angular_radps, self.limits.tcp_mps)
        if not np.allclose(out, t, rtol=0, atol=1e-12):
            codes.append(SafetyCode.SPEED)
        out = self._accel(out, codes)
        out = self._workspace(out, pose, codes)
        if self.kinematics is not None and joints is not None:
            out = self._joint_stages(out, np.asarray(joints, dtype=float), codes)
            out = self._rescale(out, pose, codes)
        self._last = out.copy()
        return SafetyResult(out, tuple(codes))

    def _accel(self, t: FloatArray, codes: list[SafetyCode]) -> FloatArray:
        step = t - self._last
        ratio = np.max(np.abs(step) / (self._amax * self.dt))
        if ratio > 1.0:
            codes.append(SafetyCode.ACCEL)
            return self._last + step / ratio
        return t

    def _workspace(self, t: FloatArray, pose: Pose, codes: list[SafetyCode]) -> FloatArray:
        p = np.asarray(pose.position, dtype=float)
        v = t[:3]
        # Fastest speed per axis that keeps p + v dt inside the box (inward motion is always allowed).
        vmax = np.maximum((self._hi - p) / self.dt, 0.0)
        vmin = np.minimum((self._lo - p) / self.dt, 0.0)
        clipped = np.clip(v, vmin, vmax)
        if np.any(clipped != v):
            codes.append(SafetyCode.WORKSPACE)
            t = t.copy()
            t[:3] = clipped
        return t

    def _rescale(self, t: FloatArray, pose: Pose, codes: list[SafetyCode]) -> FloatArray:
        """Stage 9 removes the part toward a singularity in the length-normalised twist space, which can
        lengthen the linear part: the speed limits and the workspace step hold again here, by scaling
        the *whole* twist (so every joint velocity keeps its direction, and stage 10's verdict stands).
        Found by the controller-limits property test (``tests/test_controller_limits.py``)."""
        scale = min(speed_scales(t, self.limits.linear_mps, self.limits.angular_radps, self.limits.tcp_mps))
        code = SafetyCode.SPEED
        p, v = np.asarray(pose.position, dtype=float), t[:3]
        room = np.where(v > 0, self._hi - p, self._lo - p) / self.dt  # the speed per axis that reaches a face
        # divide only where the axis would pass a face (|v| > |room|): there |room / v| < 1, no overflow
        reach = np.abs(v) > np.abs(room)
        ratios = np.maximum(np.divide(room, v, out=np.ones_like(v), where=reach), 0.0)
        if float(np.min(ratios)) < scale:
            scale, code = float(np.min(ratios)), SafetyCode.WORKSPACE
        if scale >= 1.0:
            return t
        if code not in codes:
            codes.append(code)
        return t * scale

    def _normalised_jacobian(self, q: FloatArray) -> FloatArray:
        """The Jacobian at ``q`` with its linear rows divided by ``characteristic_length_m`` (stage 8)."""
        assert self.kinematics is not None
        jac = np.array(self.kinematics.jacobian(q), dtype=float)
        jac[:3] /= self.cfg.characteristic_length_m
        return jac

    def _condition(self, q: FloatArray) -> float:
        """Condition number of the length-normalised Jacobian at ``q`` (see stage 8)."""
        return float(np.linalg.cond(self._normalised_jacobian(q)))

    def singularity_share(self, q: FloatArray, twist: FloatArray) -> tuple[float, float]:
        """``(k, share)``: the condition number at ``q`` (rad) and the share of ``twist`` (m/s, rad/s)
        along the weakest output direction, signed positive toward the singularity (stage 8)."""
        jac = self._normalised_jacobian(q)
        kappa, u = self._weakest(jac)
        _, tn, along = self._along_toward(jac, q, kappa, u, twist)
        norm = float(np.linalg.norm(tn))
        return kappa, (along / norm if norm > 0 else 0.0)

    def _along_toward(
        self, jac: FloatArray, q: FloatArray, kappa: float, u: FloatArray, twist: FloatArray
    ) -> tuple[FloatArray, FloatArray, float]:
        """``(u, tn, along)``: the weakest direction ``u`` signed toward the singularity, ``twist`` with
        its linear part divided by ``characteristic_length_m``, and the component of that along ``u``."""
        u = self._signed_toward(jac, q, kappa, u)
        tn = np.array(twist, dtype=float)
        tn[:3] /= self.cfg.characteristic_length_m
        return u, tn, float(u @ tn)

    @staticmethod
    def _weakest(jac: FloatArray) -> tuple[float, FloatArray]:
        """``(k, u)``: the condition number of the normalised Jacobian ``jac`` and its weakest output
        direction (unit, normalised twist space, sign arbitrary), from one SVD."""
        u_mat, sing, _ = np.linalg.svd(jac)
        kappa = float(sing[0] / sing[-1]) if sing[-1] > 0 else float("inf")
        return kappa, u_mat[:, -1]

    def _signed_toward(self, jac: FloatArray, q: FloatArray, kappa: float, u: FloatArray) -> FloatArray:
        """``u`` signed toward the singularity: does a small joint step realising ``+u`` raise ``k``?"""
        probe = np.linalg.pinv(jac) @ u
        step = 0.01 / max(float(np.max(np.abs(probe))), 1e-12)  # at most 0.01 rad per joint
        return -u if np.linalg.cond(self._normalised_jacobian(q + step * probe)) < kappa else u

    def _joint_stages(self, t: FloatArray, q: FloatArray, codes: list[SafetyCode]) -> FloatArray:
        kin = self.kinematics
        assert kin is not None
        if not np.any(t):
            return t
        c = self.cfg
        jac = self._normalised_jacobian(q)  # once per tick, and one SVD gives k and the weak direction
        kappa, u = self._weakest(jac)
        if kappa > c.singularity_slow:
            u, tn, along = self._along_toward(jac, q, kappa, u, t)
            if along > c.singularity_share * float(np.linalg.norm(tn)):  # moving toward the singularity
                halt = kappa >= c.singularity_stop
                codes.append(SafetyCode.SINGULARITY_HALT if halt else SafetyCode.SINGULARITY_SLOW)
                keep = 0.0 if halt else 1.0 - (kappa - c.singularity_slow) / (c.singularity_stop - c.singularity_slow)
                # Only the part toward the singularity is slowed (removed at the stop): the rest of the
                # command needs nothing the singularity takes away and passes.
                tn = tn - (1.0 - keep) * along * u
                t = tn.copy()
                t[:3] *= c.characteristic_length_m
        qdot = kin.joint_velocities(q, t)
        near_lo = (q - kin.lower < c.joint_margin_rad) & (qdot < 0)
        near_hi = (kin.upper - q < c.joint_margin_rad) & (qdot > 0)
        if np.any(near_lo | near_hi):
            codes.append(SafetyCode.JOINT_BOUND)
            return ZERO.copy()
        ratio = float(np.max(np.abs(qdot) / kin.velocity_limit))
        if ratio > 1.0:
            codes.append(SafetyCode.JOINT_SPEED)
            t = t / ratio
        return t
