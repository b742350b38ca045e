"""The machine-stall probe beside ``bench soak``: real probe processes, stall matching, and a clear
reason when there is no probe."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import textwrap
import time

import pytest

from sa_daemon.bench.platform import PlatformLatency, PlatformProbe, Stall

needs_rt = pytest.mark.skipif(os.geteuid() != 0, reason="SCHED_FIFO needs root (CI runs as root)")


def _latency(*stalls: Stall) -> PlatformLatency:
    return PlatformLatency(5.0, [0, 1], [1000, 1000], [9.0, 3.0], [len(stalls), 0], list(stalls))


def test_an_overrun_is_matched_to_the_stall_that_overlaps_its_delay():
    # The tick ending at 10.0 s was at least 5 ms late: held up somewhere in [9.995, 10.0].
    stall = Stall(cpu=0, end=10.001, late_s=0.009)  # the machine ran nothing from 9.992 to 10.001
    lat = _latency(Stall(0, 3.0, 0.02), stall)
    assert lat.during_stall(10.0, 0.005) == stall
    assert lat.during_stall(3.5, 0.005) is None  # long after that stall ended
    assert lat.during_stall(2.97, 0.005) is None  # before that stall began (2.98)


def test_of_overlapping_stalls_the_longest_is_named():
    a, b = Stall(0, 5.0, 0.006), Stall(1, 5.001, 0.03)
    assert _latency(a, b).during_stall(5.0, 0.005) == b


def test_the_report_keeps_every_figure_and_stall():
    d = _latency(Stall(1, 7.25, 0.0123)).as_dict()
    assert d["late_total"] == 1 and d["max_ms"] == [9.0, 3.0] and d["stalls"] == [[1, 7.25, 12.3]]
    json.dumps(d)


def test_a_probe_that_cannot_run_says_so(monkeypatch):
    monkeypatch.setattr(sys, "executable", "/bin/false")  # every probe process exits 1 at once
    probe = PlatformProbe(0.005)
    probe.start()
    assert probe.stop() is None
    # Each CPU named with its exit status (1, or -15 when the stop came first).
    assert probe.unavailable is not None
    assert re.fullmatch(r"probe failed: cpu \d+: exit -?\d+(; cpu \d+: exit -?\d+)*", probe.unavailable)


def test_without_real_time_permission_the_probe_refuses_to_measure():
    # A normal-priority probe would measure the load, not the machine.
    code = textwrap.dedent(
        """
        import os, resource, sys
        from sa_daemon.bench.platform import main
        resource.setrlimit(resource.RLIMIT_RTPRIO, (0, 0))
        if os.geteuid() == 0:
            os.setgid(65534); os.setuid(65534)
        sys.exit(main(["--cpu", "0", "--threshold", "0.005", "--out", "/nonexistent/x.json"]))
        """
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=30, check=False)
    assert r.returncode == 1
    assert "SCHED_FIFO refused" in r.stderr and "LimitRTPRIO" in r.stderr


@needs_rt
def test_real_probes_watch_every_cpu_and_report_stalls_with_their_times():
    cpus = sorted(os.sched_getaffinity(0))
    t0 = time.monotonic()
    probe = PlatformProbe(0.0)  # threshold 0: every wake-up is "late", so every one is kept with its time
    probe.start()
    time.sleep(1.0)
    lat = probe.stop()
    t1 = time.monotonic()
    assert lat is not None, probe.unavailable
    assert lat.cpus == cpus
    assert all(200 < n < 1500 for n in lat.wakeups)  # 1 kHz for about a second each (start-up not counted)
    assert lat.late == lat.wakeups and lat.late_total == len(lat.stalls)
    assert all(t0 < s.end < t1 and s.late_s >= 0 and s.cpu in cpus for s in lat.stalls)
    assert [s.end for s in lat.stalls] == sorted(s.end for s in lat.stalls)
    assert all(m >= 0 for m in lat.max_ms)
