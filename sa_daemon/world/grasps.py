"""Grasp poses: analytic generation from primitive shapes, grasp-type classification and reachability.

Frames (see ``docs/scenes.md``): the arm base frame has x forward, y left, z up, the shoulder at
(0, 0, 0.267) m; the table top is at ``table_z`` (m, base frame; a scene setting, 0 unless given), and the
heights the reach filter and the side-grasp pitch look at are taken above it. A grasp is a :class:`~sa_daemon.geometry.Pose` of the tool frame:
z is the approach direction (from the gripper into the object), y the fingers' closing axis,
x = y cross z, and the position is the TCP between the fingertips. Lengths in m, angles in rad.

Classification (the same rule for generated and raw grasps): *top* if the approach is within 30 deg of
straight down, *side* if it is within 30 deg of the horizontal plane, otherwise no type. A side grasp is
*side_horizontal* if the closing axis is closer to horizontal than vertical (``|y_z| < sqrt(0.5)``), else
*side_vertical*; a top grasp is *top_horizontal* if the closing axis is at least as close to base y as to
base x (``|y . e_y| >= |y . e_x|``), else *top_vertical*.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence

import numpy as np

from ..geometry import FloatArray, Pose
from .goals import GraspType

GRIPPER_MAX_OPENING_M = 0.085
"""Widest object extent (m) the xArm gripper can close on (rim grasps pinch a wall instead)."""
TCP_OFFSET_M = 0.172
"""Distance (m) from the wrist flange to the TCP along tool z."""
SHOULDER_M: FloatArray = np.array([0.0, 0.0, 0.267])
"""Shoulder point (m) in the base frame, centre of the reachability sphere."""
REACH_M = 0.70
"""Largest wrist-point distance (m) from the shoulder accepted by :func:`is_reachable`."""
MIN_WRIST_HEIGHT_M = 0.03
"""Lowest wrist-point height above the table top (m) accepted by :func:`is_reachable`."""
MIN_TCP_HEIGHT_M = 0.005
"""Lowest TCP height above the table top (m) accepted by :func:`is_reachable`."""
CONE_RAD = math.radians(30.0)
"""Half-angle of the top and side approach cones (rad)."""

GRASP_DEPTH_M = 0.02  # TCP this far below a top surface / inside a face (at most half the extent)
RIM_DEPTH_M = 0.015  # rim grasps: TCP this far below the rim
RIM_INSET_M = 0.003  # rim grasps: TCP this far inside the outer radius (the middle of the wall)
LOW_TCP_HEIGHT_M = 0.05  # side grasps with a TCP lower than this above the table approach pitched down ...
SIDE_PITCH_RAD = math.radians(25.0)  # ... by this angle, keeping the wrist off the table
TALL_M = 0.12  # side grasps of objects taller than this at two heights instead of one
LONG_M = 0.10  # grasps along objects longer than this at three points instead of one
MAX_FACE_ANGLE_RAD = math.radians(120.0)  # box faces approached at most this far from the bearing
MAX_BASE_GRASPS = 8  # per goal before adding flips, so at most 16 poses per goal
SHAPE_SIZES = {"box": "[x, y, z]", "cylinder": "[radius, height]", "sphere": "[radius]"}
"""Shapes and the meaning of their ``size`` lists (m); box sizes are full extents in the object frame."""

_TOL = 1e-9
_COS_CONE = math.cos(CONE_RAD)
_SIN_CONE = math.sin(CONE_RAD)
_UP = np.array([0.0, 0.0, 1.0])
_DOWN = -_UP
_ALLOWED_AXES = {
    GraspType.TOP: "any horizontal axis",
    GraspType.TOP_HORIZONTAL: "a horizontal axis within 45 deg of base y",
    GraspType.TOP_VERTICAL: "a horizontal axis within 45 deg of base x",
    GraspType.SIDE: "the horizontal or the vertical axis",
    GraspType.SIDE_HORIZONTAL: "a horizontal axis",
    GraspType.SIDE_VERTICAL: "the vertical axis",
}


class GraspInfeasibleError(ValueError):
    """A grasp type cannot be realised on a primitive with the gripper's opening."""


class UnreachableGraspError(ValueError):
    """Every grasp pose of a type fails :func:`is_reachable`."""


