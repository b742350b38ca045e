"""Fault injection against a real daemon process (issue 6): every failure we can foresee is injected
into a running ``sa-daemon run`` and what the person would care about is checked - the arm stops or
keeps behaving, nothing hangs, nothing is lost, and the daemon recovers by itself.

Most daemons here run through ``tests/faultd.py``: the real CLI with fakes only at the hardware
boundaries (a joystick without /dev/input, the xArm SDK without an arm, the speech engine), driven
over stdin. Timing figures come from the daemon's own clock: the MCAP recording (``/state`` at the
control rate, ``/event``) and the state stream; each test prints its figures (``pytest -s``) for
``docs/safety.md``. Every wait is event-driven with a generous timeout.
"""

from __future__ import annotations

import contextlib
import itertools
import json
import math
import os
import signal
import socket
import subprocess
import sys
import threading
import time
import uuid
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import zmq
from helpers import (
    CLI,
    COMMIT_MODEL_TOML,
    FAULTD,
    START_TIMEOUT_S,
    DaemonProc,
    fill_disk,
    free_port,
    process_gone,
    small_disk,
)
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from sa_daemon.config import Config
from sa_daemon.io import protocol
from sa_daemon.io.recorder import read_recording

CFG = Config()
CONTROL_S = 1.0 / CFG.runtime.control_hz
PLAN_S = CFG.planner.period_s
MAX_STATE_GAP_S = 0.2
WORKER_START_S = 3.0  # s: a replacement planner worker plans within this of its start (twice the slowest seen)
RECEIVER_GAP_S = 1.0  # s: arrival gaps at the test's subscriber also hold this busy process's scheduling
# (0.63 s seen once on 2 cores while a replacement planner worker started and compiled); "the stream never
# pauses" is decided on the daemon's own clock (MAX_STATE_GAP_S), this only catches a delivery that stalls
ZERO6 = [0.0] * 6


def figure(name: str, text: str) -> None:
    """A measured figure for docs/safety.md (shown with ``pytest -s``)."""
    print(f"\nFIGURE {name}: {text}", flush=True)


def faultd(workdir: Path, *extra: str, config: str = "", arm: str = "kinematic", inp: str = "evdev",
           scene: str = "scene1", speech_init: str = "ok", env: dict[str, str] | None = None) -> DaemonProc:
    """A daemon run through ``tests/faultd.py`` (fake joystick plugged, fake xArm reachable)."""
    run: tuple[str, ...] = ("--arm", arm, "--input", inp, "--scene", scene)
    if inp == "sim":
        run += ("--task", "cup:top")
    return DaemonProc(workdir, *extra, config=config, entry=[sys.executable, str(FAULTD), "--speech-init", speech_init, "--"],
                      run=run, stdin=True, env=env)


def recording(path: Path) -> tuple[list[dict], list[dict], list[int]]:
    """``(states, events, state log times ns)`` of an MCAP recording."""
    states, events, log_ns = [], [], []
    for topic, t_ns, m in read_recording(path):
        if topic == "/state":
            states.append(m)
            log_ns.append(t_ns)
        elif topic == "/event":
            events.append(m)
    return states, events, log_ns


def messages_in(path: Path) -> int:
    """Every complete message record of an MCAP file, whatever its encoding (the JSON ``/state`` and
    ``/event``, and the live view's Foxglove messages); a file cut short counts up to its last whole record."""
    from mcap.records import Message
    from mcap.stream_reader import StreamReader

    n = 0
    with open(path, "rb") as f:
        try:
            for rec in StreamReader(f, skip_magic=False).records:
                n += isinstance(rec, Message)
        except Exception:  # noqa: BLE001, S110 - a torn last record ends the file
            pass
    return n


def max_gap(times: list[float]) -> float:
    return max((b - a for a, b in itertools.pairwise(times)), default=0.0)


def state_gaps(proc: DaemonProc, start: int = 0) -> tuple[float, float]:
    """Largest gap between state messages from ``start`` on: by the daemon's ``t`` and by arrival (s)."""
    got = proc.collector.received(start, topic="state")
    return max_gap([m["t"] for _, m in got]), max_gap([at for at, _ in got])


def clean_log(d: DaemonProc) -> None:
    """The daemon's stderr has no traceback and no error line."""
    text = (d.dir / "stderr.txt").read_text(errors="replace")
    assert "Traceback" not in text and " ERROR " not in text, text[-3000:]


def nonzero(v: list[float]) -> bool:
    return any(abs(x) > 0 for x in v)


# -- joystick lost mid-motion ------------------------------------------------------------------------------


def test_joystick_lost_mid_motion_zeroes_the_command_at_the_next_tick_and_comes_back(tmp_path):
    """ho assistance and the stick pushed forward: the arm moves. The stick is unplugged: the command is
    zero at the very next control tick (the assistance alone must not keep the arm moving) and the stop
    latches (the person's stop button went with the stick); the daemon keeps running and publishing,
    looks for the device, takes input again when it returns, and moves again after a resume."""
    d = faultd(tmp_path / "d", "--method", "ho", "--duration", "600", "--no-speech", "--record", "joy.mcap",
               config="[joystick]\npoll_s = 0.2\n")
    try:
        d.wait_ready()
        c = d.collector
        c.state(lambda s: s["input"]["connected"], timeout_s=30, what="state with the stick connected")
        d.fault("axes 0.6 0 0")
        c.state(lambda s: abs(s["command_twist"][0]) >= 0.05 and nonzero(s["robot_twist"]), timeout_s=30,
                what="the arm moving forward under ho assistance")
        i_unplug = len(c)
        t_unplug = d.fault("unplug")["t"]
        i_lost, lost = c.event("input_lost", timeout_s=10, start=i_unplug)
        _, s = c.state(lambda s: s["t"] > lost["t"] + 0.3, timeout_s=10, start=i_lost)
        assert s["command_twist"] == ZERO6 and s["user_twist"] == ZERO6
        assert s["input"] == {"backend": "evdev", "connected": False, "fresh": False}
        assert s["safety"] == "stopped" and s["stopped"] is True
        c.event("stop", timeout_s=10, start=i_unplug, source="joystick_lost")
        # Still running: it answers and publishes while the device is away.
        st_ = d.request({"cmd": "status"})
        assert st_["ok"] and st_["input_connected"] is False and st_["pid"] == d.proc.pid

        i_replug = len(c)
        t_replug = d.fault("replug")["t"]
        _, back = c.event("input_back", timeout_s=10, start=i_replug)
        assert "/dev/input/event8" in back["detail"]
        d.fault("axes 0.6 0 0")
        _, s = c.state(lambda s: s["t"] > back["t"] + 0.2, timeout_s=10, start=i_replug)
        assert s["command_twist"] == ZERO6 and s["stopped"], "moved again without a resume"
        assert d.request({"cmd": "resume"})["ok"]
        _, moving = c.state(lambda s: s["input"]["connected"] and s["command_twist"][0] > 0.0, timeout_s=10,
                            start=i_replug, what="motion after the stick came back")
        d.fault("button mode")  # its buttons work again too
        c.event("mode", timeout_s=10, start=i_replug, mode="rotation")
        gap_t, gap_rx = state_gaps(d, i_unplug)
        assert d.stop(signal.SIGTERM) == 0
    finally:
        d.close()
    clean_log(d)

    states, events, _ = recording(tmp_path / "d" / "joy.mcap")
    lost_ev = next(e for e in events if e["type"] == "input_lost" and e["t"] >= t_unplug - 1e-3)
    after = [s for s in states if s["t"] > t_unplug]
    before = [s for s in states if s["t"] <= t_unplug]
    assert nonzero(before[-1]["command_twist"]), "the arm was not moving when the stick was unplugged"
    # The first control tick after the daemon saw the loss commands zero, and every one after it until the
    # stick is back; at most the tick in flight when the unplug happened still carries the old command.
    first_after_lost = next(s for s in states if s["t"] > lost_ev["t"])
    assert first_after_lost["command_twist"] == ZERO6, first_after_lost
    zero = next(s for s in after if s["command_twist"] == ZERO6)
    assert after.index(zero) <= 1, f"{after.index(zero)} control ticks still moved after the unplug"
    held = [s for s in after if zero["t"] <= s["t"] <= t_replug]
    assert held and all(s["command_twist"] == ZERO6 and s["user_twist"] == ZERO6 for s in held)
    assert all(math.isfinite(x) for s in states for x in s["command_twist"])
    latency = zero["t"] - t_unplug
    assert latency <= 2 * CONTROL_S, f"command zero {latency * 1e3:.1f} ms after the unplug"
    assert gap_t <= MAX_STATE_GAP_S and gap_rx <= RECEIVER_GAP_S, (gap_t, gap_rx)
    back_s = back["t"] - t_replug
    assert back_s <= 0.2 + 0.5  # the next poll (joystick.poll_s = 0.2) finds it
    figure("joystick_lost", f"command zero {latency * 1e3:.1f} ms after the unplug ({after.index(zero)} ticks "
           f"in flight; period {CONTROL_S * 1e3:.0f} ms), daemon saw it {(lost_ev['t'] - t_unplug) * 1e3:.1f} ms "
           f"after; input back {back_s:.2f} s after the replug (poll 0.2 s); motion again at t={moving['t']:.2f}; "
           f"largest state gap {max(gap_t, gap_rx) * 1e3:.0f} ms")


# -- the planner worker: killed, hung ---------------------------------------------------------------------


