"""Foxglove messages from the daemon's protocol messages (pure functions; ``docs/foxglove.md``).

Inputs are the documented dictionaries of ``docs/protocol.md`` (the ``scene`` reply, a ``state``
message, an event), so the live view, the recorder and a replay build the same messages. Every pose
is in the arm base frame, frame id :data:`FRAME` ("base"), metres; quaternions arrive as
``quat_wxyz`` and leave in Foxglove's ``(x, y, z, w)`` fields.

Topics:

- ``/scene`` (``foxglove.SceneUpdate``): entity ``table``; ``object/<name>`` (primitive and label,
  coloured by the object's share of the belief); ``grasps/<target>`` (one arrow per grasp pose, along
  the approach, ending at the TCP of the grasp, coloured by the target's probability); ``gripper``
  (the TCP, its axes, and the commanded and the user's linear velocities as arrows of length
  ``|v| x`` :data:`TWIST_ARROW_S`).
- ``/belief`` (JSON, schema :data:`BELIEF_SCHEMA`): the target probabilities for the Plot panel.
- ``/log`` (``foxglove.Log``): every event but ``plan`` (questions, answers, faults, stops, scenes...).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from foxglove.messages import (
    ArrowPrimitive,
    Color,
    CubePrimitive,
    CylinderPrimitive,
    Log,
    LogLevel,
    Pose,
    Quaternion,
    SceneEntity,
    SceneEntityDeletion,
    SceneEntityDeletionType,
    SceneUpdate,
    SpherePrimitive,
    TextPrimitive,
    Timestamp,
    Vector3,
)

from ..geometry import quat_mul, quat_to_matrix
from ..world.goals import object_probabilities

FRAME = "base"
"""The frame id of every entity: the arm base frame."""
TWIST_ARROW_S = 1.0
"""A velocity arrow is as long as the distance the velocity covers in this time (s): 0.25 m/s -> 25 cm."""
GRASP_ARROW_M = 0.06
"""Length of a grasp pose's approach arrow (m)."""
AXES_M = 0.05
"""Length of the gripper's axis arrows (m)."""

BELIEF_SCHEMA: dict[str, Any] = {
    "type": "object",
    "title": "sa_daemon.Belief",
    "properties": {
        "t": {"type": "number", "description": "s since the daemon started"},
        "p": {"type": "object", "additionalProperties": {"type": "number"},
              "description": "probability per target, keyed object_grasptype (':' -> '_' for message paths)"},
        "targets": {"type": "array", "items": {"type": "object", "properties": {
            "goal": {"type": "string"}, "p": {"type": "number"}}}},
        "top": {"type": "string", "description": "the most likely target"},
        "top_p": {"type": "number"},
        "action": {"type": "string"},
        "question": {"type": ["string", "null"]},
    },
}

JSON_TOPICS: dict[str, dict[str, Any]] = {"/belief": BELIEF_SCHEMA}
"""The live view's JSON topics and their schemas (the live server and every recording carry them)."""

_OBJECT_GREY = (0.62, 0.62, 0.62)
_OBJECT_HOT = (1.0, 0.55, 0.1)
_LOW = (0.25, 0.45, 0.95)
_HIGH = (0.95, 0.15, 0.1)


def _mix(a: Sequence[float], b: Sequence[float], s: float, alpha: float) -> Color:
    s = min(max(float(s), 0.0), 1.0)
    r, g, bl = (x + (y - x) * s for x, y in zip(a, b, strict=True))
    return Color(r=r, g=g, b=bl, a=alpha)


def probability_color(p: float) -> Color:
    """Blue (p = 0) to red (p = 1), more opaque as ``p`` grows: the grasps' colour scale."""
    return _mix(_LOW, _HIGH, p, 0.35 + 0.65 * min(max(float(p), 0.0), 1.0))


def _pose(position: Sequence[float], quat_wxyz: Sequence[float] = (1.0, 0.0, 0.0, 0.0)) -> Pose:
    w, x, y, z = (float(v) for v in quat_wxyz)
    px, py, pz = (float(v) for v in position)
    return Pose(position=Vector3(x=px, y=py, z=pz), orientation=Quaternion(x=x, y=y, z=z, w=w))


_X_TO_Z = (math.cos(-math.pi / 4), 0.0, math.sin(-math.pi / 4), 0.0)  # -90 deg about y: arrow x -> tool z
_X_TO_Y = (math.cos(math.pi / 4), 0.0, 0.0, math.sin(math.pi / 4))  # +90 deg about z: arrow x -> tool y


def _arrow_dims(length: float, diameter: float) -> dict[str, float]:
    """An arrow's shaft and head (m) for a total ``length``: the head 30 % of it, at most 2 cm, and 2.5
    times as wide as the shaft."""
    head = min(0.3 * length, 0.02)
    return {"shaft_length": max(length - head, 0.0), "shaft_diameter": diameter, "head_length": head,
            "head_diameter": 2.5 * diameter}


