"""The one registry of arm backends: name -> how to build it, whether it has joints, whether it is simulated.

Everything that names a backend reads it from here: config validation (``arm.backend``), the CLI's
``--arm`` choices (``run``: all; ``eval``: the simulated ones), the goal filter that ``run`` applies
before it builds a jointed arm, and :func:`make_arm`. Backends are imported lazily, so the kinematic arm
needs neither MuJoCo nor the xArm SDK, and this module imports nothing of the package at load time
(``config.py`` reads it).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from ..config import Config
    from ..planner.scene import Scene
    from .base import Arm


def _kinematic(scene: Scene, cfg: Config) -> Arm:
    from .kinematic import KinematicArm

    return KinematicArm(scene.start, cfg.limits)


def _mujoco(scene: Scene, cfg: Config) -> Arm:
    from .mujoco_arm import MujocoArm

    return MujocoArm(scene, cfg)


def _xarm(scene: Scene, cfg: Config) -> Arm:
    from .xarm_arm import XArm

    return XArm(cfg)


@dataclass(frozen=True)
class Backend:
    """One arm backend: ``joints`` - it has the xArm-6's joints (``Arm.kinematics``: bounds,
    singularities, reachable goals); ``simulated`` - it runs in simulated time (``eval`` can use it)."""

    name: str
    build: Callable[[Scene, Config], Arm]
    joints: bool
    simulated: bool
    summary: str


REGISTRY: dict[str, Backend] = {b.name: b for b in (
    Backend("kinematic", _kinematic, joints=False, simulated=True,
            summary="gripper-only, exact twist integration (fast; the evaluation's default)"),
    Backend("mujoco", _mujoco, joints=True, simulated=True,
            summary="the xArm-6 in MuJoCo physics with the scene's objects (the daemon's default)"),
    Backend("xarm", _xarm, joints=True, simulated=False, summary="the real xArm-6 through the xArm SDK"),
)}
BACKENDS = tuple(REGISTRY)
JOINTED_BACKENDS = tuple(n for n, b in REGISTRY.items() if b.joints)
"""Backends with joints (``Arm.kinematics``): the xArm-6 model, its bounds and singularities."""
SIMULATED_BACKENDS = tuple(n for n, b in REGISTRY.items() if b.simulated)


def backend(name: str) -> Backend:
    """The backend called ``name``; ``ValueError`` listing the backends if there is none."""
    try:
        return REGISTRY[name]
    except KeyError:
        raise ValueError(f"unknown arm backend {name!r} (one of {', '.join(BACKENDS)})") from None


def make_arm(name: str, scene: Scene, cfg: Config) -> Arm:
    """A fresh arm of backend ``name`` holding the TCP at ``scene.start`` (simulated arms); raises
    ``ValueError`` for an unknown backend."""
    return backend(name).build(scene, cfg)