def classify_grasp(pose: Pose, fine: bool) -> GraspType | None:
    """Grasp type of ``pose`` by the rule in the module docstring; ``None`` if it fits no type.

    ``fine=False`` gives ``top``/``side``; ``fine=True`` the four fine types. Boundaries are inclusive
    (exactly 30 deg is still top/side); ties of the closing-axis rule go to top_horizontal and
    side_vertical.
    """
    rot = pose.rotation
    y, z = rot[:, 1], rot[:, 2]
    if z[2] <= -_COS_CONE + _TOL:  # angle between z and -Z_base <= 30 deg
        if not fine:
            return GraspType.TOP
        return GraspType.TOP_HORIZONTAL if abs(y[1]) >= abs(y[0]) - _TOL else GraspType.TOP_VERTICAL
    if abs(z[2]) <= _SIN_CONE + _TOL:  # |elevation of z| <= 30 deg
        if not fine:
            return GraspType.SIDE
        return GraspType.SIDE_HORIZONTAL if abs(y[2]) < math.sqrt(0.5) - _TOL else GraspType.SIDE_VERTICAL
    return None


def cluster_grasps(
    poses: Iterable[Pose], grasp_types: Iterable[GraspType | str]
) -> dict[GraspType, list[Pose]]:
    """Sort raw, untyped grasps (e.g. from GPD) into the listed types, keeping their order.

    A pose goes to every listed type it matches (``top`` and ``top_vertical`` can share one); poses
    matching none are dropped. Every listed type is a key, possibly with an empty list. No
    reachability filtering here.
    """
    types = [GraspType(t) for t in grasp_types]
    out: dict[GraspType, list[Pose]] = {t: [] for t in types}
    for pose in poses:
        found = (classify_grasp(pose, fine=False), classify_grasp(pose, fine=True))
        for t, kept in out.items():
            if t in found:
                kept.append(pose)
    return out


def wrist_point(pose: Pose) -> FloatArray:
    """Wrist-flange point (m): ``tcp - 0.172 * z_tool``."""
    return pose.position - TCP_OFFSET_M * pose.rotation[:, 2]


def is_reachable(pose: Pose, table_z: float = 0.0) -> bool:
    """Crude reachability: wrist point within 0.70 m of the shoulder (0, 0, 0.267) and at least 0.03 m
    above the table top at ``table_z`` (m, base frame), TCP at least 0.005 m above it. The sphere
    is the arm's reach; the heights keep the wrist and fingers off the table. One function so an
    IK-based check can replace it."""
    w = wrist_point(pose)
    return bool(
        np.linalg.norm(w - SHOULDER_M) <= REACH_M
        and w[2] >= table_z + MIN_WRIST_HEIGHT_M
        and pose.position[2] >= table_z + MIN_TCP_HEIGHT_M
    )


def flip_grasp(pose: Pose) -> Pose:
    """The parallel-jaw twin of ``pose``: rotated 180 deg about tool z (same approach, y reversed)."""
    rot = pose.rotation * np.array([-1.0, -1.0, 1.0])
    return Pose.from_matrix(pose.position, rot)


def grasp_pose(tcp: Sequence[float] | FloatArray, approach: FloatArray, closing: FloatArray) -> Pose:
    """Pose with tool z along ``approach`` and tool y along ``closing`` made orthogonal to it."""
    z = np.asarray(approach, dtype=float)
    z = z / np.linalg.norm(z)
    y = np.asarray(closing, dtype=float)
    y = y - np.dot(y, z) * z
    y = y / np.linalg.norm(y)
    return Pose.from_matrix(tcp, np.column_stack((np.cross(y, z), y, z)))


def check_primitive(
    shape: str, size: Sequence[float], position: Sequence[float]
) -> tuple[FloatArray, FloatArray]:
    """Validated ``(size, position)`` arrays; raises ``ValueError`` for an unknown shape, a size list of
    the wrong length, non-positive or non-finite sizes, or a bad position."""
    if shape not in SHAPE_SIZES:
        raise ValueError(f"unknown shape {shape!r} (one of {', '.join(SHAPE_SIZES)})")
    s = np.asarray(size, dtype=float).reshape(-1)
    if s.shape != ({"box": 3, "cylinder": 2, "sphere": 1}[shape],):
        raise ValueError(f"{shape} needs {SHAPE_SIZES[shape]}, got {list(size)}")
    if not np.all(np.isfinite(s)) or np.any(s <= 0.0):
        raise ValueError(f"{shape} size must be positive and finite (m), got {list(size)}")
    p = np.asarray(position, dtype=float).reshape(-1)
    if p.shape != (3,) or not np.all(np.isfinite(p)):
        raise ValueError(f"position must be 3 finite numbers (m), got {list(position)}")
    return s, p


