"""What the person and the protocol can ask of the daemon: joystick buttons and the commands of
``docs/protocol.md`` (``status``, ``answer``, ``stop``, ``resume``, ``set_method``).

Functions of a running :class:`~.daemon.Daemon`, called on its event loop. A command that cannot be
applied raises :class:`~..io.protocol.RequestError`, which the server returns as a refusal; nothing has
changed then.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from ..io.protocol import Request, RequestError
from ..model.methods import method_spec
from ..planner.worker import WorkerStatus
from . import messages

if TYPE_CHECKING:
    from .daemon import Daemon


def handle(d: Daemon, req: Request) -> dict[str, Any]:
    """Answer one validated command (``docs/protocol.md``)."""
    if req.cmd == "status":
        return messages.status(d.view)
    if req.cmd == "answer":
        d.asker.answer(req.args["value"], source="command")
        return {}
    if req.cmd == "stop":
        stop(d, "command")
        return {}
    if req.cmd == "resume":
        resume(d)
        return {}
    if req.cmd == "set_method":
        set_method(d, req.args["method"])
        return {"method": d.ctl.method}
    if req.cmd == "scene":
        return messages.scene(d.view)
    if req.cmd == "set_profile":
        return set_profile(d, req.args["profile"])
    if req.cmd == "set_scene":
        return set_scene(d, req.args)
    raise RequestError(f"unknown command {req.cmd!r}")


def on_button(d: Daemon, button: Any) -> None:
    """A joystick button press (see :class:`~..io.joystick.Button`)."""
    name = getattr(button, "value", str(button))
    ctl = d.ctl
    if name == "mode":
        d.event("mode", mode=ctl.toggle_mode().value)
    elif name == "gripper":
        d.set_gripper(not ctl.gripper_closed)
    elif name in ("yes", "no", "other"):
        try:
            d.asker.answer(name, source="button")
        except RequestError:
            pass  # no question pending: the press means nothing
    elif name == "assist":
        ctl.set_assist(not ctl.assist)
        d.event("assist", on=ctl.assist)
    elif name == "stop":
        stop(d, "button")


def stop(d: Daemon, source: str) -> None:
    """Latch the stop and command zero now, without waiting for the next control tick."""
    d.ctl.stop()
    if d.arm is not None:
        d.arm.command_twist(np.zeros(6))
    d.event("stop", source=source)


def resume(d: Daemon) -> None:
    """Clear the arm's fault and release the stop; the arm restarts from rest."""
    if d.arm is not None:
        d.arm.reset_fault()
    passed = d.ctl.resume()
    d.fault_reported = None
    d.event("resume")
    if passed:
        d.event("stop_test", passed=True)


def set_profile(d: Daemon, name: str) -> dict[str, Any]:
    """Switch the person's profile (between tasks): refused while the arm moves, or when the profile is
    missing or invalid (the reason names the key); nothing changes then."""
    from ..config import ConfigError
    from ..profile import load_profile

    if np.any(d.ctl.last.safety.twist != 0.0):
        raise RequestError("the arm is moving: stop it (or let the task end) before switching profile")
    base = d.opts.base_config if d.opts.base_config is not None else d.cfg
    try:
        profile = load_profile(name, d.cfg.profiles.dir)
        cfg = profile.apply(base)
        if d.joystick is not None:
            d.joystick.reconfigure(cfg.joystick)
    except (ConfigError, ValueError) as e:
        raise RequestError(f"set_profile: {e}") from None
    d.opts.profile = {"name": profile.name, "path": profile.path, "keys": profile.keys()}
    d.reconfigure(cfg)
    d.event("profile", **d.opts.profile)
    return {"profile": profile.name, "keys": profile.keys()}


def set_scene(d: Daemon, args: dict[str, Any]) -> dict[str, Any]:
    """A scene from perception (``world/live.py``): applied now with the arm stopped, or at the simulated
    user's next task; refused (nothing changes) when invalid, when no goal is reachable, while the arm
    is not stopped (``now``), or when the simulated user's tasks are not in it."""
    from ..arm.backends import backend
    from ..world.live import scene_from_request
    from ..world.scene import SceneError

    when = args.get("when", "now")
    try:
        scene = scene_from_request(args, d.opts.scene)
        dropped: list[dict[str, str]] = []
        if backend(d.opts.arm).joints:
            from ..arm.kinematics import ArmKinematics
            from ..arm.reach import reachable_goals

            scene, dropped = reachable_goals(scene, ArmKinematics(), d.cfg.safety.joint_margin_rad)
    except (SceneError, ValueError) as e:
        raise RequestError(str(e)) from None
    if d.sim is not None:
        missing = [t for t in d.sim.sim.tasks if t not in scene.targets]
        if missing:
            raise RequestError(f"set_scene: the simulated user's task {missing[0]} is not in the scene")
        if when == "now":
            raise RequestError('set_scene: with the simulated user, a scene changes between tasks (when = "next_task")')
        d.pending_scene = (scene, dropped)
    elif when == "next_task":
        raise RequestError('set_scene: "next_task" is for the simulated user; stop the arm and send when = "now"')
    elif not d.ctl.stopped:
        raise RequestError('set_scene: stop the arm first (the stop command), then send the scene with when = "now"')
    else:
        d.apply_scene(scene, dropped)
    return {"scene": scene.name, "targets": list(scene.targets), "dropped": dropped, "when": when}


def set_method(d: Daemon, method: str) -> None:
    """Switch the assistance method (``ValueError`` on an unknown name, refused by the server)."""
    spec = method_spec(method)
    had_question = d.ctl.question is not None
    d.ctl.set_method(method)
    if had_question:
        d.asker.cleared()
    if not spec.planned:
        d.planner_status = WorkerStatus.IDLE
    d.event("method", method=method)
