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
        d.asker.answer(req.args["value"] == "yes", source="command")
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
    raise RequestError(f"unknown command {req.cmd!r}")


def on_button(d: Daemon, button: Any) -> None:
    """A joystick button press (see :class:`~..io.joystick.Button`)."""
    name = getattr(button, "value", str(button))
    ctl = d.ctl
    if name == "mode":
        d.event("mode", mode=ctl.toggle_mode().value)
    elif name == "gripper":
        d.set_gripper(not ctl.gripper_closed)
    elif name in ("yes", "no"):
        try:
            d.asker.answer(name == "yes", source="button")
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
