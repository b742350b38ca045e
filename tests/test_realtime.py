"""runtime.realtime_priority: the event-loop thread under SCHED_FIFO, nothing created after it.

Real system calls, in child processes (the test process keeps its own policy). Linux only; setting
SCHED_FIFO needs root or RLIMIT_RTPRIO, which CI has (it runs as root): the tests skip elsewhere.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from helpers import DaemonProc

from sa_daemon.runtime.realtime import set_switch_interval

CHILD = textwrap.dedent(
    """
    import json, os, subprocess, sys, threading
    from sa_daemon.runtime.realtime import make_realtime

    if sys.argv[1] == "drop":  # an unprivileged user with no RLIMIT_RTPRIO: refused
        import resource
        resource.setrlimit(resource.RLIMIT_RTPRIO, (0, 0))
        os.setgid(65534); os.setuid(65534)
    err = make_realtime(int(sys.argv[2]))
    seen = {}
    t = threading.Thread(target=lambda: seen.setdefault("thread", os.sched_getscheduler(0)))
    t.start(); t.join()
    child = -1
    if sys.argv[1] == "keep":  # (user nobody may not run this interpreter)
        out = subprocess.run([sys.executable, "-c", "import os; print(os.sched_getscheduler(0))"],
                             capture_output=True, text=True, check=True)
        child = int(out.stdout)
    print(json.dumps({"err": err, "main": os.sched_getscheduler(0) & ~getattr(os, "SCHED_RESET_ON_FORK", 0),
                      "priority": os.sched_getparam(0).sched_priority, "thread": seen["thread"],
                      "child": child}))
    """
)

needs_rt = pytest.mark.skipif(
    not sys.platform.startswith("linux") or os.geteuid() != 0, reason="SCHED_FIFO needs root (CI runs as root)"
)


def _child(mode: str, priority: int) -> dict:
    out = subprocess.run([sys.executable, "-c", CHILD, mode, str(priority)], capture_output=True, text=True,
                         check=True, timeout=30)
    return json.loads(out.stdout)


@needs_rt
def test_only_the_calling_thread_runs_real_time():
    r = _child("keep", 10)
    assert r["err"] is None
    assert (r["main"], r["priority"]) == (os.SCHED_FIFO, 10)
    # Threads and processes created afterwards start under the normal policy (SCHED_RESET_ON_FORK):
    # a planner worker restarted later can never hog a core at real-time priority.
    assert r["thread"] == os.SCHED_OTHER and r["child"] == os.SCHED_OTHER


def test_priority_zero_changes_nothing():
    r = _child("keep", 0)
    assert r["err"] is None and r["main"] == os.SCHED_OTHER and r["priority"] == 0


@needs_rt
def test_without_permission_it_says_why_and_changes_nothing():
    r = _child("drop", 10)
    assert "runtime.realtime_priority 10" in r["err"] and "SCHED_FIFO refused" in r["err"]
    assert r["main"] == os.SCHED_OTHER


def _policy(pid: int, tid: int) -> int:
    """Scheduling policy of one thread, from /proc (field 41 of stat)."""
    stat = Path(f"/proc/{pid}/task/{tid}/stat").read_text()
    return int(stat.rsplit(")", 1)[1].split()[38])


@needs_rt
def test_the_daemon_runs_its_event_loop_real_time_and_the_planner_does_not(tmp_path):
    d = DaemonProc(tmp_path, "--no-speech", "--duration", "60", config="[runtime]\nrealtime_priority = 12\n")
    try:
        d.wait_ready()
        st = d.request({"cmd": "status"})
        assert st["control"]["realtime_priority"] == 12
        pid = d.proc.pid
        assert _policy(pid, pid) == os.SCHED_FIFO  # the main thread: the event loop
        others = [int(t) for t in os.listdir(f"/proc/{pid}/task") if int(t) != pid]
        assert others and all(_policy(pid, t) == os.SCHED_OTHER for t in others)  # ZeroMQ, recorder, ...
        worker = st["planner"]["pid"]
        assert worker and _policy(worker, worker) == os.SCHED_OTHER
    finally:
        d.close()


def test_the_daemon_bounds_the_interpreter_lock_hand_over_while_it_runs(tmp_path):
    # Python's default (5 ms) would let a busy helper thread hold the lock for half a control period.
    d = DaemonProc(tmp_path, "--no-speech", "--duration", "60", config="[runtime]\ngil_switch_interval_s = 0.0007\n")
    try:
        d.wait_ready()
        assert d.request({"cmd": "status"})["control"]["switch_interval_s"] == pytest.approx(0.0007)
    finally:
        d.close()


def test_set_switch_interval_returns_the_previous_one_to_restore():
    before = sys.getswitchinterval()
    try:
        assert set_switch_interval(0.0005) == before
        assert sys.getswitchinterval() == pytest.approx(0.0005)
    finally:
        sys.setswitchinterval(before)


def test_a_busy_helper_thread_delays_the_loop_by_at_most_about_the_switch_interval():
    """The mechanism behind ``runtime.gil_switch_interval_s``: a thread waking from a sleep while a
    pure-Python thread computes waits for the lock for about one switch interval."""
    code = textwrap.dedent(
        """
        import sys, threading, time
        sys.setswitchinterval(float(sys.argv[1]))
        stop = False
        def busy():
            while not stop:
                sum(range(1000))
        threading.Thread(target=busy, daemon=True).start()
        waits = []
        for _ in range(100):
            t = time.perf_counter(); time.sleep(0.002); waits.append(time.perf_counter() - t - 0.002)
        stop = True
        print(sorted(waits)[50])
        """
    )

    def median_wait(interval_s: float) -> float:  # the median: robust to a rare stall of the machine
        out = subprocess.run([sys.executable, "-c", code, str(interval_s)], capture_output=True, text=True,
                             check=True, timeout=60)
        return float(out.stdout)

    assert median_wait(0.005) > 0.004  # a wake waits for the busy thread's full 5 ms
    assert median_wait(0.0005) < 0.002