@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGSTOP], ids=["killed", "hung"])
def test_planner_worker_killed_or_hung_falls_back_and_is_replaced(tmp_path, sig):
    """policy+noqns (plans, never asks) with the simulated user. While a planned move (or HO) is applied the
    worker is killed (SIGKILL) or hangs (SIGSTOP): the move is dropped for no assistance within one
    planning period of the plan that did not come, a new worker is started (a dead one at the next
    planner tick, a hung one after planner.budget_s + runtime.worker_hang_s) and plans again, and the
    state stream never pauses for more than 200 ms."""
    # State messages at 100 Hz: the last plan's arrival is known to 10 ms (the plans counter).
    d = faultd(tmp_path / "d", "--method", "policy+noqns", "--duration", "600", "--no-speech",
               "--record", "plan.mcap", inp="sim", config="[runtime]\npublish_hz = 100\n")
    old = None
    try:
        d.wait_ready()
        c = d.collector
        i0, s0 = c.state(lambda s: s["planner"]["status"] == "ok" and s["action"]["kind"] == "move",
                         timeout_s=START_TIMEOUT_S, start=len(c), what="a planned move being applied")
        old, plans0 = s0["planner"]["pid"], s0["planner"]["plans"]
        # Plans arrive every period: wait for one more so that the last plan before the fault is seen here.
        c.state(lambda s: s["planner"]["plans"] > plans0 and s["action"]["kind"] == "move", timeout_s=30,
                start=i0, what="the next planned move")
        i_fault = len(c)
        fault_ns, fault_mono = time.time_ns(), time.monotonic()
        os.kill(old, sig)
        ir, restart = c.event("planner_restart", timeout_s=30, start=i_fault, old_pid=old)
        new = restart["pid"]
        assert new != old
        assert restart["reason"] == ("worker died" if sig == signal.SIGKILL else restart["reason"])
        if sig == signal.SIGSTOP:
            assert restart["reason"].startswith("no plan for")
        i_ok, ok = c.state(lambda s: s["planner"]["pid"] == new and s["planner"]["status"] == "ok"
                           and s["planner"]["plans"] > 0, timeout_s=START_TIMEOUT_S, start=ir,
                           what="the new worker planning")
        new_ok_s = c.received(i_ok, i_ok + 1)[0][0] - fault_mono
        c.state(lambda s: s["t"] > ok["t"] + 0.5, timeout_s=10, start=i_ok)
        gap_t, gap_rx = state_gaps(d, i0)
        stream = c.slice(i0, topic="state")
        st_ = d.request({"cmd": "status"})
        assert st_["planner"]["pid"] == new and st_["planner"]["restarts"] == 1
        assert d.stop(signal.SIGTERM) == 0
    finally:
        d.close()
        if old is not None and not process_gone(old):
            os.kill(old, signal.SIGCONT)
            os.kill(old, signal.SIGKILL)
    clean_log(d)
    assert process_gone(old), "the old worker was left behind"

    states, events, log_ns = recording(tmp_path / "d" / "plan.mcap")
    # The daemon's clock at the fault, from the wall clock each record carries (one clock on one machine).
    k = next(i for i, ns in enumerate(log_ns) if ns >= fault_ns)
    t_fault = states[k]["t"] - (log_ns[k] - fault_ns) / 1e9
    # The last plan before the fault arrived after the last state stream message that did not show it yet.
    before = [s for s in stream if s["t"] <= t_fault]
    plans_last = before[-1]["planner"]["plans"]
    t_plan_lb = max(s["t"] for s in before if s["planner"]["plans"] < plans_last)
    t_plan_ub = min(s["t"] for s in before if s["planner"]["plans"] == plans_last)  # it arrived in between
    # a planned assistance at the fault: the move waited for, or HO if a plan switched in the last instants
    assert states[k - 1]["action"].startswith(("move", "ho")), "no planned assistance applied at the fault"
    fallback = next(s for s in states[k:] if s["action"] == "none")
    # Nothing but no-assist between the fallback and the first plan of the new worker.
    t_new_plan = max(s["t"] for s in stream if s["t"] < ok["t"])  # it came after this state message
    between = [s["action"] for s in states if fallback["t"] <= s["t"] <= t_new_plan]
    assert between and set(between) == {"none"}, set(between)
    due = t_plan_lb + PLAN_S  # when the plan that never came was due (at the earliest)
    late_s = fallback["t"] - due
    uncertain_s = t_plan_ub - t_plan_lb  # of the last plan's arrival, from the state stream
    fallback_s = fallback["t"] - t_fault
    restart_s = restart["t"] - t_fault
    if sig == signal.SIGKILL:
        assert fallback_s <= PLAN_S + 2 * CONTROL_S, f"no-assist {fallback_s * 1e3:.0f} ms after the kill"
        assert restart_s <= PLAN_S + 2 * CONTROL_S
    else:
        # The plan's action lives one period past the plan that did not come, plus the control tick.
        assert late_s <= PLAN_S + CONTROL_S + uncertain_s + 1e-3, (late_s, uncertain_s)
        # Declared hung at the first planner tick after budget_s + worker_hang_s without a reply, and the
        # request it hangs on was sent at most one period after the fault.
        silent_s = float(restart["reason"].split()[3])
        limit = CFG.planner.budget_s + CFG.runtime.worker_hang_s
        assert limit - 0.005 <= silent_s <= limit + PLAN_S + 2 * CONTROL_S, restart["reason"]  # (rounded to 0.01)
        assert restart_s <= silent_s + PLAN_S + 2 * CONTROL_S
        assert any(e["type"] == "planner_late" for e in events if t_fault <= e["t"] <= restart["t"])
    # A new worker's first plan waits for its interpreter, imports and numba's cache (0.3-0.5 s on session
    # 19's machine, 1.1-1.5 s on session 20's slower one, under the full suite): a machine's figure, which
    # docs/safety.md reports; the bound only says the replacement comes up and plans in seconds.
    assert new_ok_s - restart_s <= WORKER_START_S, f"new worker planning {new_ok_s - restart_s:.2f} s after the restart"
    assert gap_t <= MAX_STATE_GAP_S and gap_rx <= RECEIVER_GAP_S, (gap_t, gap_rx)
    figure(f"planner_{'sigkill' if sig == signal.SIGKILL else 'hang'}",
           f"no-assist {fallback_s * 1e3:.0f} ms after the fault, {late_s * 1e3:.0f} ms (-0..{uncertain_s * 1e3:.0f} ms) "
           f"after the missing plan was due (period {PLAN_S * 1e3:.0f} ms); planner_restart {restart_s:.2f} s after the fault; new worker "
           f"planning {new_ok_s:.2f} s after the fault ({new_ok_s - restart_s:.2f} s after its start); "
           f"largest state gap {max(gap_t, gap_rx) * 1e3:.0f} ms")


# -- the xArm driver: controller error, lost connection, no reply, NaN pose -------------------------------

XARM_CONFIG = """\
[arm.xarm]
sdk = "fake"
reconnect_min_s = 0.1
reconnect_max_s = 0.8

[safety]
stop_self_test = "off"  # these tests are about the driver's faults; tests/test_stop.py tests the self-test

[joystick]
poll_s = 0.2
"""
VC = "vc_set_cartesian_velocity"


def xarm_daemon(workdir: Path, *extra: str, config: str = XARM_CONFIG) -> DaemonProc:
    """manual method (the command is the stick's twist), the fake xArm, the fake stick."""
    return faultd(workdir, "--method", "manual", "--duration", "600", "--no-speech", *extra, config=config,
                  arm="xarm")


def moving(d: DaemonProc, x: float = 0.6, start: int | None = None) -> dict:
    """Push the stick forward and wait until the arm is commanded (and accepts) a forward twist."""
    c = d.collector
    i = len(c) if start is None else start
    c.state(lambda s: s["input"]["connected"], timeout_s=30, start=0, what="the stick connected")
    t = d.fault(f"axes {x} 0 0")["t"]
    _, s = c.state(lambda s: s["command_twist"][0] >= 0.05 and s["arm"]["fault"] is None, timeout_s=30, start=i,
                   what="the xArm commanded forward")
    calls = d.fault(f"calls {VC} {t}")["calls"]
    assert accepted_moving(calls), "the fake controller accepted no forward command"
    return s


def accepted_moving(calls: list[dict]) -> list[dict]:
    """Velocity commands the controller accepted (code 0) with a non-zero speed."""
    return [c for c in calls if nonzero(c["args"][0]) and c["result"] == 0]


def assert_stopped_by_duration(r: dict) -> tuple[float, float]:
    """Checks on faultd's report of a stalled event loop (``loop_hang``/``loop_stuck``): the fake
    controller zeroed the speed one command duration after the last moving command, and no later than a
    control period plus that duration after the stall. Returns (s after the last command, s after the
    stall)."""
    duration = CFG.arm.xarm.command_periods / CFG.runtime.control_hz
    last = r["last_moving_command"]
    assert last is not None and last["speeds"][0] > 0 and last["duration"] == pytest.approx(duration)
    # The driver's SDK thread may still send the one command it had in hand when the loop stopped.
    assert r["moving_commands_during"] <= 1 and last["t"] <= r["blocked_at"] + 5e-3, r
    assert r["zero_at"] is not None, "the arm kept moving while no command came"
    stop_after_last = r["zero_at"] - last["t"]
    assert duration - 1e-3 <= stop_after_last <= duration + 2e-3, stop_after_last
    stop_after_block = r["zero_at"] - r["blocked_at"]
    assert stop_after_block <= duration + CONTROL_S + 2e-3, stop_after_block
    return stop_after_last, stop_after_block


def resume_and_move(d: DaemonProc, since: float) -> tuple[float, float]:
    """Nothing moved since ``since``; ``resume`` re-enables the arm and the held stick moves it again.
    Returns (daemon t of the resume request, latency to the first accepted moving command, s)."""
    assert not accepted_moving(d.fault(f"calls {VC} {since}")["calls"]), "the arm moved before resume"
    c = d.collector
    i = len(c)
    t_resume = d.fault("now")["t"]
    assert d.request({"cmd": "resume"})["ok"]
    c.event("resume", timeout_s=10, start=i)
    c.state(lambda s: s["arm"]["fault"] is None and s["command_twist"][0] > 0.0, timeout_s=30, start=i,
            what="motion after resume")
    moves = accepted_moving(d.fault(f"calls {VC} {since}")["calls"])
    assert moves and moves[0]["t"] >= t_resume
    names = [c["args"] for c in d.fault(f"calls set_mode {t_resume}")["calls"]]
    assert [5] in names, "recovery did not set Cartesian velocity mode"
    return t_resume, moves[0]["t"] - t_resume


