"""The daemon's outgoing messages: the ``status`` reply and the ``state`` message of ``docs/protocol.md``,
the ``/state`` record of the MCAP recording, and the progress line.

Pure functions of a read-only :class:`~.view.View`; the daemon decides when each is sent.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..io import protocol
from ..model.actions import Action
from .view import View


def status(v: View) -> dict[str, Any]:
    """The ``status`` reply of ``docs/protocol.md``."""
    st = v.arm_state
    return {
        "version": protocol.PROTOCOL_VERSION,
        "method": v.method,
        "arm": v.arm_name,
        "arm_fault": st.fault if st is not None else None,
        "arm_status": v.arm_status(),
        "input": v.input_backend,
        "input_connected": v.input_connected,
        "planner": v.planner(),
        "stopped": v.stopped,
        "stop_tested": v.stop_tested,
        "profile": v.profile,
        "profiles": v.profiles(),
        "answers": ["yes", "no", "other"] if v.third_answer else ["yes", "no"],
        "answer_times": v.answer_times(),
        "assist": v.assist,
        "uptime_s": round(v.t, 3),
        "scene": v.scene,
        "task": v.task,
        "pid": v.pid,
        "control": v.control(),
        "commands": v.commands(),
        "record": v.record(),
        "foxglove": v.foxglove(),
        "speech": v.speech(),
        "voice": v.voice(),
    }


def scene(v: View) -> dict[str, Any]:
    """The ``scene`` reply of ``docs/protocol.md``: the running scene's objects and every target's grasp
    poses (base frame, m), the table height and the start pose, for a view of the table."""
    sc = v.scene_data
    return {
        "name": sc.name,
        "table_z": round(float(sc.table_z), 6),
        "start": sc.start.as_dict(),
        "objects": [{"name": o.name, "shape": o.shape, "size": protocol.finite_list(o.size),
                     "position": protocol.finite_list(o.position), "yaw": round(float(o.yaw), 6)}
                    for o in sc.objects],
        "goals": [{"target": g.target, "poses": [p.as_dict() for p in g.poses]} for g in sc.goals],
    }


def belief_list(v: View) -> list[dict[str, Any]]:
    tp = v.belief.target_probabilities()
    return [{"goal": g, "p": float(p)} for g, p in tp.items()]  # unrounded: sums to 1 within 1e-12


def action_dict(action: Action) -> dict[str, Any]:
    d: dict[str, Any] = {"kind": action.kind.value}
    if action.target is not None:
        d["goal"] = action.target
    return d


def state_message(v: View) -> dict[str, Any]:
    """The ``state`` message of ``docs/protocol.md``."""
    st = v.arm_state
    tick = v.tick
    fresh = v.input_fresh
    return {
        "v": protocol.PROTOCOL_VERSION,
        "t": round(v.t, 4),
        "mode": v.mode.value,
        "user_twist": protocol.finite_list(v.user_twist if fresh else np.zeros(6)),
        "robot_twist": protocol.finite_list(tick.command.robot_twist),
        "command_twist": protocol.finite_list(tick.safety.twist),
        "gripper_pose": st.pose.as_dict() if st is not None else None,
        "gripper_closed": bool(st is not None and st.gripper_closed),  # as the arm reports it
        "belief": belief_list(v),
        "action": action_dict(v.action),
        "question": v.question_text(),
        "planner": v.planner(),
        "safety": tick.safety.status.value,
        "safety_codes": [c.value for c in tick.safety.codes],
        "method": v.method,
        "assist": v.assist,
        "yielding": v.yielding,
        "stopped": v.stopped,
        "stop_tested": v.stop_tested,
        "arm": {"backend": v.arm_name, "fault": st.fault if st else None},
        "input": {"backend": v.input_backend, "connected": v.input_connected, "fresh": fresh},
        "task": v.task,
    }


def record_state(v: View) -> dict[str, Any]:
    """The ``/state`` record of the last control tick."""
    tp = v.belief.target_probabilities()
    tick, st, q = v.tick, v.arm_state, v.question
    assert st is not None
    return {
        "t": round(v.t, 4),
        "mode": v.mode.value,
        "user_twist": v.user_twist.tolist(),
        "robot_twist": tick.command.robot_twist.tolist(),
        "command_twist": tick.safety.twist.tolist(),
        "gripper_pose": st.pose.as_dict(),
        "belief": {g: float(p) for g, p in tp.items()},
        "action": tick.command.action.label,
        "opposed": bool(tick.command.opposed),
        "safety": tick.safety.status.value,
        "question": q.target if q is not None else None,
    }


def progress_line(v: View) -> str:
    """The one-line progress report ``sa-daemon run --progress`` prints every second."""
    tp = v.belief.target_probabilities()
    top = max(tp, key=tp.__getitem__)
    p = v.arm_state.pose.position if v.arm_state else np.zeros(3)
    pl = v.planner()
    return (
        f"[{v.t:7.2f}] {v.action.label:<22} "
        f"belief {top} {tp[top]:.2f}  tcp ({p[0]:+.3f} {p[1]:+.3f} {p[2]:+.3f}) m  "
        f"{v.mode.value:<11} planner {pl['status']} {pl['last_plan_ms']:.1f} ms  "
        f"safety {v.tick.safety.status.value}"
    )
