"""Scenes at run time (``set_scene``, ``docs/protocol.md``): a scene from a perception pipeline.

The request's ``scene`` is the scene file's format as JSON (``docs/scenes.md``): objects as primitives
with grasp types, or with the raw untyped grasp poses a grasp detector gives (sorted into types by the
scene's own rule). ``start`` may be left out (the running scene's is kept). ``marker_to_base``
(``{position, quat_wxyz}``) maps a scene given in a marker's frame into the arm's base frame; objects
stay upright, so its rotation must be about the vertical. Everything is validated with the scene file's
rules (errors name the object and the field) before anything changes.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..geometry import Pose, quat_mul, quat_to_matrix
from .scene import Scene, SceneError, scene_from_dict

#: A scene larger than this is refused (a detector gone wrong must not stall the planner).
MAX_OBJECTS = 64
MAX_GRASPS = 2000
#: How far from vertical ``marker_to_base`` may turn the vertical (rad): objects stand upright.
MAX_TILT_RAD = math.radians(1.0)


def _transform(data: dict[str, Any], t: Pose) -> dict[str, Any]:
    """``data`` (scene JSON, marker frame) in the base frame under ``t`` (a rotation about z)."""
    r = quat_to_matrix(t.quat_wxyz)
    yaw = math.atan2(r[1, 0], r[0, 0])
    out = dict(data)
    objs = []
    for o in data.get("objects", []):
        o = dict(o)
        if isinstance(o.get("position"), list) and len(o["position"]) == 3:
            o["position"] = (r @ np.asarray(o["position"], dtype=float) + t.position).tolist()
        o["yaw"] = float(o.get("yaw", 0.0)) + yaw
        grasps = []
        for g in o.get("grasps") or []:
            g = dict(g)
            if isinstance(g.get("position"), list) and len(g["position"]) == 3:
                g["position"] = (r @ np.asarray(g["position"], dtype=float) + t.position).tolist()
            if isinstance(g.get("quat_wxyz"), list) and len(g["quat_wxyz"]) == 4:
                g["quat_wxyz"] = quat_mul(t.quat_wxyz, np.asarray(g["quat_wxyz"], dtype=float)).tolist()
            elif g.get("rpy") is not None:
                raise SceneError("set_scene: marker_to_base: give grasps as quat_wxyz, not rpy, with a transform")
            grasps.append(g)
        if o.get("grasps") is not None:
            o["grasps"] = grasps
        objs.append(o)
    out["objects"] = objs
    return out


def scene_from_request(args: dict[str, Any], current: Scene) -> Scene:
    """The scene a ``set_scene`` request describes; :class:`SceneError` naming the part otherwise."""
    data = args.get("scene")
    if not isinstance(data, dict):
        raise SceneError("set_scene: scene: must be an object (the scene file's format as JSON)")
    objects = data.get("objects")
    if isinstance(objects, list):
        if len(objects) > MAX_OBJECTS:
            raise SceneError(f"set_scene: objects: {len(objects)} objects, more than {MAX_OBJECTS}")
        n = sum(len(o["grasps"]) for o in objects if isinstance(o, dict) and isinstance(o.get("grasps"), list))
        if n > MAX_GRASPS:
            raise SceneError(f"set_scene: grasps: {n} grasp poses, more than {MAX_GRASPS}")
    if "start" not in data:
        data = {**data, "start": {"position": current.start.position.tolist(),
                                  "quat_wxyz": current.start.quat_wxyz.tolist()}}
    if args.get("marker_to_base") is not None:
        m = args["marker_to_base"]
        try:
            t = Pose(m["position"], m["quat_wxyz"])
        except (KeyError, TypeError, ValueError) as e:
            raise SceneError(f"set_scene: marker_to_base: needs position (m) and quat_wxyz, finite: {e}") from None
        if math.acos(min(1.0, abs(float(quat_to_matrix(t.quat_wxyz)[2, 2])))) > MAX_TILT_RAD:
            raise SceneError("set_scene: marker_to_base: its rotation must be about the vertical (objects stand upright)")
        data = _transform(data, t)
    return scene_from_dict(data, "set_scene")
