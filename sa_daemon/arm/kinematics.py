"""xArm-6 TCP kinematics with Pinocchio, built from the same MJCF file MuJoCo simulates (``xarm6.xml``).

One model, two engines: :class:`ArmKinematics` parses ``xarm6.xml`` with ``pinocchio.buildModelFromMJCF``
and locks the two finger slides, leaving the six arm joints; the MJCF ``tcp`` site becomes a Pinocchio
frame. There is no second hand-written copy of the joint table.

Units: joint positions rad, joint velocities rad/s, positions m, linear velocities m/s, angular
velocities rad/s. Twists and Jacobians are in the base frame, ordered ``[v; w]``, ``v`` being the
velocity of the TCP point (``pinocchio.LOCAL_WORLD_ALIGNED``).
"""

from __future__ import annotations

from contextlib import ExitStack
from importlib import resources
from pathlib import Path

import numpy as np
import pinocchio as pin

from ..geometry import FloatArray, Pose, as_twist, rotation_error

ARM_JOINTS = ("joint1", "joint2", "joint3", "joint4", "joint5", "joint6")
"""Names of the six arm joints in ``xarm6.xml``, base to flange."""
FINGER_JOINTS = ("finger_left", "finger_right")
"""The gripper's slide joints (locked in the kinematic model)."""
TCP_FRAME = "tcp"
"""The MJCF site (and Pinocchio frame) of the tool centre point, 0.172 m along the flange z."""
VELOCITY_LIMIT_RADPS = 2.14
"""Joint speed limit (rad/s): xarm6 ``joint_limits.yaml`` (the URDF's 3.14 is the higher of the two)."""

# Damped least squares: no damping while the smallest singular value of J exceeds SIGMA_MIN, then the
# damping grows smoothly to LAMBDA_MAX at a singularity (Maciejewski & Klein). J mixes m/rad and
# rad/rad rows, so these are in those mixed units; 0.04 is well below the arm's usual singular values
# (about 0.1 to 1) and keeps joint speeds finite at exact singularities.
SIGMA_MIN = 0.04
LAMBDA_MAX = 0.04


class IKError(ValueError):
    """Inverse kinematics did not reach the pose within tolerance (message says how far it got)."""


def model_path() -> Path:
    """Path of the packaged ``xarm6.xml`` (an ordinary file in an installed or editable package)."""
    return Path(str(resources.files("sa_daemon.arm").joinpath("xarm6.xml")))


def build_arm_model(path: str | Path | None = None) -> pin.Model:
    """The six-joint Pinocchio model of ``xarm6.xml`` (finger slides locked at 0)."""
    with ExitStack() as stack:
        if path is None:
            path = stack.enter_context(resources.as_file(resources.files("sa_daemon.arm").joinpath("xarm6.xml")))
        full = pin.buildModelFromMJCF(str(path))
    locked = [full.getJointId(name) for name in FINGER_JOINTS if full.existJointName(name)]
    model = pin.buildReducedModel(full, locked, pin.neutral(full)) if locked else full
    names = tuple(model.names[1:])
    if names != ARM_JOINTS:
        raise ValueError(f"{path}: expected arm joints {ARM_JOINTS}, found {names}")
    if not model.existFrame(TCP_FRAME):
        raise ValueError(f"{path}: no site/frame named {TCP_FRAME!r}")
    return model


def dls(jac: FloatArray, twist: FloatArray) -> FloatArray:
    """Damped least-squares solution ``qdot`` of ``jac @ qdot = twist`` (adaptive damping, see SIGMA_MIN).

    Exact (the pseudo-inverse) while the smallest singular value exceeds ``SIGMA_MIN``.
    """
    u, s, vt = np.linalg.svd(jac, full_matrices=False)
    smin = s[-1] if s.size else 0.0
    lam2 = 0.0 if smin >= SIGMA_MIN else LAMBDA_MAX**2 * (1.0 - (smin / SIGMA_MIN) ** 2)
    return vt.T @ ((s / (s * s + lam2)) * (u.T @ twist)) if lam2 > 0.0 else vt.T @ ((u.T @ twist) / s)


