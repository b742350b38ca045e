"""Rigid-body geometry: the one pose type and the vectorised quaternion maths behind it.

Conventions (used everywhere in sa-daemon):

* positions in metres, angles in radians, twists as ``[vx, vy, vz, wx, wy, wz]`` in m/s and rad/s,
  all expressed in the arm base frame unless a name says otherwise;
* quaternions are unit quaternions in **w, x, y, z** order (``quat_wxyz``), hemisphere not normalised
  (``q`` and ``-q`` are the same rotation; every distance here folds the sign);
* an angular velocity ``w`` is a base-frame rate vector, so integrating it over ``dt`` gives
  ``q' = exp(w dt) * q`` (left multiplication).

The functions take arrays with any leading batch shape so the planner can evaluate every grasp pose of
every goal in one numpy call; :class:`Pose` wraps one pose for the rest of the code.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]

_EPS = 1e-12


def quat_normalize(q: ArrayLike) -> FloatArray:
    """Unit quaternion(s) of ``q`` (``..., 4``); raises on zero or non-finite input."""
    q = np.asarray(q, dtype=float)
    n = np.linalg.norm(q, axis=-1, keepdims=True)
    if not np.all(np.isfinite(q)) or np.any(n < 1e-9):
        raise ValueError("quaternion must be finite and non-zero")
    return q / n


# Structure constants of the Hamilton product: (a * b)_k = sum_ij a_i b_j _HAMILTON[4 i + j, k].
_HAMILTON = np.zeros((16, 4))
for _i, _j, _k, _s in (
    (0, 0, 0, 1), (1, 1, 0, -1), (2, 2, 0, -1), (3, 3, 0, -1),
    (0, 1, 1, 1), (1, 0, 1, 1), (2, 3, 1, 1), (3, 2, 1, -1),
    (0, 2, 2, 1), (1, 3, 2, -1), (2, 0, 2, 1), (3, 1, 2, 1),
    (0, 3, 3, 1), (1, 2, 3, 1), (2, 1, 3, -1), (3, 0, 3, 1),
):
    _HAMILTON[4 * _i + _j, _k] = _s


COMPONENTWISE_MIN = 2048
"""Products in one :func:`quat_mul` call from which it computes component by component."""


def norms(v: ArrayLike) -> FloatArray:
    """Euclidean norms along the last axis (one ``einsum``: several times faster than ``np.linalg.norm``
    or ``sqrt(sum(v * v))`` on the planner's arrays, which allocate ``v * v`` first)."""
    v = np.asarray(v, dtype=float)
    return np.sqrt(np.einsum("...i,...i->...", v, v))


def _against_set(a: FloatArray, b: FloatArray) -> bool:
    """``a`` is a set of quaternions ``(G, 4)`` and ``b`` ``(..., 1, 4)`` pairs each of its own with all of
    them: the broadcast is an outer product over ``G``, which one matrix product computes."""
    return a.ndim == 2 and b.ndim >= 2 and b.shape[-2] == 1 and a.shape[0] > 1


def quat_mul(a: ArrayLike, b: ArrayLike) -> FloatArray:
    """Hamilton product ``a * b`` of wxyz quaternions, broadcasting over leading axes.

    Three ways, by shape, all the same product: when ``a`` is a set ``(G, 4)`` and ``b`` is ``(..., 1, 4)``
    (every quaternion against every goal), ``a * b`` is linear in ``b``: one ``(N, 4) x (4, 4G)`` matrix
    product. Small batches: one outer product and one matrix product (numpy's call overhead dominates,
    so fewer calls win). Large batches (``COMPONENTWISE_MIN`` products or more): the sixteen products
    component by component, without the ``(..., 16)`` temporaries (2-4x faster there).
    """
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    if _against_set(a, b):
        left = np.einsum("gi,ijk->jgk", a, _HAMILTON.reshape(4, 4, 4)).reshape(4, -1)  # b -> a * b, per goal
        return (b[..., 0, :] @ left).reshape(b.shape[:-2] + a.shape)
    if math.prod(np.broadcast_shapes(a.shape[:-1], b.shape[:-1])) >= COMPONENTWISE_MIN:
        aw, ax, ay, az = np.moveaxis(a, -1, 0)
        bw, bx, by, bz = np.moveaxis(b, -1, 0)
        return np.stack((aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
                         aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw), axis=-1)
    outer = a[..., :, None] * b[..., None, :]
    return outer.reshape(outer.shape[:-2] + (16,)) @ _HAMILTON


def quat_conj(q: ArrayLike) -> FloatArray:
    """Conjugate (the inverse for unit quaternions)."""
    q = np.asarray(q, dtype=float)
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def quat_angle(a: ArrayLike, b: ArrayLike) -> FloatArray:
    """Geodesic angle between rotations ``a`` and ``b`` in rad, in [0, pi]: ``2 acos(|<a, b>|)``."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    if _against_set(a, b):  # every quaternion of b against the set a: one matrix product
        dot = np.abs(b[..., 0, :] @ a.T)
    elif _against_set(b, a):
        dot = np.abs(a[..., 0, :] @ b.T)
    else:
        dot = np.abs(np.einsum("...i,...i->...", a, b))
    return 2.0 * np.arccos(np.clip(dot, 0.0, 1.0))


def quat_to_rotvec(q: ArrayLike) -> FloatArray:
    """Rotation vector (axis * angle, rad) of ``q``, taking the short way (angle in [0, pi])."""
    q = np.asarray(q, dtype=float)
    w, v = q[..., 0], q[..., 1:]
    s = norms(v)
    angle = 2.0 * np.arctan2(s, np.minimum(np.abs(w), 1.0))  # q and -q: the same rotation, w >= 0 the short way
    # angle / s -> 2 as s -> 0 (first-order expansion), avoids 0/0.
    scale = np.where(s > 1e-9, angle / np.maximum(s, _EPS), 2.0)
    return v * np.where(w < 0.0, -scale, scale)[..., None]


def rotvec_to_quat(r: ArrayLike) -> FloatArray:
    """Unit quaternion of a rotation vector ``r`` (rad)."""
    r = np.asarray(r, dtype=float)
    angle = norms(r)
    half = 0.5 * angle
    # sin(half)/angle -> 0.5 as angle -> 0.
    k = np.where(angle > 1e-9, np.sin(half) / np.maximum(angle, _EPS), 0.5)
    return np.concatenate((np.cos(half)[..., None], r * k[..., None]), axis=-1)


def quat_to_matrix(q: ArrayLike) -> FloatArray:
    """3x3 rotation matrix (``..., 3, 3``) of wxyz quaternion(s)."""
    w, x, y, z = np.moveaxis(quat_normalize(q), -1, 0)
    return np.stack(
        (
            np.stack((1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)), axis=-1),
            np.stack((2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)), axis=-1),
            np.stack((2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)), axis=-1),
        ),
        axis=-2,
    )


def quat_z_axis(q: ArrayLike) -> FloatArray:
    """The z axis turned by wxyz quaternion(s), ``(..., 3)``: the third column of :func:`quat_to_matrix`
    (the same numbers) without the other two, e.g. a gripper's approach axis."""
    w, x, y, z = np.moveaxis(quat_normalize(q), -1, 0)
    return np.stack((2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)), axis=-1)