def test_xarm_controller_error_stops_reports_and_waits_for_resume(tmp_path):
    d = xarm_daemon(tmp_path / "d", "--record", "err.mcap")
    try:
        d.wait_ready()
        c = d.collector
        moving(d)
        # A warning is reported but does not stop the arm.
        t_warn = d.fault("arm_warn 24")["t"]
        c.state(lambda s: s["t"] > t_warn + 0.3, timeout_s=10)
        st_ = d.request({"cmd": "status"})
        assert st_["arm_status"]["warn_code"] == 24 and st_["arm_fault"] is None
        assert len(accepted_moving(d.fault(f"calls {VC} {t_warn}")["calls"])) >= 10
        i = len(c)
        t_err = d.fault("arm_error 22")["t"]
        _, ev = c.event("fault", timeout_s=10, start=i, source="arm")
        assert ev["detail"] == "xArm error 22: self collision"
        _, s = c.state(lambda s: s["t"] > ev["t"] + 0.5, timeout_s=10, start=i)
        assert s["arm"]["fault"] == "xArm error 22: self collision"
        assert s["safety"] == "arm_fault" and s["command_twist"] == ZERO6
        assert s["input"]["fresh"] and s["user_twist"][0] > 0, "the stick is still pushed"
        st_ = d.request({"cmd": "status"})
        assert st_["arm_fault"] == "xArm error 22: self collision" and st_["arm_status"]["error_code"] == 22
        assert d.fault("speed")["speed"] == ZERO6
        zeros = [x for x in d.fault(f"calls {VC} {t_err}")["calls"] if not nonzero(x["args"][0])]
        assert zeros, "no zero velocity command after the error"
        t_resume, move_s = resume_and_move(d, t_err)
        assert d.stop() == 0
    finally:
        d.close()
    clean_log(d)
    states, _, _ = recording(tmp_path / "d" / "err.mcap")
    zero = next(s for s in states if s["t"] > t_err and s["command_twist"] == ZERO6)
    assert all(s["command_twist"] == ZERO6 for s in states if zero["t"] <= s["t"] <= t_resume)
    figure("xarm_error", f"fault event {(ev['t'] - t_err) * 1e3:.1f} ms, command zero {(zero['t'] - t_err) * 1e3:.1f} ms, "
           f"zero velocity sent {(zeros[0]['t'] - t_err) * 1e3:.1f} ms after error 22; no motion for "
           f"{t_resume - t_err:.2f} s until resume; moving {move_s * 1e3:.0f} ms after resume")


def test_xarm_lost_connection_stops_reconnects_with_backoff_and_waits_for_resume(tmp_path):
    d = xarm_daemon(tmp_path / "d", "--record", "drop.mcap")
    try:
        d.wait_ready()
        c = d.collector
        moving(d)
        i = len(c)
        t_drop = d.fault("arm_drop")["t"]
        _, ev = c.event("fault", timeout_s=10, start=i, source="arm", detail="disconnected")
        _, s = c.state(lambda s: s["t"] > ev["t"] + 0.1, timeout_s=10, start=i)
        assert s["command_twist"] == ZERO6 and s["safety"] == "arm_fault"
        assert d.fault("speed")["speed"] == ZERO6  # the last command's duration ran out
        # Reconnect attempts with a doubling delay, up to reconnect_max_s.
        deadline = time.monotonic() + 30
        while len(attempts := d.fault(f"calls connect {t_drop}")["calls"]) < 6:
            assert time.monotonic() < deadline, attempts
            time.sleep(0.2)
        assert all(a["result"] == "failed" for a in attempts)
        gaps = [b["t"] - a["t"] for a, b in itertools.pairwise(attempts)]
        expect = [min(0.1 * 2 ** (k + 1), 0.8) for k in range(len(gaps))]
        for g, e in zip(gaps, expect):
            assert e - 0.005 <= g <= e + 0.1, (gaps, expect)
        assert d.request({"cmd": "status"})["arm_status"]["connected"] is False
        # The link comes back: reconnected, but still stopped until resume.
        i = len(c)
        t_restore = d.fault("arm_restore")["t"]
        _, ev2 = c.event("fault", timeout_s=10, start=i, source="arm")
        assert ev2["detail"] == "disconnected (reconnected; resume to re-enable)"
        st_ = d.request({"cmd": "status"})
        assert st_["arm_status"]["connected"] is True and st_["arm_status"]["reconnects"] == 1
        _, s = c.state(lambda s: s["t"] > ev2["t"] + 0.5, timeout_s=10, start=i)
        assert s["command_twist"] == ZERO6 and s["arm"]["fault"] == ev2["detail"]
        _, move_s = resume_and_move(d, t_drop)
        assert d.stop() == 0
    finally:
        d.close()
    clean_log(d)
    figure("xarm_disconnect", f"fault event {(ev['t'] - t_drop) * 1e3:.1f} ms after the drop; reconnect attempts "
           f"every {', '.join(f'{g:.2f}' for g in gaps)} s (0.1 s doubling to 0.8 s); reconnected "
           f"{ev2['t'] - t_restore:.2f} s after the link returned; no motion until resume, moving "
           f"{move_s * 1e3:.0f} ms after it")


def test_xarm_reply_timeout_stops_reports_and_reconnects(tmp_path):
    """The controller stops answering (every SDK call blocks, then returns code 3 as after the SDK's 2 s
    reply timeout): the arm stops by itself (command duration), the daemon reports it and commands zero,
    reconnects, and waits for resume."""
    d = xarm_daemon(tmp_path / "d", "--record", "hang.mcap")
    try:
        d.wait_ready()
        c = d.collector
        moving(d)
        i = len(c)
        t_hang = d.fault("arm_hang 2")["t"]
        _, ev = c.event("fault", timeout_s=10, start=i, source="arm")
        report_s = ev["t"] - t_hang
        assert ev["detail"].startswith("xArm not answering: no reply to ")
        # The driver notices a call without reply after STALE_POSE_S (0.5 s), not at the SDK's 2 s timeout.
        assert 0.5 <= report_s <= 0.5 + 3 * CONTROL_S + 0.05, report_s
        _, s = c.state(lambda s: s["t"] > ev["t"] + 0.1, timeout_s=10, start=i)
        assert s["command_twist"] == ZERO6 and s["safety"] == "arm_fault"
        assert d.fault("speed")["speed"] == ZERO6  # stopped by the last command's duration meanwhile
        last = accepted_moving(d.fault(f"calls {VC} {t_hang - 0.5}")["calls"])[-1]
        assert last["t"] <= t_hang + 0.01, "a command got through the hung link"
        stop_s = last["t"] + last["kwargs"]["duration"] - t_hang
        _, dis = c.event("fault", timeout_s=10, start=i, source="arm", detail="disconnected")
        c.event("fault", timeout_s=10, start=i, source="arm", detail="disconnected (reconnected; resume to re-enable)")
        _, move_s = resume_and_move(d, t_hang)
        assert d.stop() == 0
    finally:
        d.close()
    clean_log(d)
    states, _, _ = recording(tmp_path / "d" / "hang.mcap")
    zero = next(s for s in states if s["t"] > t_hang and s["command_twist"] == ZERO6)
    figure("xarm_timeout", f"arm stopped by the command duration {stop_s * 1e3:.0f} ms after the controller "
           f"stopped answering; '{ev['detail']}' reported {report_s:.2f} s after, command zero "
           f"{(zero['t'] - t_hang):.2f} s after; link declared lost at the SDK's reply timeout "
           f"({dis['t'] - t_hang:.2f} s), reconnected, moving {move_s * 1e3:.0f} ms after resume")


def test_xarm_nan_pose_stops_and_reports_with_a_clear_error(tmp_path):
    """The controller reports a NaN pose (a corrupt report): the pose is refused, the cached one ages, and
    after STALE_POSE_S the arm is stopped with a fault naming the cause; a good pose again does not
    resume by itself."""
    d = xarm_daemon(tmp_path / "d")
    try:
        d.wait_ready()
        c = d.collector
        moving(d)
        i = len(c)
        t_nan = d.fault("arm_pose_nan")["t"]
        _, ev = c.event("fault", timeout_s=10, start=i, source="arm")
        assert ev["detail"].startswith("xArm pose not updated for 0.5 s (unusable reply: position must be 3 finite")
        assert "nan" in ev["detail"]
        _, s = c.state(lambda s: s["t"] > ev["t"] + 0.1, timeout_s=10, start=i)
        assert s["command_twist"] == ZERO6 and s["safety"] == "arm_fault"
        assert all(math.isfinite(x) for x in s["gripper_pose"]["position"])  # never published
        assert d.request({"cmd": "status"})["arm_status"]["poll_errors"] > 10
        d.fault("arm_pose_ok")
        _, s = c.state(lambda s: s["t"] > ev["t"] + 0.6, timeout_s=10, start=i)
        assert s["command_twist"] == ZERO6 and s["arm"]["fault"] == ev["detail"]
        # (Until the fault the arm moved on the last good pose, for at most STALE_POSE_S.)
        _, move_s = resume_and_move(d, ev["t"])
        assert d.stop() == 0
    finally:
        d.close()
    clean_log(d)
    figure("nan_pose", f"refused at once, fault '{ev['detail'][:60]}...' {ev['t'] - t_nan:.2f} s after the "
           f"first NaN pose (STALE_POSE_S 0.5 s: until then it moved on the last good pose); "
           f"moving {move_s * 1e3:.0f} ms after resume")


# -- NaN/inf in joystick values ---------------------------------------------------------------------------


@pytest.mark.parametrize("bad", ["nan 0 0", "0 inf 0", "0 0 -inf", "nan nan nan"])
def test_non_finite_joystick_values_are_refused_and_never_reach_the_arm(tmp_path, bad):
    """evdev carries integers, so a non-finite sample can only come from a broken driver or mapper: it is
    handed to the daemon's input callback directly. It is refused with an event; the stick's last good
    value stays in force and no NaN ever reaches a command, the recording or the stream."""
    d = faultd(tmp_path / "d", "--method", "manual", "--duration", "600", "--no-speech", "--record", "nan.mcap")
    try:
        d.wait_ready()
        c = d.collector
        c.state(lambda s: s["input"]["connected"], timeout_s=30, what="the stick connected")
        d.fault("axes 0.5 0 0")
        _, s0 = c.state(lambda s: s["user_twist"][0] > 0, timeout_s=10)
        i = len(c)
        t_bad = d.fault(f"sample {bad}")["t"]
        _, ev = c.event("input_refused", timeout_s=10, start=i)
        assert ev["reason"] == "joystick axes must be 3 finite numbers"
        _, s = c.state(lambda s: s["t"] > ev["t"] + 0.2, timeout_s=10, start=i)
        assert s["user_twist"] == s0["user_twist"] and s["command_twist"][0] > 0
        assert d.stop() == 0
    finally:
        d.close()
    clean_log(d)
    states, events, _ = recording(tmp_path / "d" / "nan.mcap")
    assert [e for e in events if e["type"] == "input_refused"]
    for s in states:
        for k in ("user_twist", "robot_twist", "command_twist"):
            assert all(math.isfinite(x) for x in s[k]), (k, s)
    around = [s for s in states if s0["t"] <= s["t"] <= t_bad + 0.2]
    assert around and all(s["user_twist"] == around[0]["user_twist"] for s in around)
    assert all(s["safety"] != "nan_refused" for s in around), "the sample got past the input check"