def _horizontal(angle: float) -> FloatArray:
    return np.array([math.cos(angle), math.sin(angle), 0.0])


def _offsets(length: float) -> list[float]:
    """Grasp points along an extent (m): the middle, plus the quarter points on long objects."""
    return [0.0] if length <= LONG_M else [-length / 4.0, 0.0, length / 4.0]


def _heights(centre_z: float, height: float) -> list[float]:
    """TCP heights (m) of side grasps: the middle, or the thirds of tall objects."""
    n = 1 if height <= TALL_M else 2
    bottom = centre_z - height / 2.0
    return [bottom + height * (i + 1) / (n + 1) for i in range(n)]


def _pitch(tcp_height: float) -> float:
    """Downward pitch (rad) of a side approach: 25 deg when the TCP is low above the table (still a side
    grasp), else 0. Candidates are generated with the table top at z = 0, so heights are z."""
    return SIDE_PITCH_RAD if tcp_height < LOW_TCP_HEIGHT_M - _TOL else 0.0  # tolerance: lifted frames round


def _side_approach(direction: FloatArray, tcp_z: float) -> FloatArray:
    """Horizontal unit ``direction`` pitched down by :func:`_pitch`."""
    pitch = _pitch(tcp_z)
    return math.cos(pitch) * direction + math.sin(pitch) * _DOWN


def _top_candidates(shape: str, s: FloatArray, c: FloatArray, yaw: float, rim: bool) -> list[Pose]:
    """Straight-down grasps that fit the gripper, any closing direction."""
    opening = GRIPPER_MAX_OPENING_M
    if shape == "cylinder" and (rim or 2.0 * s[0] > opening):
        # Containers: pinch the wall at 8 points round the rim, closing axis radial.
        z = c[2] + s[1] / 2.0 - min(RIM_DEPTH_M, s[1] / 2.0)
        out = []
        for k in range(8):
            u = _horizontal(math.pi / 8.0 + k * math.pi / 4.0)
            tcp = c + (s[0] - RIM_INSET_M) * u
            out.append(grasp_pose([tcp[0], tcp[1], z], _DOWN, u))
        return out
    if shape == "box":
        z = c[2] + s[2] / 2.0 - min(GRASP_DEPTH_M, s[2] / 2.0)
        out = []
        for axis in (0, 1):  # close across the local x faces, then across the local y faces
            if s[axis] > opening:
                continue
            closing = _horizontal(yaw + axis * math.pi / 2.0)
            along = _horizontal(yaw + (1 - axis) * math.pi / 2.0)
            for off in _offsets(s[1 - axis]):
                tcp = c + off * along
                out.append(grasp_pose([tcp[0], tcp[1], z], _DOWN, closing))
        return out
    if 2.0 * s[0] > opening:
        return []
    # Narrow cylinder or sphere: across the top at closing angles every 30 deg.
    z = c[2] if shape == "sphere" else c[2] + s[1] / 2.0 - min(GRASP_DEPTH_M, s[1] / 2.0)
    return [grasp_pose([c[0], c[1], z], _DOWN, _horizontal(math.radians(a))) for a in range(0, 180, 30)]


def _side_candidates(shape: str, s: FloatArray, c: FloatArray, yaw: float) -> list[Pose]:
    """Near-horizontal grasps that fit the gripper, from the robot's side of the object."""
    opening = GRIPPER_MAX_OPENING_M
    bearing = math.atan2(c[1], c[0]) if np.hypot(c[0], c[1]) > 1e-9 else 0.0
    out = []
    if shape in ("cylinder", "sphere"):
        radius = s[0]
        height = s[1] if shape == "cylinder" else 2.0 * radius
        heights = _heights(c[2], height)
        relative = (-90, -45, 0, 45, 90) if len(heights) == 1 else (-45, 0, 45)
        for z in heights:
            for rel in relative:
                u = _horizontal(bearing + math.radians(rel))
                approach = _side_approach(u, z)
                tcp = np.array([c[0], c[1], z])
                if 2.0 * radius <= opening:  # across the diameter, TCP on the axis
                    out.append(grasp_pose(tcp, approach, np.cross(_UP, u)))
                if height / math.cos(_pitch(z)) <= opening:  # top to bottom (tilted when pitched)
                    # a cylinder's TCP just inside its near surface, a sphere's at its centre
                    inset = 0.0 if shape == "sphere" else radius - min(GRASP_DEPTH_M, radius)
                    out.append(grasp_pose(tcp - inset * u, approach, _UP))
        return out
    for axis in (0, 1):
        for sign in (1.0, -1.0):
            normal = sign * _horizontal(yaw + axis * math.pi / 2.0)  # outward normal of the face
            u = -normal
            if math.acos(np.clip(np.dot(u, _horizontal(bearing)), -1.0, 1.0)) > MAX_FACE_ANGLE_RAD + _TOL:
                continue  # would reach round behind the object
            along = _horizontal(yaw + (1 - axis) * math.pi / 2.0)
            face = c + normal * (s[axis] / 2.0 - min(GRASP_DEPTH_M, s[axis] / 2.0))
            if s[1 - axis] <= opening:  # horizontal closing across the face
                for z in _heights(c[2], s[2]):
                    out.append(grasp_pose([face[0], face[1], z], _side_approach(u, z), along))
            if s[2] / math.cos(_pitch(c[2])) <= opening:  # vertical closing, top to bottom
                for off in _offsets(s[1 - axis]):
                    tcp = face + off * along
                    out.append(grasp_pose(tcp, _side_approach(u, c[2]), _UP))
    return out


