"""The composition root: a :class:`~.daemon.Daemon` from a :class:`~..config.Config` and plain options.

``sa-daemon run`` (``verbs.py`` turns its flags into a config and a :class:`Launch`), ``bench loop``,
``bench soak`` and the tests all build the daemon here, so there is one way to assemble it and none of
them needs argparse or edits a daemon after it was built.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from ..arm.backends import backend
from ..config import Config
from ..world.scene import load_scene
from .daemon import Daemon
from .options import RunOptions

DEFAULT_SCENE = "scene1"
DEFAULT_TASK = "cup:top"  # the paper's task 1


@dataclass(frozen=True)
class Launch:
    """What to run, besides the config: ``scene`` (a built-in name or a scene file), the simulated user's
    ``tasks`` (default: ``cup:top`` where the scene has it, else its first target), the ``input`` backend
    (``sim`` or ``evdev``), ``duration_s`` (``None``: until stopped, or until the tasks are done),
    the simulated user's ``seed``, progress lines, ``exit_when_done`` (default: when no duration), and
    the simulated ``user``'s profile."""

    scene: str = DEFAULT_SCENE
    tasks: Sequence[str] = ()
    input: str = "sim"
    duration_s: float | None = None
    seed: int = 0
    progress: bool = True
    exit_when_done: bool | None = None
    user: str = "calibrated"  # the simulated user's profile: a built-in name or a file (sim/users.py)
    profile: str | None = None  # the person's profile: a name in profiles.dir or a file (profile.py)


def build_daemon(cfg: Config, launch: Launch) -> Daemon:
    """The daemon ``cfg`` and ``launch`` describe; nothing is started. An unknown scene or task, or an
    exposed command endpoint without CURVE, is refused here, naming it."""
    scene = load_scene(launch.scene)
    tasks = list(launch.tasks) or ([DEFAULT_TASK] if DEFAULT_TASK in scene.targets else scene.targets[:1])
    for t in tasks:
        scene.goal(t)  # an unknown task is refused before anything starts (KeyError naming it)
    if backend(cfg.arm.backend).joints:  # the goals keep the poses the xArm-6 reaches (arm/reach.py)
        from ..arm.kinematics import ArmKinematics
        from ..arm.reach import reachable_scene

        scene = reachable_scene(scene, ArmKinematics(), cfg.safety.joint_margin_rad)
    if launch.input == "sim":  # the simulated user's profile: its [sim_user] over the config's
        from ..sim.users import load_user

        cfg = load_user(launch.user).apply(cfg)
    base = cfg  # profiles switched at run time apply over this
    profile = None
    if launch.profile:  # the person's settings over the configuration (refused, naming the key, if wrong)
        from ..profile import load_profile

        profile = load_profile(launch.profile, cfg.profiles.dir)
        cfg = profile.apply(cfg)
    exit_when_done = launch.duration_s is None if launch.exit_when_done is None else launch.exit_when_done
    opts = RunOptions(
        scene=scene, arm=cfg.arm.backend, input=launch.input, tasks=tasks, method=cfg.method,
        pub=cfg.zmq.pub, cmd=cfg.zmq.cmd, duration_s=launch.duration_s, record=cfg.record.path or None,
        seed=launch.seed, progress=launch.progress, exit_when_done=exit_when_done,
        profile=None if profile is None else {"name": profile.name, "path": profile.path, "keys": profile.keys()},
        base_config=base,
    )
    return Daemon(cfg, opts)