# -- refusing to start: bad configs, bad scene files ------------------------------------------------------

SCENE = """\
name = "fault-check"

[start]
position = [0.25, 0.0, 0.35]
rpy = [3.14159265, -0.78539816, 0.0]

[[objects]]
name = "cup"
shape = "cylinder"
size = [0.04, 0.10]
position = [0.45, 0.05, 0.05]
rim = true
grasp_types = ["top", "side"]
"""

BAD_SCENES = {
    "start.position": ("position = [0.25, 0.0, 0.35]", "position = [0.25, nan, 0.35]", "start.position[1]"),
    "start.rpy": ("rpy = [3.14159265, -0.78539816, 0.0]", "rpy = [3.14159265, -inf, 0.0]", "start.rpy[1]"),
    "object.position": ("position = [0.45, 0.05, 0.05]", "position = [inf, 0.05, 0.05]",
                        "objects[0] 'cup': position[0]"),
    "object.size": ("size = [0.04, 0.10]", "size = [0.04, nan]", "objects[0] 'cup': size[1]"),
    "object.yaw": ("rim = true", "rim = true\nyaw = -inf", "objects[0] 'cup': yaw"),
    "object.grasp_types": ('["top", "side"]', '["top", "sideways"]', "objects[0] 'cup': grasp_types"),
}

BAD_CONFIGS = {
    "unknown key": ("[runtime]\npublish_hzz = 30\n", "runtime.publish_hzz: unknown key"),
    "nan": ("[safety]\nstale_command_s = nan\n", "safety.stale_command_s"),
    "inf": ("[safety]\nlinear_accel_mps2 = inf\n", "safety.linear_accel_mps2"),
    "negative": ("[limits]\nlinear_mps = -0.1\n", "limits.linear_mps"),
    "wrong type": ('[planner]\nperiod_s = "fast"\n', "planner.period_s"),
    "out of range": ("[runtime]\ncontrol_hz = 5000\n", "runtime.control_hz"),
    "box": ("[safety]\nworkspace_min_m = [0.0, 0.0, 1.0]\n", "workspace_min_m"),
    "joystick axis": ('[joystick]\naxes = ["ABS_X", "ABS_Y", "ABS_NOPE"]\n', "joystick.axes: 'ABS_NOPE'"),
    "joystick button": ('[joystick]\nbutton_stop = "BTN_NOPE"\n', "joystick.button_stop: 'BTN_NOPE'"),
    "record path": ('[record]\npath = "/proc/no/such/dir/run.mcap"\n', "record.path"),
    "xarm without its SDK": ('[arm]\nbackend = "xarm"\n', 'arm.backend "xarm"'),
    "endpoint": ('[zmq]\npub = "tcp://127.0.0.1:notaport"\n', "zmq.pub"),
}


def _processes_with(marker: str) -> list[int]:
    """Pids whose environment carries ``marker`` (the daemon and anything it started)."""
    found = []
    for p in Path("/proc").iterdir():
        if p.name.isdigit():
            try:
                if marker.encode() in (p / "environ").read_bytes() and not process_gone(int(p.name)):
                    found.append(int(p.name))
            except OSError:
                pass
    return found


def _refuses_to_start(tmp_path: Path, config: str | None, args: list[str], key: str, entry: list[str] = CLI,
                      record: bool = True, ports: bool = True) -> str:
    """Run ``sa-daemon run``; it must exit 2 naming ``key`` and leave nothing behind."""
    marker = f"SA_FAULT_TEST={uuid.uuid4().hex}"
    pub, cmd = free_port(), free_port()
    argv = [*entry]
    if config is not None:
        (tmp_path / "config.toml").write_text(config)
        argv += ["--config", str(tmp_path / "config.toml")]
    argv += ["run", "--duration", "5", "--no-speech", "--quiet", *args]
    if ports:
        argv += ["--pub", f"tcp://127.0.0.1:{pub}", "--cmd", f"tcp://127.0.0.1:{cmd}"]
    if record:
        argv += ["--record", "run.mcap"]
    env = {**os.environ, "SA_FAULT_TEST": marker.split("=", 1)[1]}
    t0 = time.monotonic()
    r = subprocess.run(argv, capture_output=True, text=True, timeout=120, cwd=tmp_path, env=env, check=False)
    took = time.monotonic() - t0
    assert r.returncode == 2, (r.returncode, r.stderr[-2000:])
    assert key in r.stderr, r.stderr[-2000:]
    assert "Traceback" not in r.stderr, r.stderr[-2000:]
    assert "sa-daemon: ran" not in r.stderr  # it never ran
    assert not (tmp_path / "run.mcap").exists(), "a recording was started"
    for port in (pub, cmd):
        with socket.socket() as s:
            s.bind(("127.0.0.1", port))  # free again (or never taken)
    assert _processes_with(marker) == [], "a process (the planner worker?) was left behind"
    return f"exit 2 in {took:.1f} s: {r.stderr.strip().splitlines()[-1][:150]}"


@pytest.mark.parametrize("name", list(BAD_SCENES))
def test_bad_scene_file_exits_2_naming_the_key_and_starts_nothing(tmp_path, name):
    old, new, key = BAD_SCENES[name]
    assert SCENE.count(old) == 1
    good = tmp_path / "good.toml"
    good.write_text(SCENE)
    from sa_daemon.world.scene import load_scene

    assert load_scene(good).targets == ["cup:top", "cup:side"]  # the unmodified scene is valid
    (tmp_path / "bad.toml").write_text(SCENE.replace(old, new))
    text = _refuses_to_start(tmp_path, None, ["--scene-file", "bad.toml", "--task", "cup:top"], key)
    figure(f"bad_scene[{name}]", text)


@pytest.mark.parametrize("name", list(BAD_CONFIGS))
def test_bad_config_exits_2_naming_the_key_and_starts_nothing(tmp_path, name):
    config, key = BAD_CONFIGS[name]
    args = ["--scene", "scene1"]
    if name.startswith("joystick"):
        args += ["--input", "evdev"]
    if name == "xarm without its SDK":
        try:
            import xarm  # noqa: F401
        except ImportError:
            pass
        else:
            pytest.skip("the xArm SDK is installed here")
    text = _refuses_to_start(tmp_path, config, args, key, record=name != "record path", ports=name != "endpoint")
    figure(f"bad_config[{name}]", text)


def test_bad_joystick_config_is_refused_even_with_a_stick_plugged(tmp_path):
    """With a (fake) stick present the bad axis name is still refused before anything starts, instead of
    the stick being ignored as "not a joystick"."""
    config, key = BAD_CONFIGS["joystick axis"]
    text = _refuses_to_start(tmp_path, config, ["--scene", "scene1", "--input", "evdev"], key,
                             entry=[sys.executable, str(FAULTD), "--"])
    figure("bad_joystick_config_with_stick", text)


# -- speech: the engine missing, failing, hanging; the sound player failing, hanging ----------------------

SPEECH_CONFIG = COMMIT_MODEL_TOML + """
[sim_user]
answer_delay_s = 1000.0

[speech]
wav_dir = "wav"
play = {play}
"""


def control_periods(log_ns: list[int], t0: float, t1: float, states: list[dict]) -> np.ndarray:
    """Intervals (s) between recorded control ticks with daemon time in [t0, t1]."""
    ns = [n for n, s in zip(log_ns, states) if t0 <= s["t"] <= t1]
    return np.diff(np.asarray(ns, dtype=float)) / 1e9


def ask_and_answer(d: DaemonProc, start: int, timeout_s: float = 60.0) -> tuple[dict, dict]:
    """Wait for the next question, answer it "no" by command; (question, answer) events."""
    c = d.collector
    iq, q = c.event("question", timeout_s=timeout_s, start=start)
    r = d.request({"cmd": "answer", "value": "no"})
    assert r == {"ok": True}, r
    _, a = c.event("answer", timeout_s=10, start=iq, goal=q["goal"])
    assert a["source"] == "command" and a["value"] == "no"
    return q, a


def loops_unaffected(d: DaemonProc, start: int, t0: float, t1: float, path: Path) -> str:
    """The state stream (no gap over 200 ms) and the control loop (recorded ticks) while speech was broken."""
    gap_t, gap_rx = state_gaps(d, start)
    assert gap_t <= MAX_STATE_GAP_S and gap_rx <= RECEIVER_GAP_S, (gap_t, gap_rx)
    states, _, log_ns = recording(path)
    periods = control_periods(log_ns, t0, t1, states)
    assert len(periods) >= 0.9 * (t1 - t0) / CONTROL_S, f"{len(periods)} control ticks in {t1 - t0:.1f} s"
    p99 = float(np.percentile(periods, 99))
    assert p99 <= 2 * CONTROL_S, f"control period p99 {p99 * 1e3:.1f} ms"
    return (f"control {len(periods) / (t1 - t0):.0f} Hz, period p99 {p99 * 1e3:.1f} ms, max "
            f"{periods.max() * 1e3:.1f} ms over {t1 - t0:.0f} s; largest state gap {max(gap_t, gap_rx) * 1e3:.0f} ms")


