"""The daemon's outgoing messages, built from its current state: the ``status`` reply and the ``state``
message of ``docs/protocol.md``, the ``/state`` record of the MCAP recording, and the progress line.

Pure reads of a :class:`~.daemon.Daemon`; the daemon decides when each is sent.
"""

from __future__ import annotations

import os
import sys
import time
from typing import TYPE_CHECKING, Any

import numpy as np

from ..arm.base import ArmState
from ..arm.safety import SafetyResult
from ..io import protocol
from ..planner.actions import Action
from ..planner.model import Command

if TYPE_CHECKING:
    from .daemon import Daemon


def status(d: Daemon) -> dict[str, Any]:
    """The ``status`` reply of ``docs/protocol.md``."""
    return {
        "version": protocol.PROTOCOL_VERSION,
        "method": d.method,
        "arm": d.arm.name if d.arm is not None else d.opts.arm,
        "arm_fault": d.arm_state.fault if d.arm_state is not None else None,
        "arm_status": d.arm.status() if d.arm is not None else {},
        "input": d.opts.input,
        "input_connected": d.input_connected,
        "planner": planner_dict(d),
        "stopped": bool(d.safety and d.safety.stopped),
        "assist": d.assist,
        "uptime_s": round(d.now(), 3),
        "scene": d.opts.scene.name,
        "task": d.sim.task if d.sim is not None else None,
        "pid": os.getpid(),
        "control": control_dict(d),
        "commands": commands_dict(d),
        "record": record_dict(d),
        "speech": d.speaker.status() if d.speaker is not None else None,
        "voice": d.voice.status() if d.voice is not None else None,
    }


def control_dict(d: Daemon) -> dict[str, Any]:
    """The control loop's own timing counters since READY (``docs/protocol.md``, ``status``)."""
    r = d.rates.get("control")
    st = r.stats if r is not None else None
    return {
        "ticks": st.ticks if st is not None else 0,
        "overruns": st.overruns if st is not None else 0,
        "skipped": st.skipped if st is not None else 0,
        "realtime_priority": 0 if d.realtime_refused is not None else d.cfg.runtime.realtime_priority,
        "switch_interval_s": sys.getswitchinterval(),
    }


def commands_dict(d: Daemon) -> dict[str, Any]:
    s = d.server
    return {
        "requests": s.requests if s is not None else 0,
        "refused": s.refused if s is not None else 0,
        "deferred": s.deferred if s is not None else 0,
        "per_tick": d.cfg.zmq.max_requests_per_tick,
    }


def record_dict(d: Daemon) -> dict[str, Any] | None:
    r = d.recorder
    if r is None:
        return None
    return {"path": str(r.path), "written": r.written, "flushed": r.flushed, "dropped": r.dropped,
            "error": r.error}


def planner_dict(d: Daemon) -> dict[str, Any]:
    w = d.worker
    return {
        "pid": w.pid if w is not None else None,
        "status": d.planner_status.value,
        "last_plan_ms": round(d.last_plan_ms, 3),
        "restarts": w.restarts if w is not None else 0,
        "plans": d.plans,
    }


def belief_list(d: Daemon) -> list[dict[str, Any]]:
    tp = d.belief.target_probabilities()
    return [{"goal": g, "p": float(p)} for g, p in tp.items()]  # unrounded: sums to 1 within 1e-12


def action_dict(action: Action) -> dict[str, Any]:
    d: dict[str, Any] = {"kind": action.kind.value}
    if action.target is not None:
        d["goal"] = action.target
    return d


def state_message(d: Daemon) -> dict[str, Any]:
    """The ``state`` message of ``docs/protocol.md``."""
    st = d.arm_state
    cmd, res = d.command, d.safety_result
    pose = st.pose.as_dict() if st is not None else None
    action = d.current_action(time.monotonic())
    return {
        "v": protocol.PROTOCOL_VERSION,
        "t": round(d.now(), 4),
        "mode": d.mode.value,
        "user_twist": protocol.finite_list(d.user_twist if d.input_fresh() else np.zeros(6)),
        "robot_twist": protocol.finite_list(cmd.robot_twist),
        "command_twist": protocol.finite_list(res.twist),
        "gripper_pose": pose,
        "gripper_closed": bool(st is not None and st.gripper_closed),  # as the arm reports it
        "belief": belief_list(d),
        "action": action_dict(action),
        "question": d.question.text if d.question is not None else None,
        "planner": planner_dict(d),
        "safety": res.status.value,
        "safety_codes": [c.value for c in res.codes],
        "method": d.method,
        "assist": d.assist,
        "stopped": bool(d.safety and d.safety.stopped),
        "arm": {"backend": d.arm.name if d.arm else d.opts.arm, "fault": st.fault if st else None},
        "input": {"backend": d.opts.input, "connected": d.input_connected, "fresh": d.input_fresh()},
        "task": d.sim.task if d.sim is not None else None,
    }


def record_state(d: Daemon, cmd: Command, res: SafetyResult, st: ArmState) -> dict[str, Any]:
    tp = d.belief.target_probabilities()
    return {
        "t": round(d.now(), 4),
        "mode": d.mode.value,
        "user_twist": d.user_twist.tolist(),
        "robot_twist": cmd.robot_twist.tolist(),
        "command_twist": res.twist.tolist(),
        "gripper_pose": st.pose.as_dict(),
        "belief": {g: float(p) for g, p in tp.items()},
        "action": cmd.action.label,
        "opposed": bool(cmd.opposed),
        "safety": res.status.value,
        "question": d.question.target if d.question is not None else None,
    }


def print_progress(d: Daemon) -> None:
    """The one-line progress report ``sa-daemon run`` prints every second (stderr, through the console
    thread)."""
    tp = d.belief.target_probabilities()
    top = max(tp, key=tp.__getitem__)
    p = d.arm_state.pose.position if d.arm_state else np.zeros(3)
    d.console.write(
        f"[{d.now():7.2f}] {d.current_action(time.monotonic()).label:<22} "
        f"belief {top} {tp[top]:.2f}  tcp ({p[0]:+.3f} {p[1]:+.3f} {p[2]:+.3f}) m  "
        f"{d.mode.value:<11} planner {d.planner_status.value} {d.last_plan_ms:.1f} ms  "
        f"safety {d.safety_result.status.value}"
    )
