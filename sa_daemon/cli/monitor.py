"""``sa-daemon monitor``: a live terminal view of a running daemon, built only from its PUB stream."""

from __future__ import annotations

import sys
import time
from collections import deque
from typing import Any

from ..io.client import subscribe
from ..io.security import ClientCurve

BAR = 30  # characters of a full belief bar


def _vec(v: list[float]) -> str:
    return " ".join(f"{x:+.3f}" for x in v)


def render(state: dict[str, Any], events: deque[str]) -> str:
    """One screen: belief bars per goal, action, question, mode, twists, planner and safety status."""
    lines = [
        (
            f"sa-daemon  t={state['t']:.2f} s  method={state['method']}  mode={state['mode']}  "
            f"assist={'on' if state.get('assist', True) else 'off'}  stopped={state.get('stopped', False)}"
        ),
        "",
        "belief:",
    ]
    if state.get("stop_tested") is False:
        lines.insert(1, "STOP NOT TESTED: press stop, then resume (sa-daemon resume), before the arm moves")
    for b in sorted(state["belief"], key=lambda b: -b["p"]):
        n = round(b["p"] * BAR)
        lines.append(f"  {b['goal']:<32} {'#' * n}{'.' * (BAR - n)} {b['p']:.3f}")
    a = state["action"]
    lines += [
        "",
        f"action:   {a['kind']}{' ' + a['goal'] if 'goal' in a else ''}"
        + (f"  (held back: {state['yielding']})" if state.get("yielding") else ""),
        f"question: {state['question'] or '-'}",
        f"user:     {_vec(state['user_twist'])}",
        f"robot:    {_vec(state['robot_twist'])}",
        f"command:  {_vec(state['command_twist'])}   (m/s x3, rad/s x3)",
    ]
    pose = state.get("gripper_pose") or {}
    if pose:
        lines.append(f"gripper:  {_vec(pose['position'])} m  quat_wxyz {_vec(pose['quat_wxyz'])}")
    p = state["planner"]
    lines += [
        f"planner:  pid {p['pid']}  {p['status']}  last plan {p['last_plan_ms']:.1f} ms",
        f"safety:   {state['safety']}  {' '.join(state.get('safety_codes', []))}",
        "",
        "events:",
        *[f"  {e}" for e in events],
    ]
    return "\n".join(lines)


def monitor(endpoint: str, duration_s: float | None = None, once: bool = False,
            curve: ClientCurve | None = None) -> int:
    """Show the stream until interrupted (or ``duration_s``); ``once`` prints a single state.

    ``curve``: client keys for a daemon whose PUB stream is CURVE-protected (``zmq.curve_pub``).
    """
    events: deque[str] = deque(maxlen=8)
    t_end = time.monotonic() + duration_s if duration_s else None
    last = 0.0
    tty = sys.stdout.isatty()
    try:
        for topic, msg in subscribe(endpoint, timeout_s=5.0, curve=curve):
            if topic == "event":
                extra = " ".join(f"{k}={v}" for k, v in msg.items() if k not in ("t", "type"))
                events.append(f"[{msg['t']:7.2f}] {msg['type']} {extra}")
                continue
            now = time.monotonic()
            if once or now - last >= 0.2:
                last = now
                screen = render(msg, events)
                print(("\x1b[H\x1b[2J" if tty else "") + screen, flush=True)
                if once:
                    return 0
            if t_end is not None and now > t_end:
                return 0
    except TimeoutError as e:
        print(f"sa-daemon monitor: {e} (is the daemon running?)", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 0
    return 0