def test_no_speech_engine_questions_are_still_published_and_answerable(tmp_path):
    d = faultd(tmp_path / "d", "--method", "policy", "--duration", "600", "--record", "sp.mcap",
               config=SPEECH_CONFIG.format(play="false"), inp="sim", speech_init="fail")
    try:
        ready = d.wait_ready()
        c = d.collector
        st_ = d.request({"cmd": "status"})
        assert st_["ok"]
        i0 = 0
        _, un = c.event("speech_unavailable", timeout_s=10)
        assert un["error"] == "speech unavailable: RuntimeError: injected: no speech driver"
        q, a = ask_and_answer(d, i0)
        assert q["spoken"] == "unavailable" and q["text"].endswith("your goal?")
        _, s = c.state(lambda s: s["t"] > a["t"] + 2.0, timeout_s=10)
        assert d.stop() == 0
    finally:
        d.close()
    clean_log(d)
    assert not (tmp_path / "d" / "wav").exists() or not list((tmp_path / "d" / "wav").iterdir())
    loops = loops_unaffected(d, 0, ready["t"], s["t"], tmp_path / "d" / "sp.mcap")
    figure("speech_missing", f"speech_unavailable at start; question at t={q['t']:.1f} s published "
           f"(spoken 'unavailable'), answered by command {a['after_s'] * 1e3:.0f} ms later; {loops}")


def test_speech_engine_failing_then_hanging_leaves_questions_answerable(tmp_path):
    d = faultd(tmp_path / "d", "--method", "policy", "--duration", "600", "--record", "sp.mcap",
               config=SPEECH_CONFIG.format(play="false"), inp="sim")
    try:
        d.wait_ready()
        c = d.collector
        d.fault("speech_fail")
        q1, _ = ask_and_answer(d, 0)
        assert q1["spoken"] == "written"  # queued (play = false): the engine fails while speaking it
        _, sp = c.event("spoken", timeout_s=30, text=q1["text"])
        assert sp["error"] == "RuntimeError: injected: the speech driver failed" and sp["played"] is False
        assert sp["outcome"] == "failed"
        assert sp["wav"] is None
        i_hang = len(c)
        t_hang = d.fault("speech_hang")["t"]
        q2, _ = ask_and_answer(d, i_hang, timeout_s=120)
        q3, a3 = ask_and_answer(d, c.event("answer", start=i_hang, goal=q2["goal"])[0], timeout_s=120)
        assert not [m for m in c.slice(i_hang, topic="event") if m["type"] == "spoken"], "a hung engine spoke"
        _, s = c.state(lambda s: s["t"] > a3["t"] + 2.0, timeout_s=10)
        t_term = time.monotonic()
        assert d.stop(timeout_s=20) == 0  # the hung speech thread does not hold the exit
        exit_s = time.monotonic() - t_term
    finally:
        d.close()
    clean_log(d)
    loops = loops_unaffected(d, i_hang, t_hang, s["t"], tmp_path / "d" / "sp.mcap")
    assert exit_s < 10.0
    figure("speech_engine", f"failing engine: spoken event with the error, question answered; hung engine: "
           f"{2} questions published and answered by command (t={q2['t']:.1f}, {q3['t']:.1f} s), no spoken "
           f"event; SIGTERM exit 0 in {exit_s:.1f} s; {loops}")


APLAY = """\
#!/bin/sh
# A sound player for the tests: its mode file says whether it fails, hangs or plays.
echo $$ >> "$APLAY_PIDS"
case "$(cat "$APLAY_MODE")" in
  fail) echo "aplay: main:831: audio open error: No such file or directory" >&2; exit 1 ;;
  hang) exec sleep 100000 ;;
  *) exit 0 ;;
esac
"""


def test_sound_player_failing_then_hanging_leaves_questions_answerable_and_nothing_behind(tmp_path):
    """The real engine synthesises each question; the fake ``aplay`` first fails (no sound card), then
    hangs. Questions stay published and answerable, the loops do not notice, and a hung player does not
    outlive the daemon."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    (bin_dir / "aplay").write_text(APLAY)
    (bin_dir / "aplay").chmod(0o755)
    mode, pids = tmp_path / "aplay.mode", tmp_path / "aplay.pids"
    mode.write_text("fail")
    env = {"PATH": f"{bin_dir}{os.pathsep}{os.environ['PATH']}", "APLAY_MODE": str(mode), "APLAY_PIDS": str(pids)}
    d = faultd(tmp_path / "d", "--method", "policy", "--duration", "600", "--record", "sp.mcap",
               config=SPEECH_CONFIG.format(play="true"), inp="sim", env=env)
    try:
        d.wait_ready()
        c = d.collector
        q1, _ = ask_and_answer(d, 0)
        assert q1["spoken"] == "played"  # a player is installed (the fake): the question is for playing
        _, sp = c.event("spoken", timeout_s=60, text=q1["text"])
        assert sp["played"] is False and sp["error"] == "aplay: aplay: main:831: audio open error: No such file or directory"
        assert sp["outcome"] == "written"
        assert sp["wav"] and (tmp_path / "d" / sp["wav"]).stat().st_size > 1000  # synthesised all the same
        mode.write_text("hang")
        i_hang = len(c)
        t_hang = d.fault("now")["t"]
        q2, _ = ask_and_answer(d, i_hang, timeout_s=120)
        deadline = time.monotonic() + 60
        while len(pids.read_text().split()) < 2:  # the player of question 2 is running (and hangs)
            assert time.monotonic() < deadline, "the player was never started for question 2"
            time.sleep(0.05)
        hung = int(pids.read_text().split()[1])
        assert not process_gone(hung)  # hanging (the next question's playback may end it; the daemon's stop must)
        q3, a3 = ask_and_answer(d, c.event("answer", start=i_hang, goal=q2["goal"])[0], timeout_s=120)
        _, s = c.state(lambda s: s["t"] > a3["t"] + 2.0, timeout_s=10)
        t_term = time.monotonic()
        assert d.stop(timeout_s=20) == 0
        exit_s = time.monotonic() - t_term
    finally:
        d.close()
    clean_log(d)
    deadline = time.monotonic() + 10
    while not process_gone(hung):
        if time.monotonic() > deadline:
            os.kill(hung, signal.SIGKILL)
            raise AssertionError("the hung sound player outlived the daemon")
        time.sleep(0.05)
    loops = loops_unaffected(d, i_hang, t_hang, s["t"], tmp_path / "d" / "sp.mcap")
    figure("sound_player", f"failing aplay: spoken event with aplay's error, WAV kept, question answered; hung "
           f"aplay: questions at t={q2['t']:.1f} and {q3['t']:.1f} s published and answered; SIGTERM exit 0 in "
           f"{exit_s:.1f} s and the hung player ended with the daemon; {loops}")


# -- ending the daemon: SIGTERM, SIGINT, SIGKILL (xArm) ---------------------------------------------------


def mcap_summary(path: Path) -> Any:
    """The summary section of a finished MCAP file."""
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        return make_reader(f).get_summary()


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT], ids=["SIGTERM", "SIGINT"])
def test_signal_stops_the_xarm_first_flushes_the_recording_and_exits_0(tmp_path, sig):
    d = xarm_daemon(tmp_path / "d", "--record", "end.mcap")
    try:
        d.wait_ready()
        moving(d)
        d.collector.state(lambda s: s["command_twist"][0] > 0.1 and s["t"] > 2.0, timeout_s=10, what="full speed")
        t_sig = d.fault("now")["t"]
        d.proc.send_signal(sig)
        rc = d.proc.wait(30)
        assert rc == 0, d.log
        d._reader.join(10)
        final = d.final
    finally:
        d.close()
    clean_log(d)
    assert final is not None and final["exit"] == 0
    path = tmp_path / "d" / "end.mcap"
    summary = mcap_summary(path)
    assert summary is not None and summary.statistics is not None, "the recording was not finished"
    states, events, _ = recording(path)
    assert summary.statistics.message_count == messages_in(path)  # every message reads back
    assert states and events
    kinds = [e["type"] for e in events]
    assert kinds[-2:] == ["shutdown", "stopped"] or kinds[-3:-1] == ["shutdown", "stopped"], kinds[-4:]
    shutdown = next(e for e in events if e["type"] == "shutdown")
    stopped = next(e for e in events if e["type"] == "stopped")
    assert shutdown["reason"] == signal.Signals(sig).name and stopped["code"] == 0
    # The arm's last commands: a zero the controller accepted, sent before the daemon said "stopped";
    # nothing moving after the shutdown began; the controller's velocity is zero.
    tail = final["vc_tail"]
    last = tail[-1]
    assert last["speeds"] == ZERO6 and last["result"] == 0
    assert not [c for c in tail if c["t"] > shutdown["t"] and nonzero(c["speeds"])]
    first_zero = next(c for c in tail if c["t"] >= shutdown["t"] and not nonzero(c["speeds"]))
    assert first_zero["t"] <= stopped["t"]
    assert final["speed"] == ZERO6 and final["connected"] is False
    assert nonzero(states[-1]["command_twist"]) or states[-1]["t"] >= t_sig  # recorded up to the end
    assert states[-1]["t"] >= t_sig - 2 * CONTROL_S
    figure(f"{signal.Signals(sig).name.lower()}", f"exit 0; zero velocity accepted by the controller "
           f"{(first_zero['t'] - shutdown['t']) * 1e3:.1f} ms after the shutdown began, before 'stopped' "
           f"(+{(stopped['t'] - first_zero['t']) * 1e3:.1f} ms); recording finished (summary: "
           f"{summary.statistics.message_count} messages), last state {1e3 * (shutdown['t'] - states[-1]['t']):.0f} ms "
           f"before the shutdown event")


def test_xarm_stops_by_itself_when_the_daemon_stops_commanding(tmp_path):
    """What a SIGKILL or a stalled daemon means for the arm: no more commands. Every velocity command
    carries ``duration = arm.xarm.command_periods / control_hz``, and the controller (here the fake, which
    models the duration) zeroes the speed that long after the last one. The daemon's event loop is
    blocked for 0.5 s while the fake's velocity is watched."""
    d = xarm_daemon(tmp_path / "d")
    try:
        d.wait_ready()
        moving(d)
        d.collector.state(lambda s: s["command_twist"][0] > 0.1, timeout_s=10, what="full speed")
        r = d.fault("loop_hang 0.5")
        calls = d.fault(f"calls {VC} 0")["calls"]
        assert d.stop() == 0
    finally:
        d.close()
    clean_log(d)
    duration = CFG.arm.xarm.command_periods / CFG.runtime.control_hz
    assert calls and all(abs(c["kwargs"]["duration"] - duration) < 1e-12 for c in calls)
    stop_after_last, stop_after_block = assert_stopped_by_duration(r)
    figure("xarm_deadman", f"every command carries duration {duration * 1e3:.0f} ms ({len(calls)} checked); "
           f"no command for 0.5 s: the controller's speed is zero {stop_after_block * 1e3:.1f} ms after the "
           f"daemon stalled, {stop_after_last * 1e3:.1f} ms after the last command")