class ArmKinematics:
    """Implements :class:`sa_daemon.arm.base.Kinematics` for the xArm-6 TCP.

    ``lower``/``upper``: joint bounds (rad) from the MJCF (the published limits, +-2 pi on joints 1, 4
    and 6); ``velocity_limit``: 2.14 rad/s per joint; ``joint_margin``: a joint closer than this (rad) to a
    bound is not moved toward it by :meth:`joint_velocities`.
    """

    def __init__(self, path: str | Path | None = None, joint_margin: float = 0.1,
                 velocity_limit: float = VELOCITY_LIMIT_RADPS) -> None:
        if not (joint_margin >= 0.0 and velocity_limit > 0.0):
            raise ValueError("joint_margin must be >= 0 rad and velocity_limit > 0 rad/s")
        self.model = build_arm_model(path)
        self.data = self.model.createData()
        self.tcp_id = self.model.getFrameId(TCP_FRAME)
        self.n = self.model.nq
        self.joint_names = ARM_JOINTS
        self.lower: FloatArray = np.array(self.model.lowerPositionLimit, dtype=float)
        self.upper: FloatArray = np.array(self.model.upperPositionLimit, dtype=float)
        self.velocity_limit: FloatArray = np.full(self.n, float(velocity_limit))
        self.joint_margin = float(joint_margin)

    # -- forward -------------------------------------------------------------------------------------

    def _q(self, q: FloatArray) -> FloatArray:
        q = np.asarray(q, dtype=float).reshape(-1)
        if q.shape != (self.n,) or not np.all(np.isfinite(q)):
            raise ValueError(f"q must be {self.n} finite joint positions (rad), got {q!r}")
        return q

    def tcp_transform(self, q: FloatArray) -> tuple[FloatArray, FloatArray]:
        """(position (m), 3x3 rotation) of the TCP in the base frame at ``q`` (rad)."""
        pin.framesForwardKinematics(self.model, self.data, self._q(q))
        m = self.data.oMf[self.tcp_id]
        return m.translation.copy(), m.rotation.copy()

    def fk(self, q: FloatArray) -> Pose:
        """TCP pose (base frame, m) at joint positions ``q`` (rad)."""
        p, r = self.tcp_transform(q)
        return Pose.from_matrix(p, r)

    def jacobian(self, q: FloatArray) -> FloatArray:
        """6 x 6 TCP Jacobian at ``q`` (rad): joint velocities (rad/s) to the base-frame twist
        ``[v (m/s); w (rad/s)]`` of the TCP point."""
        return pin.computeFrameJacobian(self.model, self.data, self._q(q), self.tcp_id, pin.LOCAL_WORLD_ALIGNED)

    def joint_origins(self, q: FloatArray) -> FloatArray:
        """6 x 3 positions (m, base frame) of the joint origins at ``q`` (rad); row 2 is the elbow."""
        pin.forwardKinematics(self.model, self.data, self._q(q))
        return np.array([self.data.oMi[i].translation for i in range(1, self.n + 1)])

    # -- differential inverse ------------------------------------------------------------------------

    def blocked(self, q: FloatArray, qdot: FloatArray) -> np.ndarray:
        """Joints within ``joint_margin`` (rad) of a bound whose velocity points toward that bound."""
        return ((q <= self.lower + self.joint_margin) & (qdot < 0.0)) | (
            (q >= self.upper - self.joint_margin) & (qdot > 0.0)
        )

    def joint_velocities(self, q: FloatArray, twist: FloatArray) -> FloatArray:
        """Joint velocities (rad/s) realising the base-frame ``twist`` (m/s, rad/s) at ``q`` (rad).

        1. Damped least squares on the TCP Jacobian (exact away from singularities).
        2. A joint inside ``joint_margin`` of a bound that would move toward it is locked (its column
           removed) and the rest re-solved, so the others still do what they can; repeated until no
           locked joint is left to add.
        3. The whole vector is scaled so no joint exceeds ``velocity_limit``: the direction of motion is
           kept, the speed reduced.
        """
        q = self._q(q)
        t = as_twist(twist)
        if not np.any(t):
            return np.zeros(self.n)
        jac = self.jacobian(q)
        qdot = dls(jac, t)
        if np.any(self.blocked(q, qdot)):  # rare: only near a bound
            free = np.ones(self.n, dtype=bool)
            for _ in range(self.n):
                newly = self.blocked(q, qdot) & free
                if not np.any(newly):
                    break
                free &= ~newly
                qdot = np.zeros(self.n)
                if np.any(free):
                    qdot[free] = dls(jac[:, free], t)
            qdot[~free] = 0.0
        peak = float(np.max(np.abs(qdot) / self.velocity_limit))
        return qdot / peak if peak > 1.0 else qdot

    # -- inverse -------------------------------------------------------------------------------------

    def ik(self, pose: Pose, q0: FloatArray, tol_m: float = 1e-5, tol_rad: float = 1e-5,
           max_iter: int = 300, max_step_rad: float = 0.2) -> FloatArray:
        """Joint positions (rad) putting the TCP at ``pose``, by iterated damped least squares from ``q0``.

        Each iteration solves ``J dq = [dp; dr]`` (position error m, rotation-vector error rad, base
        frame), limits the step to ``max_step_rad`` per joint and clips to the joint bounds. Converges to
        the solution near ``q0`` (the seed picks the elbow and wrist configuration). Raises
        :class:`IKError` if the error is not below ``tol_m`` / ``tol_rad`` after ``max_iter`` iterations.
        """
        q = np.clip(self._q(q0).copy(), self.lower, self.upper)
        target_p = np.asarray(pose.position, dtype=float)
        err_p = err_r = float("inf")
        for _ in range(max_iter):
            p, r = self.tcp_transform(q)
            e = np.concatenate((target_p - p, rotation_error(pose.quat_wxyz, Pose.from_matrix(p, r).quat_wxyz)))
            err_p, err_r = float(np.linalg.norm(e[:3])), float(np.linalg.norm(e[3:]))
            if err_p <= tol_m and err_r <= tol_rad:
                return q
            dq = dls(self.jacobian(q), e)
            peak = float(np.max(np.abs(dq)))
            if peak > max_step_rad:
                dq *= max_step_rad / peak
            q = np.clip(q + dq, self.lower, self.upper)
        raise IKError(
            f"IK did not reach {pose!r} from q0={np.round(q0, 3).tolist()}: "
            f"{err_p * 1000:.2f} mm, {np.degrees(err_r):.3f} deg left after {max_iter} iterations"
        )