def _arrow(tail: Sequence[float], quat_wxyz: Sequence[float], length: float, color: Color,
           diameter: float = 0.006) -> ArrowPrimitive:
    """An arrow from ``tail`` along the +x axis of ``quat_wxyz``, ``length`` m long in total."""
    return ArrowPrimitive(pose=_pose(tail, quat_wxyz), color=color, **_arrow_dims(length, diameter))


def _direction_quat(v: Sequence[float]) -> tuple[float, float, float, float]:
    """A quaternion (wxyz) turning +x onto the unit vector along ``v`` (``v`` non-zero)."""
    n = math.sqrt(sum(c * c for c in v))
    ux, uy, uz = (c / n for c in v)
    # half-way quaternion between x = (1, 0, 0) and u
    w, x, y, z = 1.0 + ux, 0.0, -uz, uy
    if w < 1e-9:  # u = -x: half a turn about z
        return (0.0, 0.0, 0.0, 1.0)
    m = math.sqrt(w * w + x * x + y * y + z * z)
    return (w / m, x / m, y / m, z / m)


def _ts(t_ns: int) -> Timestamp:
    return Timestamp(sec=t_ns // 1_000_000_000, nsec=t_ns % 1_000_000_000)


def _object_entity(obj: Mapping[str, Any], share: float, stamp: Timestamp) -> SceneEntity:
    shape, size, pos = obj["shape"], [float(s) for s in obj["size"]], obj["position"]
    yaw = float(obj.get("yaw", 0.0))
    q = (math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2))
    color = _mix(_OBJECT_GREY, _OBJECT_HOT, share, 0.85)
    cubes, cylinders, spheres = [], [], []
    if shape == "box":
        cubes.append(CubePrimitive(pose=_pose(pos, q), size=Vector3(x=size[0], y=size[1], z=size[2]), color=color))
        top = size[2] / 2
    elif shape == "cylinder":
        d = 2 * size[0]
        cylinders.append(CylinderPrimitive(pose=_pose(pos, q), size=Vector3(x=d, y=d, z=size[1]),
                                           bottom_scale=1.0, top_scale=1.0, color=color))
        top = size[1] / 2
    else:
        d = 2 * size[0]
        spheres.append(SpherePrimitive(pose=_pose(pos), size=Vector3(x=d, y=d, z=d), color=color))
        top = size[0]
    label = TextPrimitive(pose=_pose((pos[0], pos[1], pos[2] + top + 0.04)), billboard=True, font_size=14.0,
                          scale_invariant=True, color=Color(r=1.0, g=1.0, b=1.0, a=1.0),
                          text=f"{obj['name']} {share:.2f}")
    return SceneEntity(timestamp=stamp, frame_id=FRAME, id=f"object/{obj['name']}", cubes=cubes,
                       cylinders=cylinders, spheres=spheres, texts=[label])


def _grasp_arrow_poses(poses: Sequence[Mapping[str, Any]]) -> list[Pose]:
    """Each grasp pose's arrow: its tail :data:`GRASP_ARROW_M` back along the approach (tool z), +x
    along the approach, so that it ends at the grasp's TCP."""
    out = []
    for pose in poses:
        q = pose["quat_wxyz"]
        approach = quat_to_matrix(q)[:, 2]  # tool z
        out.append(_pose(np.asarray(pose["position"]) - GRASP_ARROW_M * approach, quat_mul(q, _X_TO_Z)))
    return out


def _table_entity(scene: Mapping[str, Any], stamp: Timestamp) -> SceneEntity:
    xs = [float(o["position"][0]) for o in scene["objects"]] or [0.4]
    ys = [float(o["position"][1]) for o in scene["objects"]] or [0.0]
    lo_x, hi_x, lo_y, hi_y = min(xs) - 0.2, max(xs) + 0.2, min(ys) - 0.2, max(ys) + 0.2
    z = float(scene["table_z"])
    cube = CubePrimitive(pose=_pose(((lo_x + hi_x) / 2, (lo_y + hi_y) / 2, z - 0.01)),
                         size=Vector3(x=hi_x - lo_x, y=hi_y - lo_y, z=0.02),
                         color=Color(r=0.55, g=0.42, b=0.3, a=0.6))
    return SceneEntity(timestamp=stamp, frame_id=FRAME, id="table", cubes=[cube])