def test_sigkill_of_an_xarm_daemon_keeps_the_recording_up_to_the_last_flush(tmp_path):
    d = xarm_daemon(tmp_path / "d", "--record", "kill.mcap")
    try:
        d.wait_ready()
        moving(d)
        d.collector.state(lambda s: s["t"] >= 3.0, timeout_s=30)
        worker = d.collector.latest_state()["planner"]["pid"]
        t_kill = d.fault("now")["t"]
        assert d.stop(signal.SIGKILL) == -signal.SIGKILL
    finally:
        d.close()
    deadline = time.monotonic() + 10
    while not process_gone(worker):  # the orphaned planner sees its pipe close and exits
        assert time.monotonic() < deadline, "the planner worker outlived the daemon"
        time.sleep(0.05)
    path = tmp_path / "d" / "kill.mcap"
    states, events, _ = recording(path)
    assert states and states[0]["t"] < 1.0 and [e for e in events if e["type"] == "ready"]
    ts = [s["t"] for s in states]
    assert ts == sorted(ts) and max_gap(ts) <= 0.1
    lost = t_kill - states[-1]["t"]
    assert lost <= CFG.record.flush_s + 0.3, f"the last {lost:.2f} s were lost"
    figure("sigkill", f"recording readable up to {lost:.2f} s before the kill (record.flush_s "
           f"{CFG.record.flush_s} s), {len(states)} states; the planner worker exited by itself")


# -- the disk under the recorder fills up ---------------------------------------------------------------


def test_full_disk_under_the_recorder_is_reported_and_the_arm_stays_controlled(tmp_path):
    """The recording lives on a real, small filesystem (a 1 MiB tmpfs) that another file fills while the
    xArm moves: the next write fails with ENOSPC. The daemon goes on commanding the arm (and obeys a
    stop), reports the failure once (an error line, a ``fault`` event with source ``recorder``, ``status``
    ``record.error``), nothing hangs, SIGTERM exits 0, and the recording reads back up to its last
    complete flush before the disk filled."""
    with small_disk(tmp_path / "disk", "1m") as disk:
        rec = disk / "rec.mcap"
        d = xarm_daemon(tmp_path / "d", "--record", str(rec))
        try:
            d.wait_ready()
            c = d.collector
            moving(d)
            c.state(lambda s: s["t"] >= 3.0, timeout_s=30, what="3 s of recording")
            i_fill = len(c)
            t_fill = d.fault("now")["t"]
            filler_bytes = fill_disk(disk)
            _, ev = c.event("fault", timeout_s=10 * CFG.record.flush_s, start=i_fill, source="recorder")
            assert ev["detail"].startswith("recording stopped: No space left on device (ENOSPC) writing "), ev
            st_ = d.request({"cmd": "status"})
            assert st_["record"]["error"] == ev["detail"] and st_["record"]["path"] == str(rec)
            flushed = st_["record"]["flushed"]
            assert f"the {flushed} messages before it are readable" in ev["detail"]
            # Still controlling the arm: the held stick keeps it moving, then a stop holds it.
            _, s = c.state(lambda s: s["t"] > ev["t"] + 1.0, timeout_s=10, start=i_fill)
            assert s["command_twist"][0] > 0 and s["arm"]["fault"] is None and s["safety"] != "stopped"
            moves = [m for m in accepted_moving(d.fault(f"calls {VC} {ev['t']}")["calls"]) if m["t"] <= s["t"]]
            assert len(moves) >= 0.5 * (s["t"] - ev["t"]) / CONTROL_S, f"{len(moves)} commands in {s['t'] - ev['t']:.2f} s"
            i_stop = len(c)
            assert d.request({"cmd": "stop"})["ok"]
            _, stopped = c.event("stop", timeout_s=10, start=i_stop)
            _, s = c.state(lambda s: s["t"] > stopped["t"] + 0.1, timeout_s=10, start=i_stop)
            assert s["command_twist"] == ZERO6 and s["safety"] == "stopped"
            assert d.fault("speed")["speed"] == ZERO6
            assert d.request({"cmd": "status"})["record"]["dropped"] > 0  # recording stays off, quietly
            t_term = time.monotonic()
            assert d.stop(signal.SIGTERM, timeout_s=20) == 0
            exit_s = time.monotonic() - t_term
        finally:
            d.close()
        states, events, _ = recording(rec)
        readable = messages_in(rec)
        size = rec.stat().st_size
    log = (d.dir / "stderr.txt").read_text(errors="replace")
    assert "Traceback" not in log and "Exception in thread" not in log, log[-3000:]
    assert log.count(" ERROR ") == 1 and f"ERROR sa_daemon: {ev['detail']}" in log, log[-3000:]
    assert exit_s < 10.0, f"SIGTERM took {exit_s:.1f} s"
    # What reached the disk before it filled reads back: from the start, without a gap, and all of it.
    assert states and states[0]["t"] < 1.0 and [e for e in events if e["type"] == "ready"]
    ts = [s["t"] for s in states]
    assert ts == sorted(ts) and max_gap(ts) <= 0.1
    assert readable == flushed
    lost_s = t_fill - ts[-1]
    assert ts[-1] <= ev["t"] and lost_s <= CFG.record.flush_s + 0.3, f"the last {lost_s:.2f} s before the fill were lost"
    figure("full_disk", f"ENOSPC (a 1 MiB tmpfs filled by {filler_bytes // 1024} KiB of another file): reported "
           f"{ev['t'] - t_fill:.2f} s after the disk filled (record.flush_s {CFG.record.flush_s} s), one error line "
           f"and a fault event; the arm commanded on ({len(moves)} moving commands in the next "
           f"{s['t'] - ev['t']:.1f} s) and stopped on request; SIGTERM exit 0 in {exit_s:.1f} s; recording "
           f"({size // 1024} KiB) readable up to {lost_s:.2f} s before the disk filled, {len(states)} states")


# -- the systemd watchdog kills a stuck daemon ------------------------------------------------------------

UNIT = Path(__file__).resolve().parents[1] / "systemd" / "sa-daemon.service"


def _unit_seconds(name: str) -> float | None:
    for line in UNIT.read_text().splitlines():
        k, _, v = line.partition("=")
        if k.strip() == name and v.strip():
            return float(v.strip().removesuffix("s"))
    return None


def _descendants(pid: int) -> list[int]:
    """The processes started by ``pid`` (its control group, as far as this test is concerned)."""
    children: dict[int, list[int]] = {}
    for p in Path("/proc").iterdir():
        if p.name.isdigit():
            try:
                ppid = int((p / "stat").read_text().rsplit(")", 1)[1].split()[1])
            except (OSError, IndexError, ValueError):
                continue
            children.setdefault(ppid, []).append(int(p.name))
    out, todo = [], [pid]
    while todo:
        for c in children.get(todo.pop(), []):
            out.append(c)
            todo.append(c)
    return out


class FakeSystemd:
    """systemd's side of ``Type=notify`` with ``WatchdogSec=`` for one service, over a real notify socket.

    As systemd does: the daemon gets ``NOTIFY_SOCKET`` and ``WATCHDOG_USEC`` (the unit's ``WatchdogSec``);
    the watchdog is armed at ``READY=1``; when no ``WATCHDOG=1`` came for ``WatchdogSec``, the service is
    killed with the watchdog signal (SIGABRT, followed by SIGCONT so that a stopped process gets it) sent to
    the main process and the rest of its control group (``KillMode=control-group``), and whatever is still
    alive ``TimeoutAbortSec`` later (unset in the unit: ``TimeoutStopSec``) gets SIGKILL. A thread stamps
    each datagram on arrival.
    """

    def __init__(self) -> None:
        self.watchdog_s = _unit_seconds("WatchdogSec")
        assert self.watchdog_s, "the unit has no WatchdogSec"
        self.abort_timeout_s = _unit_seconds("TimeoutAbortSec") or _unit_seconds("TimeoutStopSec") or 90.0
        name = f"sa-daemon-test-{uuid.uuid4().hex}"
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        self.sock.bind("\0" + name)
        self.sock.settimeout(0.02)
        self.env = {"NOTIFY_SOCKET": "@" + name, "WATCHDOG_USEC": str(round(self.watchdog_s * 1e6))}
        self.msgs: list[tuple[float, bytes]] = []  # (arrival, datagram)
        self._halt = threading.Event()
        self._thread = threading.Thread(target=self._receive, daemon=True, name="test-fake-systemd")
        self._thread.start()

    def _receive(self) -> None:
        while not self._halt.is_set():
            try:
                data = self.sock.recv(4096)
            except TimeoutError:
                continue
            self.msgs.append((time.monotonic(), data))

    def _times(self, field: bytes) -> list[float]:
        return [at for at, m in list(self.msgs) if field in m.split(b"\n")]

    def pings(self) -> list[float]:
        return self._times(b"WATCHDOG=1")

    def wait_ready(self, timeout_s: float = START_TIMEOUT_S) -> float:
        end = time.monotonic() + timeout_s
        while not (ready := self._times(b"READY=1")):
            assert time.monotonic() < end, "no READY=1"
            time.sleep(0.02)
        return ready[0]

    def supervise(self, proc: subprocess.Popen, until_s: float) -> dict[str, Any]:
        """Run the watchdog until it fires (or ``until_s`` passes); then kill as systemd would."""
        armed = self.wait_ready()
        end = time.monotonic() + until_s
        while True:
            last = max([armed, *self.pings()])
            if time.monotonic() - last >= self.watchdog_s:
                break
            if time.monotonic() > end:
                return {"fired": False}
            time.sleep(0.005)
        t_abort = time.monotonic()
        group = _descendants(proc.pid)
        for pid in [proc.pid, *group]:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGABRT)
                os.kill(pid, signal.SIGCONT)
        killed = False
        try:
            rc = proc.wait(self.abort_timeout_s)
        except subprocess.TimeoutExpired:
            killed = True
            for pid in [proc.pid, *group]:
                with contextlib.suppress(ProcessLookupError):
                    os.kill(pid, signal.SIGKILL)
            rc = proc.wait(10)
        return {"fired": True, "last_ping": last, "t_abort": t_abort, "exit_s": time.monotonic() - t_abort,
                "rc": rc, "sigkill": killed, "group": group}

    def close(self) -> None:
        self._halt.set()
        self._thread.join(5)
        self.sock.close()