def _thin(poses: list[Pose], limit: int) -> list[Pose]:
    """At most ``limit`` poses, evenly spread over the list (order kept)."""
    if len(poses) <= limit:
        return poses
    idx = np.unique(np.round(np.linspace(0, len(poses) - 1, limit)).astype(int))
    return [poses[i] for i in idx]


def generate_grasps(
    shape: str,
    size: Sequence[float],
    position: Sequence[float],
    yaw: float,
    grasp_type: GraspType | str,
    rim: bool = False,
    table_z: float = 0.0,
) -> list[Pose]:
    """Reachable grasp poses of one type on a primitive, each followed by its 180-deg flip.

    ``shape``: ``box`` (``size`` = full extents [x, y, z] in the object frame, turned by ``yaw`` rad about
    base z), ``cylinder`` (``[radius, height]``, upright) or ``sphere`` (``[radius]``); ``position`` is the
    shape's centre (m, base frame) and ``table_z`` the table top's height (m, base frame). Top grasps of a cylinder with ``rim`` or wider than the gripper pinch
    its wall at 8 points round the rim. At most 16 poses, in a deterministic order.

    Raises :class:`GraspInfeasibleError` if no pose of the type fits the gripper, and
    :class:`UnreachableGraspError` if none passes :func:`is_reachable` (both are ``ValueError``).
    """
    s, c = check_primitive(shape, size, position)
    gt = GraspType(grasp_type)
    if rim and shape != "cylinder":
        raise ValueError(f"rim grasps need a cylinder, not a {shape}")
    yaw = float(yaw)
    if not math.isfinite(yaw):
        raise ValueError(f"yaw must be finite (rad), got {yaw}")
    table_z = float(table_z)
    if not math.isfinite(table_z):
        raise ValueError(f"table_z must be finite (m), got {table_z}")
    fine = gt not in (GraspType.TOP, GraspType.SIDE)
    # Generated in a frame with the table top at z = 0 (only _pitch looks at heights), then lifted back.
    lift = np.array([0.0, 0.0, table_z])
    c_table = c - lift
    cands = _top_candidates(shape, s, c_table, yaw, rim) if gt.is_top else _side_candidates(shape, s, c_table, yaw)
    typed = [Pose(p.position + lift, p.quat_wxyz) for p in cands if classify_grasp(p, fine) == gt]
    if not typed:
        raise GraspInfeasibleError(
            f"cannot generate {gt.value} grasps for a {shape} of size {s.tolist()} m at yaw {yaw:.3f} rad: "
            f"its extent along every closing axis a {gt.value} grasp allows ({_ALLOWED_AXES[gt]}) exceeds "
            f"the {GRIPPER_MAX_OPENING_M} m gripper opening"
            + (" (set rim = true for containers)" if gt.is_top and shape == "cylinder" else "")
        )
    reachable = [p for p in typed if is_reachable(p, table_z)]
    if not reachable:
        raise UnreachableGraspError(
            f"no reachable {gt.value} grasp pose for the {shape} at {c.tolist()} m: each needs its wrist "
            f"point within {REACH_M} m of the shoulder {SHOULDER_M.tolist()}, the wrist >= {MIN_WRIST_HEIGHT_M} m "
            f"and the TCP >= {MIN_TCP_HEIGHT_M} m above the table top (z = {table_z} m)"
        )
    return [q for p in _thin(reachable, MAX_BASE_GRASPS) for q in (p, flip_grasp(p))]