class SceneDrawing:
    """The table, the objects and every target's grasp poses of one ``scene`` reply; the geometry is
    computed once, :meth:`update` colours it by a belief (the feed redraws it often)."""

    def __init__(self, scene: Mapping[str, Any]) -> None:
        self._scene = scene
        self._arrows = {g["target"]: _grasp_arrow_poses(g["poses"]) for g in scene["goals"]}
        self._arrow_shape = _arrow_dims(GRASP_ARROW_M, 0.003)

    def update(self, belief: Mapping[str, float], t_ns: int, replace: bool = False) -> SceneUpdate:
        """Every entity coloured by ``belief`` (target -> probability; a target missing from it is drawn
        at 0). With ``replace`` every entity of an earlier scene is deleted first."""
        stamp = _ts(t_ns)
        shares = object_probabilities(belief)
        entities = [_table_entity(self._scene, stamp)]
        entities += [_object_entity(o, shares.get(o["name"], 0.0), stamp) for o in self._scene["objects"]]
        for target, poses in self._arrows.items():
            color = probability_color(float(belief.get(target, 0.0)))
            arrows = [ArrowPrimitive(pose=p, color=color, **self._arrow_shape) for p in poses]
            entities.append(SceneEntity(timestamp=stamp, frame_id=FRAME, id=f"grasps/{target}", arrows=arrows))
        deletions = [SceneEntityDeletion(timestamp=stamp, type=SceneEntityDeletionType.All)] if replace else []
        return SceneUpdate(deletions=deletions, entities=entities)


def scene_update(scene: Mapping[str, Any], belief: Mapping[str, float], t_ns: int,
                 replace: bool = False) -> SceneUpdate:
    """:meth:`SceneDrawing.update` of ``scene`` (drawn once)."""
    return SceneDrawing(scene).update(belief, t_ns, replace)


def gripper_update(state: Mapping[str, Any], t_ns: int) -> SceneUpdate:
    """The gripper (TCP sphere and axes) and its commanded and user linear velocities, from a ``state``
    message (nothing when the state has no pose)."""
    pose = state.get("gripper_pose")
    if not pose:
        return SceneUpdate()
    p, q = pose["position"], pose["quat_wxyz"]
    closed = bool(state.get("gripper_closed"))
    q_y, q_z = quat_mul(q, (_X_TO_Y, _X_TO_Z))  # the arrows along tool y and tool z
    arrows = [_arrow(p, q, AXES_M, Color(r=1.0, g=0.1, b=0.1, a=1.0)),
              _arrow(p, q_y, AXES_M, Color(r=0.1, g=0.9, b=0.1, a=1.0)),
              _arrow(p, q_z, AXES_M, Color(r=0.1, g=0.3, b=1.0, a=1.0))]
    for key, color in (("command_twist", Color(r=0.75, g=0.2, b=0.95, a=0.9)),
                       ("user_twist", Color(r=0.1, g=0.85, b=0.85, a=0.9))):
        v = [float(c) for c in state.get(key, [0.0] * 6)[:3]]
        speed = math.sqrt(sum(c * c for c in v))
        if speed > 1e-4:
            arrows.append(_arrow(p, _direction_quat(v), speed * TWIST_ARROW_S, color, diameter=0.008))
    tcp = SpherePrimitive(pose=_pose(p, q), size=Vector3(x=0.03, y=0.03, z=0.03),
                          color=Color(r=0.2, g=0.2, b=0.2, a=1.0) if closed else Color(r=0.9, g=0.9, b=0.9, a=1.0))
    entity = SceneEntity(timestamp=_ts(t_ns), frame_id=FRAME, id="gripper", arrows=arrows, spheres=[tcp])
    return SceneUpdate(entities=[entity])


def belief_message(state: Mapping[str, Any]) -> dict[str, Any]:
    """The ``/belief`` message of a ``state`` message (:data:`BELIEF_SCHEMA`)."""
    targets = [{"goal": b["goal"], "p": float(b["p"])} for b in state.get("belief", [])]
    top = max(targets, key=lambda b: b["p"]) if targets else {"goal": "", "p": 0.0}
    action = state.get("action") or {}
    label = action.get("kind", "") + (f" {action['goal']}" if action.get("goal") else "")
    return {"t": state.get("t", 0.0), "p": {b["goal"].replace(":", "_"): b["p"] for b in targets},
            "targets": targets, "top": top["goal"], "top_p": top["p"], "action": label,
            "question": state.get("question")}


_ERRORS = frozenset({"fault", "planner_error", "planner_exit"})
_WARNINGS = frozenset({"stop", "question_timeout", "input_lost", "input_refused", "planner_late", "planner_restart",
                       "speech_unavailable", "voice_unavailable", "speech_player_missing"})
_NOT_LOGGED = frozenset({"plan"})


def event_log(event: Mapping[str, Any], t_ns: int) -> Log | None:
    """The ``/log`` message of an event (``docs/protocol.md``): every kind but ``plan``, at level Error
    for faults, Warning for stops, timeouts and lost input, Info otherwise; ``None`` for a ``plan``."""
    kind = str(event.get("type", ""))
    if kind in _NOT_LOGGED:
        return None
    level = LogLevel.Error if kind in _ERRORS else LogLevel.Warning if kind in _WARNINGS else LogLevel.Info
    fields = " ".join(f"{k}={v}" for k, v in event.items() if k not in ("t", "type"))
    return Log(timestamp=_ts(t_ns), level=level, message=f"{kind} {fields}".strip(), name="sa-daemon")