@pytest.mark.parametrize("how", ["loop_blocked", "sigstop"])
def test_systemd_watchdog_kills_a_stuck_daemon_and_the_arm_stops_by_itself(tmp_path, how):
    """The daemon runs under a fake systemd (the unit's WatchdogSec and timeouts, a real notify socket)
    with the fake xArm moving. It gets stuck - its event loop blocked for good (a hang inside the
    process), or the whole process stopped (SIGSTOP, what a stuck process looks like from outside). Its
    WATCHDOG=1 pings stop; a watchdog period after the last one "systemd" sends SIGABRT (+ SIGCONT) to the
    service's processes, and SIGKILL after TimeoutAbortSec if needed. While it is healthy it pings well
    within WatchdogSec. The arm stops by itself (the command duration) long before the watchdog fires,
    and the recording reads back up to the last flush before the stall (all of it while the recorder's
    thread still runs)."""
    sd = FakeSystemd()
    d = faultd(tmp_path / "d", "--method", "manual", "--duration", "600", "--no-speech", "--record", "wd.mcap",
               config=XARM_CONFIG, arm="xarm", env=sd.env)
    group: list[int] = []
    try:
        d.wait_ready()
        t_ready = sd.wait_ready()
        moving(d)
        d.collector.state(lambda s: s["command_twist"][0] > 0.1, timeout_s=30, what="moving at full speed")
        # Healthy for 2.5 s after READY=1 (counted from READY, not from the daemon's start: on a loaded
        # machine start-up alone can take seconds): at least two pings beside READY's.
        time.sleep(max(0.0, t_ready + 2.5 - time.monotonic()))
        healthy = [t_ready, *sd.pings()]
        assert len(healthy) >= 3, sd.msgs
        worst_healthy_gap = max_gap(healthy)
        arm = None
        if how == "loop_blocked":
            arm = d.fault(f"loop_stuck {2 * CONTROL_S + 3 * CFG.arm.xarm.command_periods / CFG.runtime.control_hz}")
            t_stuck = arm["blocked_mono"]
            t_stuck_daemon = arm["blocked_at"]
        else:
            t_stuck_daemon = d.fault("now")["t"]
            t_stuck = time.monotonic()
            os.kill(d.proc.pid, signal.SIGSTOP)
        res = sd.supervise(d.proc, until_s=3 * sd.watchdog_s + 10)
        group = res.get("group", [])
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.kill(d.proc.pid, signal.SIGCONT)
        d.close()
        sd.close()
    assert res["fired"], "the watchdog never fired: the daemon kept pinging while stuck"
    late_pings = [t - t_stuck for t in sd.pings() if t > t_stuck]
    assert all(dt <= 0.05 for dt in late_pings), f"pings {late_pings} s after the daemon got stuck"
    assert t_stuck - res["last_ping"] <= sd.watchdog_s / 2 + 0.1, "it had stopped pinging before the stall"
    fired_s = res["t_abort"] - t_stuck
    assert fired_s <= sd.watchdog_s + 0.2, fired_s
    assert worst_healthy_gap < 0.6 * sd.watchdog_s, f"a healthy daemon went {worst_healthy_gap:.2f} s without a ping"
    assert res["rc"] == -signal.SIGABRT and not res["sigkill"], res  # SIGCONT let even a stopped one take it
    assert group and all(process_gone(p) for p in group), "a process of the service outlived the abort"
    if arm is not None:
        _, stop_s = assert_stopped_by_duration(arm)
    states, events, _ = recording(tmp_path / "d" / "wd.mcap")
    assert states and states[0]["t"] < 1.0 and [e for e in events if e["type"] == "ready"]
    ts = [s["t"] for s in states]
    assert ts == sorted(ts) and max_gap(ts) <= 0.1
    lost_s = t_stuck_daemon - ts[-1]
    if how == "loop_blocked":  # the writer thread flushed everything queued before the stall
        assert lost_s <= 2 * CONTROL_S, f"the last {lost_s:.2f} s before the stall were lost"
    else:  # the whole process stopped: up to the last flush
        assert lost_s <= CFG.record.flush_s + 0.3, f"the last {lost_s:.2f} s before the stop were lost"
    figure(f"watchdog[{how}]", f"WatchdogSec {sd.watchdog_s:g} s: healthy pings at most {worst_healthy_gap:.2f} s "
           f"apart; none after the stall; SIGABRT {fired_s:.2f} s after the stall, dead {res['exit_s'] * 1e3:.0f} ms "
           f"later (no SIGKILL needed; TimeoutAbortSec {sd.abort_timeout_s:g} s), {len(group)} child processes gone; "
           + (f"arm speed zero {stop_s * 1e3:.1f} ms after the stall; " if arm is not None else "")
           + f"recording readable up to {lost_s * 1e3:.0f} ms before the stall")


# -- malformed traffic on the command socket --------------------------------------------------------------

MAX_BYTES = CFG.zmq.max_request_bytes
MAX_DEPTH = CFG.zmq.max_json_depth
HANDLER_REFUSALS = {"no question is pending"}
#: Refusals the handlers give valid requests whose content they cannot apply (a scene, a profile), by prefix.
HANDLER_PREFIXES = ("set_scene", "set_profile", "the arm is moving")


class Dealer:
    """A DEALER client: ``[b"", request]`` out, ``[b"", reply]`` back."""

    def __init__(self, endpoint: str, ctx: zmq.Context) -> None:
        self.sock = ctx.socket(zmq.DEALER)
        self.sock.setsockopt(zmq.LINGER, 0)
        self.sock.setsockopt(zmq.SNDHWM, 0)
        self.sock.setsockopt(zmq.RCVHWM, 0)
        self.sock.connect(endpoint)

    def send(self, raw: bytes) -> None:
        self.sock.send_multipart([b"", raw])

    def recv(self, timeout_s: float) -> dict | None:
        if not self.sock.poll(int(timeout_s * 1000)):
            return None
        empty, body = self.sock.recv_multipart()
        assert empty == b""
        return json.loads(body)

    def ask(self, raw: bytes, timeout_s: float = 10.0) -> dict | None:
        self.send(raw)
        return self.recv(timeout_s)

    def close(self) -> None:
        self.sock.close(0)


def refusal_for(raw: bytes) -> str | None:
    """The reason the protocol refuses ``raw`` with (``None``: a valid request, the handler decides)."""
    try:
        protocol.parse_request(raw, MAX_BYTES, MAX_DEPTH)
    except protocol.RequestError as e:
        return str(e)
    return None


def check_reply(raw: bytes, reply: dict | None) -> None:
    assert reply is not None, f"no reply to {raw[:80]!r}"
    reason = refusal_for(raw)
    if reason is not None:
        assert reply == {"ok": False, "error": reason}, (raw[:80], reply)
        assert reason  # a refusal always says why
    else:
        assert (reply["ok"] is True or reply == {"ok": False, "error": next(iter(HANDLER_REFUSALS))}
                or str(reply.get("error", "")).startswith(HANDLER_PREFIXES)), reply


@pytest.fixture(scope="module")
def target(tmp_path_factory):
    """One daemon that takes the fuzzing (ho: valid commands are harmless; --record: control periods)."""
    d = DaemonProc(tmp_path_factory.mktemp("fuzz"), "--method", "ho", "--duration", "900", "--no-speech",
                   "--record", "fuzz.mcap")
    ctx = zmq.Context()
    try:
        d.wait_ready()
        d.ctx = ctx
        d.dealer = Dealer(d.cmd, ctx)
        yield d
    finally:
        d.dealer.close() if hasattr(d, "dealer") else None
        d.close()
        ctx.term()


json_scalars = st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False, allow_infinity=False) | st.text()
json_values = st.recursive(json_scalars, lambda inner: st.lists(inner, max_size=4)
                           | st.dictionaries(st.text(max_size=8), inner, max_size=4), max_leaves=20)
command_names = st.sampled_from([*protocol.COMMANDS, "reboot", "", "STATUS", "status ", "answer\x00"]) | st.text(max_size=20)
shaped = st.fixed_dictionaries({"cmd": command_names | json_values},
                               optional={"value": json_values | st.sampled_from(["yes", "no", "maybe"]),
                                         "method": json_values | st.sampled_from([*CFG.__class__.model_fields["method"].default.split(), "teleport"]),
                                         "id": json_values, "force": json_values,
                                         "profile": json_values | st.sampled_from(["alex", "../x", "a.toml"]),
                                         "scene": json_values | st.fixed_dictionaries(
                                             {"objects": st.lists(st.dictionaries(st.sampled_from(
                                                 ["name", "shape", "size", "position", "grasp_types", "grasps"]),
                                                 json_values, max_size=6), max_size=3)}),
                                         "when": st.sampled_from(["now", "next_task", "later"]) | json_values,
                                         "marker_to_base": json_values})
requests = (
    st.binary(max_size=512)
    | json_values.map(lambda v: json.dumps(v).encode())
    | shaped.map(lambda v: json.dumps(v).encode())
    | st.integers(1, 200).map(lambda n: b"[" * n + b"]" * n)
    | st.tuples(st.integers(1, 30), st.sampled_from(["[", "{\"a\":"])).map(
        lambda t: ('{"cmd":"status","id":' + t[1] * t[0] + "1" + ("]" if t[1] == "[" else "}") * t[0] + "}").encode())
    | st.sampled_from([b"NaN", b'{"cmd":"status","id":Infinity}', b"\xef\xbb\xbf{}", b"{\"cmd\":\"stop\"", b" "])
)


