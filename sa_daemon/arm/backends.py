"""The one registry of arm backends: name -> the arm class that builds it, whether it has joints, whether
it is simulated. Pure data, importing nothing: ``config.py`` validates ``arm.backend`` against it, the
CLI takes its ``--arm`` choices from it (``run``: all; ``eval``: the simulated ones), the composition
root filters goals for the jointed ones, and ``factory.make_arm`` builds from it. Each backend names its
:class:`~.base.Arm` class by import path, imported only when that arm is built (so the kinematic arm
needs neither MuJoCo nor the xArm SDK); every class builds itself with ``from_config(scene, cfg)``.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Backend:
    """One arm backend: ``arm_class`` - ``"module:Class"`` of its :class:`~.base.Arm`; ``joints`` - it has
    the xArm-6's joints (``Arm.kinematics``: bounds, singularities, reachable goals); ``simulated`` - it
    runs in simulated time (``eval`` can use it)."""

    name: str
    arm_class: str
    joints: bool
    simulated: bool
    summary: str


REGISTRY: dict[str, Backend] = {b.name: b for b in (
    Backend("kinematic", "sa_daemon.arm.kinematic:KinematicArm", joints=False, simulated=True,
            summary="gripper-only, exact twist integration (fast; the evaluation's default)"),
    Backend("mujoco", "sa_daemon.arm.mujoco_arm:MujocoArm", joints=True, simulated=True,
            summary="the xArm-6 in MuJoCo physics with the scene's objects (the daemon's default)"),
    Backend("xarm", "sa_daemon.arm.xarm_arm:XArm", joints=True, simulated=False,
            summary="the real xArm-6 through the xArm SDK"),
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
