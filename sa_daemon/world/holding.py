"""Would a gripper closed at this pose hold the object? The geometric rule that stands in for the MuJoCo
arm's lift test on arms without physics (the kinematic arm).

A grasp is a tool-frame pose (``grasps.py``): z the approach, y the fingers' closing axis, the position
the TCP between the fingertips. Closing at ``pose`` holds ``obj`` with grasp type ``grasp_type`` when:

1. **Type.** :func:`~.grasps.classify_grasp` puts the pose in ``grasp_type`` (fine or coarse, as the
   goal names it): a top grasp is not a side grasp.
2. **Between the fingertips.** The TCP is inside the object, or within ``margin_m`` of its surface
   (the fingertip pads reach ``margin_m`` beyond the TCP): fingertips closing above a box close on air.
3. **Fits the opening.** The object's chord along the closing axis through the TCP is no longer than the
   gripper's opening: a closing axis along a long box does not hold. (The parallel jaws close
   symmetrically and centre a light object, so the TCP need not be at the chord's middle.)
4. **Antipodal.** At both ends of the chord the surface normal is within the friction cone of the closing
   axis, ``atan(mu)`` with ``mu = FRICTION`` (0.8: rubber pads on plastic, wood, glass and card, 38.7
   deg): a side grasp that closes across a cylinder far off its axis squeezes it out of the fingers (the
   line must pass within ``sin(atan(mu)) r`` = 0.62 r of the axis). A pad is a patch, not a point: near
   an edge (a face within ``PAD_HALF_M`` of the chord's end) the better-aligned face counts, the pad
   resting on it.

A container grasped at the rim (``rim``, top grasps) pinches its wall: the chord is the wall, so instead
of 2-4 the TCP must be within ``opening/2`` of the wall, the rim between the TCP and the finger pads' top
(``FINGER_LENGTH_M``), and the closing axis within the friction cone of the wall's normal (radial).

Lengths in m. The rule is deliberately simple and documented in ``docs/simulated-user.md``; MuJoCo's lift
test remains the physical check.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..geometry import FloatArray, Pose
from .goals import GraspType
from .grasps import GRIPPER_MAX_OPENING_M, classify_grasp
from .scene import SceneObject

FRICTION = 0.8
"""Friction coefficient of the finger pads on the objects: rubber on dry plastic, wood, glass or card is
0.6-1.0 in engineering tables. With it, 99 % or more of the poses within the paper's closing tolerance
(1 cm, pi/48) of the generated grasps of every built-in scene hold (``tests/test_holding.py``); the
others close above a thin object."""
HOLD_MARGIN_M = 0.005
"""How far beyond the TCP the fingertip pads reach (m): a TCP this close outside the surface still holds."""
PAD_HALF_M = 0.01
"""Half the width of a finger pad (m; the xArm gripper's pads are about 2 cm wide): a pad whose centre
line leaves the object through a side face still rests on a face this close to it."""
FINGER_LENGTH_M = 0.04
"""Length of the xArm gripper's finger pads along the approach (m): the deepest a rim can sit in them."""
_FINE = {GraspType.TOP_HORIZONTAL, GraspType.TOP_VERTICAL, GraspType.SIDE_HORIZONTAL, GraspType.SIDE_VERTICAL}


@dataclass(frozen=True)
class Hold:
    """The verdict: ``held``, and when not, the first rule that failed: ``kind`` (one of
    :data:`HOLD_FAILURES`, for counting) and ``reason`` (the same with its numbers, for reading)."""

    held: bool
    reason: str = ""
    kind: str = ""


WRONG_TYPE = "wrong grasp type"
OUTSIDE = "closed outside the object"
TOO_WIDE = "not between the fingers"
SLIPS = "would slip"
RIM_MISSED = "rim not in the fingers"
HOLD_FAILURES = (WRONG_TYPE, OUTSIDE, TOO_WIDE, SLIPS, RIM_MISSED)
"""Every ``Hold.kind`` of a failed hold."""


def _to_object(obj: SceneObject, p: FloatArray) -> FloatArray:
    """``p`` (base frame) in the object's frame: centred, x/y along its yawed axes."""
    c, s = math.cos(obj.yaw), math.sin(obj.yaw)
    d = np.asarray(p, dtype=float) - np.asarray(obj.position, dtype=float)
    return np.array([c * d[0] + s * d[1], -s * d[0] + c * d[1], d[2]])


def _dir_to_object(obj: SceneObject, v: FloatArray) -> FloatArray:
    c, s = math.cos(obj.yaw), math.sin(obj.yaw)
    return np.array([c * v[0] + s * v[1], -s * v[0] + c * v[1], v[2]])


Chord = tuple[float, float, FloatArray, FloatArray]
"""``(s0, s1, n0, n1)``: ``p + s u`` is inside the object for ``s0 <= s <= s1``; ``n0``, ``n1`` are the
outward surface normals where the line enters and leaves (object frame)."""


def _box_chord(half: FloatArray, p: FloatArray, u: FloatArray) -> Chord | None:
    """The chord of the axis-aligned box of half-extents ``half`` (slab method)."""
    lo, hi = -math.inf, math.inf
    n_lo, n_hi = np.zeros(3), np.zeros(3)
    for k in range(3):
        if abs(u[k]) < 1e-12:
            if abs(p[k]) > half[k]:
                return None
            continue
        a, b = (-half[k] - p[k]) / u[k], (half[k] - p[k]) / u[k]
        e = np.eye(3)[k]
        (near, n_near), (far, n_far) = sorted(((a, -e), (b, e)), key=lambda x: x[0])
        if near > lo:
            lo, n_lo = near, n_near
        if far < hi:
            hi, n_hi = far, n_far
    return (lo, hi, n_lo, n_hi) if lo <= hi else None


def _cylinder_chord(radius: float, half_h: float, p: FloatArray, u: FloatArray) -> Chord | None:
    """The chord of the upright cylinder (axis z, centred at the origin)."""
    lo, hi = -math.inf, math.inf
    a = u[0] ** 2 + u[1] ** 2
    b = 2.0 * (p[0] * u[0] + p[1] * u[1])
    c = p[0] ** 2 + p[1] ** 2 - radius**2
    side = True
    if a < 1e-12:
        if c > 0.0:
            return None
        side = False
    else:
        disc = b * b - 4.0 * a * c
        if disc < 0.0:
            return None
        r = math.sqrt(disc)
        lo, hi = (-b - r) / (2.0 * a), (-b + r) / (2.0 * a)

    def radial(s_: float) -> FloatArray:
        q = p + s_ * u
        return np.array([q[0], q[1], 0.0]) / radius

    n_lo = radial(lo) if side else np.zeros(3)
    n_hi = radial(hi) if side else np.zeros(3)
    if abs(u[2]) >= 1e-12:
        z0, z1 = (-half_h - p[2]) / u[2], (half_h - p[2]) / u[2]
        (near, n_near), (far, n_far) = sorted(((z0, np.array([0, 0, -1.0])), (z1, np.array([0, 0, 1.0]))),
                                              key=lambda x: x[0])
        if near > lo:
            lo, n_lo = near, n_near
        if far < hi:
            hi, n_hi = far, n_far
    elif abs(p[2]) > half_h:
        return None
    return (lo, hi, n_lo, n_hi) if lo <= hi else None


def _outside_by(obj: SceneObject, q: FloatArray) -> float:
    """How far the object-frame point ``q`` is outside the object (m; 0 inside)."""
    if obj.shape == "box":
        half = np.asarray(obj.size, dtype=float) / 2.0
        return float(np.linalg.norm(np.maximum(np.abs(q) - half, 0.0)))
    if obj.shape == "cylinder":
        radius, half_h = obj.size[0], obj.size[1] / 2.0
        radial = max(math.hypot(q[0], q[1]) - radius, 0.0)
        return math.hypot(radial, max(abs(q[2]) - half_h, 0.0))
    return max(float(np.linalg.norm(q)) - obj.size[0], 0.0)


def _nearest_inside(obj: SceneObject, q: FloatArray) -> FloatArray:
    """The point of the object (object frame) nearest ``q``: ``q`` itself when inside."""
    if obj.shape == "box":
        half = np.asarray(obj.size, dtype=float) / 2.0
        return np.clip(q, -half, half)
    if obj.shape == "cylinder":
        r = math.hypot(q[0], q[1])
        scale = min(1.0, obj.size[0] / r) if r > 1e-12 else 1.0
        return np.array([q[0] * scale, q[1] * scale, float(np.clip(q[2], -obj.size[1] / 2.0, obj.size[1] / 2.0))])
    n = float(np.linalg.norm(q))
    return q * min(1.0, obj.size[0] / n) if n > 1e-12 else q


def _chord(obj: SceneObject, q: FloatArray, u: FloatArray) -> Chord | None:
    if obj.shape == "box":
        return _box_chord(np.asarray(obj.size, dtype=float) / 2.0, q, u)
    if obj.shape == "cylinder":
        return _cylinder_chord(obj.size[0], obj.size[1] / 2.0, q, u)
    r = obj.size[0]  # sphere
    b = float(q @ u)
    disc = b * b - (float(q @ q) - r**2)
    if disc < 0.0:
        return None
    s0, s1 = -b - math.sqrt(disc), -b + math.sqrt(disc)
    return s0, s1, (q + s0 * u) / r, (q + s1 * u) / r


def _slips(u: FloatArray, normal: FloatArray) -> bool:
    """The closing axis ``u`` is outside the friction cone of a contact with outward ``normal``."""
    return abs(float(u @ normal)) < math.cos(math.atan(FRICTION)) - 1e-9


def holds(obj: SceneObject, pose: Pose, grasp_type: GraspType, margin_m: float = HOLD_MARGIN_M,
          opening_m: float = GRIPPER_MAX_OPENING_M) -> Hold:
    """The rule of the module doc for a gripper closed at ``pose`` on ``obj`` with ``grasp_type``."""
    got = classify_grasp(pose, fine=grasp_type in _FINE)
    if got is not grasp_type:
        return Hold(False, f"grasp type {got.value if got else 'none'}, not {grasp_type.value}", WRONG_TYPE)
    q = _to_object(obj, pose.position)
    closing = _dir_to_object(obj, pose.rotation[:, 1])
    top = grasp_type in (GraspType.TOP, GraspType.TOP_HORIZONTAL, GraspType.TOP_VERTICAL)
    if obj.shape == "cylinder" and top and (obj.rim or 2.0 * obj.size[0] > opening_m):
        wall = abs(math.hypot(q[0], q[1]) - obj.size[0])
        depth = obj.size[1] / 2.0 - q[2]  # below the rim
        if wall > opening_m / 2.0:
            return Hold(False, f"the rim is {wall:.3f} m from the TCP, beyond the half opening", RIM_MISSED)
        if not -margin_m <= depth <= FINGER_LENGTH_M:
            return Hold(False, f"the rim is {depth:.3f} m below the TCP, outside the finger pads", RIM_MISSED)
        r = math.hypot(q[0], q[1])
        if r > 1e-9 and _slips(closing, np.array([q[0] / r, q[1] / r, 0.0])):
            return Hold(False, "the fingers pinch the wall outside the friction cone", SLIPS)
        return Hold(True)
    out = _outside_by(obj, q)
    if out > margin_m:
        return Hold(False, f"the TCP is {out:.3f} m outside the object", OUTSIDE)
    q = _nearest_inside(obj, q)  # within the margin: the pads close through the nearest part of the object
    chord = _chord(obj, q, closing)
    if chord is None:  # (only possible within the margin, just outside)
        return Hold(False, "the closing axis misses the object", OUTSIDE)
    s0, s1, n0, n1 = chord
    if s1 - s0 > opening_m + 1e-9:
        return Hold(False, f"the object spans {s1 - s0:.3f} m along the closing axis: wider than the open fingers",
                        TOO_WIDE)
    for s_end, n in ((s0, n0), (s1, n1)):
        normals = [n, *_edge_normals(obj, q + s_end * closing, PAD_HALF_M)]
        if all(_slips(closing, m) for m in normals):
            return Hold(False, "a contact is outside the friction cone: the object would slip out", SLIPS)
    return Hold(True)


def _edge_normals(obj: SceneObject, e: FloatArray, reach_m: float) -> list[FloatArray]:
    """Outward normals of every face the object-frame surface point ``e`` is within ``reach_m`` of."""
    out = []
    if obj.shape == "box":
        half = np.asarray(obj.size, dtype=float) / 2.0
        for k in range(3):
            if abs(abs(e[k]) - half[k]) <= reach_m:
                out.append(np.sign(e[k]) * np.eye(3)[k])
    elif obj.shape == "cylinder":
        r = math.hypot(e[0], e[1])
        if abs(r - obj.size[0]) <= reach_m and r > 1e-9:
            out.append(np.array([e[0] / r, e[1] / r, 0.0]))
        if abs(abs(e[2]) - obj.size[1] / 2.0) <= reach_m:
            out.append(np.array([0.0, 0.0, np.sign(e[2])]))
    return out