@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(raw=requests)
def test_fuzzed_requests_are_each_refused_with_the_reason_or_answered(target, raw):
    check_reply(raw, target.dealer.ask(raw))


def test_the_daemon_survived_the_fuzzing(target):
    """(After the hypothesis test above: same module-scoped daemon.) Still the same process, answering,
    and the state stream never paused."""
    st_ = target.request({"cmd": "status"})
    assert st_["ok"] and st_["pid"] == target.proc.pid and target.proc.poll() is None
    gap_t, gap_rx = state_gaps(target)
    # The daemon's own clock decides "never paused"; the arrival gap also holds the test process's
    # scheduling (its subscriber shares the GIL with the fuzzing client): a looser bound there.
    assert gap_t <= MAX_STATE_GAP_S and gap_rx <= RECEIVER_GAP_S, (gap_t, gap_rx)


def test_huge_requests_are_refused_or_dropped_by_zeromq_and_the_client_recovers(target):
    dealer = Dealer(target.cmd, target.ctx)
    try:
        for size in (MAX_BYTES + 1, 4 * MAX_BYTES, 16 * MAX_BYTES):  # up to libzmq's MAXMSGSIZE: refused
            raw = b'{"cmd":"status","id":"' + b"x" * (size - 24) + b'"}'
            assert len(raw) == size
            r = dealer.ask(raw)
            assert r == {"ok": False, "error": f"request too large: {size} bytes (limit {MAX_BYTES})"}, r
        # Beyond 16 x the limit libzmq drops the connection before the daemon sees anything: no reply. A
        # request queued right behind it is lost with the connection or sent again after the reconnect.
        dealer.send(b"x" * (16 * MAX_BYTES + 1))
        dealer.send(b'{"cmd": "status"}')
        behind = dealer.recv(2.0)
        assert behind is None or (behind["ok"] and dealer.recv(1.0) is None), behind
        t0 = time.monotonic()
        deadline = t0 + 30
        while (r := dealer.ask(b'{"cmd": "status"}', timeout_s=1.0)) is None:
            assert time.monotonic() < deadline, "the client never got through again"
        back_s = time.monotonic() - t0
        assert r["ok"] and r["pid"] == target.proc.pid
        # Deeply nested and very long but within the size limit: refused by the depth check, fast.
        deep = b"[" * (MAX_BYTES // 2) + b"]" * (MAX_BYTES // 2)
        t0 = time.monotonic()
        r = dealer.ask(deep)
        deep_ms = (time.monotonic() - t0) * 1e3
        assert r == {"ok": False, "error": f"request nested deeper than {MAX_DEPTH} levels"}
    finally:
        dealer.close()
    figure("huge_requests", f"{MAX_BYTES + 1} B to {16 * MAX_BYTES} B refused 'request too large'; "
           f"{16 * MAX_BYTES + 1} B dropped by libzmq (MAXMSGSIZE) with the connection: no reply to it; the "
           f"request behind it {'lost' if behind is None else 'answered after the reconnect'}; the DEALER "
           f"got through again {back_s:.2f} s after a 2 s wait; 32768-deep nesting "
           f"refused in {deep_ms:.1f} ms")


def test_flood_of_requests_every_one_answered_no_pause_no_slowdown(target):
    """20000 requests as fast as 4 DEALER sockets can send them, a third malformed: every one gets exactly
    one reply, in order (a refusal with its reason, or the answer); the daemon answers at most
    zmq.max_requests_per_tick per control period, the rest waiting in ZeroMQ's queue, so the control loop keeps
    its time: by the daemon's own counters, at most 1 % of the control periods during the flood overran
    1.5 periods (the bench target is 0.1 % on a quiet machine; the old unthrottled loop showed a p99 of
    11-34 ms). A ``stop`` from another client during the flood is not queued behind it; the state stream
    keeps >= 20 Hz without a gap over 200 ms; status answers as fast afterwards."""
    c = target.collector

    def status_ms(n: int = 20) -> float:
        ts = []
        for _ in range(n):
            t0 = time.monotonic()
            assert target.request({"cmd": "status"})["ok"]
            ts.append((time.monotonic() - t0) * 1e3)
        return float(np.median(ts))

    before_ms = status_ms()
    bad = [b"\xff\xfe", b"[1,2]", b'{"cmd":"reboot"}', b'{"cmd":"answer","value":3}', b"[" * 50]
    dealers = [Dealer(target.cmd, target.ctx) for _ in range(4)]
    per = 5000
    sent: list[list[bytes]] = [[] for _ in dealers]
    try:
        for dl in dealers:  # connected before the clock starts
            assert dl.ask(b'{"cmd":"status"}') is not None
        s0 = target.request({"cmd": "status"})
        i0 = len(c)
        t_start_ns, t0 = time.time_ns(), time.monotonic()
        for k in range(per):
            for j, dl in enumerate(dealers):
                raw = bad[(k + j) % len(bad)] if (k + j) % 3 == 0 else b'{"cmd":"status","id":%d}' % k
                dl.send(raw)
                sent[j].append(raw)
        t_sent = time.monotonic() - t0
        # The carer's stop while the flood waits: the command socket serves its connections in turn.
        t_stop = time.monotonic()
        stop = target.request({"cmd": "stop"}, timeout_s=30.0)
        stop_ms = (time.monotonic() - t_stop) * 1e3
        replies: list[list[dict]] = [[] for _ in dealers]
        poller = zmq.Poller()
        for dl in dealers:
            poller.register(dl.sock, zmq.POLLIN)
        deadline = time.monotonic() + 120
        while any(len(r) < per for r in replies):
            assert time.monotonic() < deadline, [len(r) for r in replies]
            ready = dict(poller.poll(100))
            for j, dl in enumerate(dealers):
                while dl.sock in ready and len(replies[j]) < per and (r := dl.recv(0.0)) is not None:
                    replies[j].append(r)
        t_all = time.monotonic() - t0
        t_end_ns = time.time_ns()
        s1 = target.request({"cmd": "status"})
        extra = [dl.recv(0.5) for dl in dealers]
        assert extra == [None] * len(dealers), "more replies than requests"
    finally:
        for dl in dealers:
            dl.close()
    for j in range(len(dealers)):
        for raw, reply in zip(sent[j], replies[j]):  # in order, one each
            check_reply(raw, reply)
    assert stop == {"ok": True}, stop
    st_stopped = [m for m in c.slice(i0, topic="state") if m["stopped"]]
    assert st_stopped, "no state showed the stop"
    held = [m for m in st_stopped if m["t"] >= st_stopped[0]["t"] + 2 * CONTROL_S]
    assert held and all(m["command_twist"] == ZERO6 for m in held), "the stop was not obeyed"
    assert target.request({"cmd": "resume"})["ok"]
    after_ms = status_ms()
    c.state(lambda s: True, timeout_s=5, start=len(c))
    got = c.received(i0, topic="state")
    window = max(t_all, 1.0)  # the flood and what follows it, at least 1 s
    flood = [(at, m) for at, m in got if at <= t0 + window]
    rate = (len(flood) - 1) / (flood[-1][0] - flood[0][0])
    gap_t, gap_rx = state_gaps(target, i0)
    assert rate >= 20.0, f"{rate:.1f} Hz during the flood"
    assert gap_t <= MAX_STATE_GAP_S and gap_rx <= RECEIVER_GAP_S, (gap_t, gap_rx)
    assert after_ms <= max(3 * before_ms, before_ms + 5.0), (before_ms, after_ms)
    # The stop waited for its turn among the connections, not behind the 20000 queued requests.
    assert stop_ms <= 0.25 * t_all * 1e3, (stop_ms, t_all)

    # The daemon's own figures between the two status requests (its clock, its counters).
    span_s = s1["uptime_s"] - s0["uptime_s"]
    handled = s1["commands"]["requests"] - s0["commands"]["requests"]
    assert handled == len(dealers) * per + 2  # the flood, the stop, and this status
    per_tick = s0["commands"]["per_tick"]
    assert per_tick == Config().zmq.max_requests_per_tick
    ticks = s1["control"]["ticks"] - s0["control"]["ticks"]
    overruns = s1["control"]["overruns"] - s0["control"]["overruns"]
    skipped = s1["control"]["skipped"] - s0["control"]["skipped"]
    assert ticks >= 0.8 * span_s / CONTROL_S, f"{ticks} control ticks in {span_s:.2f} s"
    assert overruns <= 0.01 * ticks, f"{overruns} of {ticks} control periods over {1.5 * CONTROL_S * 1e3:.0f} ms"
    assert handled <= per_tick * (span_s / CONTROL_S + 1), f"{handled} requests in {span_s:.2f} s"
    assert s1["commands"]["deferred"] > s0["commands"]["deferred"], "the flood was never held back"

    deadline = time.monotonic() + 10 * CFG.record.flush_s
    while max(log_ns := recording(target.dir / "fuzz.mcap")[2]) <= t_end_ns:  # until the file has the flood
        assert time.monotonic() < deadline, "the recording stopped growing"
        time.sleep(0.1)
    ns = np.asarray([n for n in log_ns if t_start_ns <= n <= t_end_ns], dtype=float)
    periods = np.diff(ns) / 1e9
    p99 = float(np.percentile(periods, 99)) if len(periods) else 0.0
    assert len(periods) >= 0.8 * t_all / CONTROL_S - 2, f"{len(periods)} control ticks in {t_all:.2f} s"
    figure("flood", f"{per * len(dealers)} requests ({per * len(dealers) // 3} malformed) from {len(dealers)} "
           f"DEALERs sent in {t_sent:.2f} s, all answered in {t_all:.2f} s ({per * len(dealers) / t_all:.0f}/s, "
           f"at most {per_tick} per control period); control: {overruns} of {ticks} periods over 1.5 T "
           f"({skipped} ticks skipped), recorded periods p99 {p99 * 1e3:.1f} ms, max {periods.max() * 1e3:.1f} ms; "
           f"a stop during the flood answered in {stop_ms:.0f} ms; state stream {rate:.0f} Hz, largest gap "
           f"{gap_t * 1e3:.0f} ms (daemon clock), {gap_rx * 1e3:.0f} ms (arrival); status round trip "
           f"{before_ms:.1f} ms before, {after_ms:.1f} ms after")