def start_configuration(kin: ArmKinematics, pose: Pose, tol_m: float = 1e-3, tol_rad: float = 1e-3) -> FloatArray:
    """Elbow-up joint positions (rad) for a start ``pose``: IK from a few seeds turned toward the pose,
    keeping the solution with the highest elbow (joint 3 origin), then the one nearest the first seed.

    On the xArm-6 the forearm folds to one side of the upper arm only (joint 3 <= 0.19 rad), so a TCP
    close above the shoulder, like the scenes' start pose, is reached with the upper arm leaning back;
    the elbow-height rule picks that over the sideways solutions with joint 1 near +-2.1 rad.
    Raises :class:`IKError` if no seed gets within ``tol_m`` (m) and ``tol_rad`` (rad).
    """
    bearing = float(np.arctan2(pose.position[1], pose.position[0]))
    seeds = [np.array([bearing, q2, q3, 0.0, q5, 0.0]) for q2, q3, q5 in (
        (-1.0, -1.0, 1.2), (0.2, -1.0, 0.8), (-1.6, -0.3, 1.1), (0.6, -1.8, 1.2), (0.0, -0.5, 0.5),
    )]
    best: tuple[float, float, FloatArray] | None = None
    errors = []
    for seed in seeds:
        try:
            q = kin.ik(pose, seed)
        except IKError as e:
            errors.append(str(e))
            continue
        d_t, d_r = kin.fk(q).distance(pose)
        if d_t > tol_m or d_r > tol_rad:
            continue
        key = (-round(float(kin.joint_origins(q)[2, 2]), 3), float(np.linalg.norm(q - seeds[0])))
        if best is None or key < best[:2]:
            best = (key[0], key[1], q)
    if best is None:
        raise IKError(f"no joint configuration reaches the start pose {pose!r}: " + "; ".join(errors[:2]))
    return best[2]