def matrix_to_quat(m: ArrayLike) -> FloatArray:
    """wxyz quaternion of one 3x3 rotation matrix (Shepperd's method, numerically stable)."""
    m = np.asarray(m, dtype=float)
    if m.shape != (3, 3) or not np.all(np.isfinite(m)):
        raise ValueError("rotation matrix must be a finite 3x3 array")
    tr = np.trace(m)
    if tr > 0.0:
        s = 2.0 * np.sqrt(tr + 1.0)
        q = [0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s]
    else:
        i = int(np.argmax(np.diag(m)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * np.sqrt(max(1.0 + m[i, i] - m[j, j] - m[k, k], _EPS))
        q = [0.0, 0.0, 0.0, 0.0]
        q[0] = (m[k, j] - m[j, k]) / s
        q[1 + i] = 0.25 * s
        q[1 + j] = (m[j, i] + m[i, j]) / s
        q[1 + k] = (m[k, i] + m[i, k]) / s
    return quat_normalize(q)


def rpy_to_quat(rpy: ArrayLike) -> FloatArray:
    """wxyz quaternion of roll, pitch, yaw (rad), extrinsic x-y-z (``R = Rz(yaw) Ry(pitch) Rx(roll)``),
    the ROS/URDF convention."""
    roll, pitch, yaw = (float(v) for v in np.asarray(rpy, dtype=float))
    qx = np.array([np.cos(roll / 2), np.sin(roll / 2), 0.0, 0.0])
    qy = np.array([np.cos(pitch / 2), 0.0, np.sin(pitch / 2), 0.0])
    qz = np.array([np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)])
    return quat_mul(qz, quat_mul(qy, qx))


def as_twist(twist: ArrayLike) -> FloatArray:
    """``twist`` as a float array of shape ``(6,)`` (linear m/s, angular rad/s); ``ValueError`` unless it is
    6 finite numbers: the one check every consumer of a commanded twist makes."""
    t = np.array(twist, dtype=float)
    if t.shape != (6,) or not np.all(np.isfinite(t)):
        raise ValueError("twist must be 6 finite numbers (m/s, rad/s)")
    return t


def integrate_pose(
    position: ArrayLike, quat_wxyz: ArrayLike, twist: ArrayLike, dt: float
) -> tuple[FloatArray, FloatArray]:
    """Apply a base-frame twist for ``dt`` seconds: ``p + v dt`` and ``exp(w dt) q``.

    Broadcasts over leading axes, so one call moves many candidate poses at once.
    """
    twist = np.asarray(twist, dtype=float)
    p = np.asarray(position, dtype=float) + twist[..., :3] * dt
    return p, turn(quat_wxyz, twist[..., 3:], dt)


def turn(quat_wxyz: ArrayLike, angular: ArrayLike, dt: float) -> FloatArray:
    """The orientation part of :func:`integrate_pose`: ``exp(w dt) q`` for a base-frame angular velocity
    ``w`` (rad/s) applied for ``dt`` seconds, renormalised. Broadcasts over leading axes."""
    q = quat_mul(rotvec_to_quat(np.asarray(angular, dtype=float) * dt), quat_wxyz)
    return q / norms(q)[..., None]


def rotation_error(target_quat_wxyz: ArrayLike, quat_wxyz: ArrayLike) -> FloatArray:
    """Base-frame rotation vector (rad) that turns ``quat_wxyz`` into ``target_quat_wxyz``.

    Following it as an angular velocity is the geodesic path between the two orientations.
    """
    return quat_to_rotvec(quat_mul(target_quat_wxyz, quat_conj(quat_wxyz)))


@dataclass(frozen=True, eq=False)
class Pose:
    """A rigid pose in the arm base frame: ``position`` (m) and unit ``quat_wxyz``.

    Immutable and validated: a pose with NaN/inf or a zero quaternion cannot be constructed, so
    nothing downstream has to re-check.
    """

    position: FloatArray
    quat_wxyz: FloatArray

    def __post_init__(self) -> None:
        p = np.array(self.position, dtype=float).reshape(-1)
        if p.shape != (3,) or not np.all(np.isfinite(p)):
            raise ValueError(f"position must be 3 finite numbers (m), got {self.position!r}")
        q = np.array(self.quat_wxyz, dtype=float).reshape(-1)
        if q.shape != (4,):
            raise ValueError(f"quat_wxyz must be 4 numbers, got {self.quat_wxyz!r}")
        q = quat_normalize(q)
        p.setflags(write=False)
        q.setflags(write=False)
        object.__setattr__(self, "position", p)
        object.__setattr__(self, "quat_wxyz", q)

    @classmethod
    def from_rpy(cls, position: Sequence[float], rpy: Sequence[float]) -> Pose:
        """Pose from position (m) and extrinsic roll-pitch-yaw (rad)."""
        return cls(np.asarray(position, dtype=float), rpy_to_quat(rpy))

    @classmethod
    def from_matrix(cls, position: Sequence[float], rotation: ArrayLike) -> Pose:
        """Pose from position (m) and a 3x3 rotation matrix whose columns are the frame's axes."""
        return cls(np.asarray(position, dtype=float), matrix_to_quat(rotation))

    @property
    def rotation(self) -> FloatArray:
        """3x3 rotation matrix; its columns are the tool x, y, z axes in the base frame."""
        return quat_to_matrix(self.quat_wxyz)

    def moved(self, twist: ArrayLike, dt: float) -> Pose:
        """This pose after applying a base-frame ``twist`` (m/s, rad/s) for ``dt`` s."""
        p, q = integrate_pose(self.position, self.quat_wxyz, as_twist(twist), dt)
        return Pose(p, q)

    def distance(self, other: Pose) -> tuple[float, float]:
        """(translation distance in m, rotation angle in rad) to ``other``."""
        return (
            float(np.linalg.norm(self.position - other.position)),
            float(quat_angle(self.quat_wxyz, other.quat_wxyz)),
        )

    def as_dict(self) -> dict[str, list[float]]:
        """JSON-ready form ``{"position": [...], "quat_wxyz": [...]}``."""
        return {"position": self.position.tolist(), "quat_wxyz": self.quat_wxyz.tolist()}

    @classmethod
    def from_dict(cls, d: dict) -> Pose:
        """Inverse of :meth:`as_dict`."""
        return cls(np.asarray(d["position"], dtype=float), np.asarray(d["quat_wxyz"], dtype=float))

    def __repr__(self) -> str:
        p = ", ".join(f"{v:.4f}" for v in self.position)
        q = ", ".join(f"{v:.4f}" for v in self.quat_wxyz)
        return f"Pose(position=[{p}], quat_wxyz=[{q}])"
