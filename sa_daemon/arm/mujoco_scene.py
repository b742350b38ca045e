"""The MuJoCo world of a scene: the xArm-6 of ``xarm6.xml`` on a pedestal, a table and the scene's objects.

Frames and units as in the scene files: base frame x forward, y left, z up (m); the arm base is at the
origin and the table top at the scene's ``table_z`` (0.2 m in the built-in scenes: a wheelchair mount
below a 0.75 m table). The floor is ``TABLE_HEIGHT_M`` below the table top and the arm stands on a
pedestal from the floor to its base. The table starts at ``TABLE_X0_M`` in front of the base, so the
base never touches it. Every object is a free body resting on the table:
boxes, cylinders and spheres with the scene's sizes, position and yaw. Containers (``rim = true``) are
hollow - a bottom and a wall of ``WALL_SEGMENTS`` boxes, ``WALL_M`` thick - so rim grasps, whose TCP sits
in the middle of the wall, pinch a real wall with one finger inside.

Masses are not in the scene files: solids have the density ``SOLID_DENSITY`` (light household goods,
e.g. a 0.25 m chips can weighs 0.32 kg), container walls ``WALL_DENSITY`` (a 0.1 m cup about 0.15 kg).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from ..world.scene import Scene, SceneObject
from .kinematics import model_path

TABLE_X0_M = 0.12
"""Near edge of the table (m, base x); the base cylinder has a 0.065 m radius."""
TABLE_SIZE_M = (0.9, 1.4, 0.04)
"""Table extent along x, y and thickness (m)."""
TABLE_HEIGHT_M = 0.75
"""Table top above the floor (m); the arm's pedestal fills the floor-to-base gap."""
WALL_M = 0.006
"""Wall thickness of containers (m): twice the grasp generator's 3 mm rim inset."""
WALL_SEGMENTS = 16
"""Boxes making up a container wall; one faces every rim and side grasp direction (multiples of pi/8)."""
BOTTOM_M = 0.005
"""Bottom thickness of containers (m)."""
SOLID_DENSITY = 300.0
"""kg/m^3 of solid objects."""
WALL_DENSITY = 1000.0
"""kg/m^3 of container walls and bottoms."""
OBJECT_FRICTION = (1.0, 0.01, 0.0001)
"""Sliding, torsional (m) and rolling (m) friction of objects and table."""
OBJECT_PREFIX = "object/"
"""Body names of scene objects are this prefix + the object's name."""

# Collision classes: arm geoms have contype 1, conaffinity 2 (xarm6.xml); world and objects touch both.
_WORLD_CONTYPE = 2
_WORLD_CONAFFINITY = 3


@dataclass(frozen=True)
class SceneModel:
    """A compiled world: ``model``, and the scene objects' names with their body ids (same order)."""

    model: mujoco.MjModel
    object_names: tuple[str, ...]
    object_bodies: tuple[int, ...]


def _yaw_quat(yaw: float) -> list[float]:
    return [math.cos(yaw / 2.0), 0.0, 0.0, math.sin(yaw / 2.0)]


def _world_geom(parent: mujoco.MjsBody, **kw) -> mujoco.MjsGeom:
    g = parent.add_geom(**kw)
    g.contype = _WORLD_CONTYPE
    g.conaffinity = _WORLD_CONAFFINITY
    g.friction = list(OBJECT_FRICTION)
    return g


def _add_object(world: mujoco.MjsBody, obj: SceneObject) -> None:
    body = world.add_body(name=OBJECT_PREFIX + obj.name, pos=list(obj.position), quat=_yaw_quat(obj.yaw))
    body.add_freejoint(name=OBJECT_PREFIX + obj.name)
    rgba = [0.9, 0.55, 0.2, 1.0]
    if obj.shape == "box":
        sx, sy, sz = obj.size
        _world_geom(body, type=mujoco.mjtGeom.mjGEOM_BOX, size=[sx / 2, sy / 2, sz / 2], density=SOLID_DENSITY,
                    rgba=rgba)
    elif obj.shape == "sphere":
        _world_geom(body, type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[obj.size[0], 0, 0], density=SOLID_DENSITY,
                    rgba=rgba)
    elif not obj.rim:
        r, h = obj.size
        _world_geom(body, type=mujoco.mjtGeom.mjGEOM_CYLINDER, size=[r, h / 2, 0], density=SOLID_DENSITY,
                    rgba=rgba)
    else:
        r, h = obj.size
        bottom = min(BOTTOM_M, h / 4)
        _world_geom(body, type=mujoco.mjtGeom.mjGEOM_CYLINDER, size=[r, bottom / 2, 0],
                    pos=[0, 0, -h / 2 + bottom / 2], density=WALL_DENSITY, rgba=rgba)
        # Segment k faces angle k pi/8; its outer face is tangent to the radius r at its middle. The wall
        # stands on the bottom, so only the bottom touches the table (16 boxes on it cost 64 contacts).
        half_chord = r * math.tan(math.pi / WALL_SEGMENTS)
        wall_h = h - bottom
        rc = r - WALL_M / 2
        for k in range(WALL_SEGMENTS):
            a = 2 * math.pi * k / WALL_SEGMENTS
            _world_geom(body, type=mujoco.mjtGeom.mjGEOM_BOX, size=[WALL_M / 2, half_chord, wall_h / 2],
                        pos=[rc * math.cos(a), rc * math.sin(a), bottom / 2], quat=_yaw_quat(a),
                        density=WALL_DENSITY, rgba=rgba)


def build_scene_model(scene: Scene, timestep_s: float, arm_xml: str | Path | None = None) -> SceneModel:
    """Compile the arm, table, pedestal, floor, light and ``scene``'s objects into one ``MjModel``."""
    spec = mujoco.MjSpec.from_file(str(arm_xml or model_path()))
    spec.option.timestep = float(timestep_s)
    spec.visual.global_.offwidth = 1280
    spec.visual.global_.offheight = 960
    world = spec.worldbody
    tx, ty, tz = TABLE_SIZE_M
    top = scene.table_z
    floor = top - TABLE_HEIGHT_M  # below the base for every accepted table_z (<= 0.5 m)
    _world_geom(world, name="table", type=mujoco.mjtGeom.mjGEOM_BOX, size=[tx / 2, ty / 2, tz / 2],
                pos=[TABLE_X0_M + tx / 2, 0.0, top - tz / 2], rgba=[0.6, 0.45, 0.3, 1.0])
    _world_geom(world, name="pedestal", type=mujoco.mjtGeom.mjGEOM_CYLINDER, size=[0.08, -floor / 2, 0],
                pos=[0.0, 0.0, floor / 2], rgba=[0.25, 0.25, 0.25, 1.0])
    _world_geom(world, name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[2.0, 2.0, 0.1],
                pos=[0.0, 0.0, floor], rgba=[0.8, 0.8, 0.8, 1.0])
    world.add_light(name="top", pos=[0.4, 0.0, top + 1.6], dir=[0.0, 0.0, -1.0], diffuse=[0.7, 0.7, 0.7])
    for obj in scene.objects:
        _add_object(world, obj)
    model = spec.compile()
    names = tuple(o.name for o in scene.objects)
    bodies = tuple(mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, OBJECT_PREFIX + n) for n in names)
    return SceneModel(model, names, bodies)


def object_heights(model: SceneModel, data: mujoco.MjData) -> np.ndarray:
    """Current centre heights (m) of the scene objects, in scene order."""
    return np.array([data.xpos[b][2] for b in model.object_bodies])
