"""``sa-daemon bench soak`` as a real subprocess: a short soak's JSON and table, its verdicts matching
its figures and its exit code. The timing criteria themselves are the benchmark's, not the test's."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest
from helpers import free_port

CLI = [sys.executable, "-m", "sa_daemon.cli"]
SOAK_S = 30.0
SAMPLE_S = 5.0
#: Tasks end within this (success or timeout), so a short soak finishes at least one.
CONFIG = "[sim_user]\ntimeout_s = 15.0\n"


@pytest.fixture(scope="module")
def soak(tmp_path_factory) -> tuple[subprocess.CompletedProcess, dict]:
    d = tmp_path_factory.mktemp("soak")
    (d / "config.toml").write_text(CONFIG)
    out = d / "figures" / "soak.json"
    r = subprocess.run(
        [*CLI, "--config", str(d / "config.toml"), "bench", "soak", "--arm", "kinematic", "--duration", str(SOAK_S),
         "--sample-every", str(SAMPLE_S), "--json", str(out), "--quiet", "--no-speech",
         "--pub", f"tcp://127.0.0.1:{free_port()}", "--cmd", f"tcp://127.0.0.1:{free_port()}"],
        check=False, cwd=d, capture_output=True, text=True, timeout=SOAK_S + 120,
    )
    assert out.exists(), f"exit {r.returncode}: {r.stderr[-2000:]}"
    return r, json.loads(out.read_text())


def test_soak_exit_code_and_verdict_follow_the_criteria(soak):
    r, f = soak
    assert r.returncode in (0, 1), r.stderr[-2000:]
    names = [c["name"] for c in f["criteria"]]
    assert names == ["daemon RSS growth %", "worker RSS growth %", "control overruns"]
    for c in f["criteria"]:
        assert c["pass"] == (c["value"] is not None and c["value"] <= c["limit"]), c
    assert [c["limit"] for c in f["criteria"]] == [5.0, 5.0, 0]  # the thresholds by default
    assert f["pass"] == all(c["pass"] for c in f["criteria"])
    assert (r.returncode == 0) == f["pass"]
    assert f"soak {'PASS' if f['pass'] else 'FAIL'}" in r.stdout
    assert r.stdout.count("PASS  ") + r.stdout.count("FAIL  ") == 3


def test_soak_rss_series_and_growth_are_consistent(soak):
    _, f = soak
    series = f["rss_series"]
    ts = [s["t_s"] for s in series]
    assert ts == sorted(ts) and len(series) >= SOAK_S / SAMPLE_S
    assert all(s["daemon_mb"] > 0 for s in series)
    assert f["warmup_s"] == pytest.approx(0.1 * SOAK_S)
    after = [s for s in series if s["t_s"] >= f["warmup_s"]]
    assert all(s["worker_mb"] > 0 and s["worker_pid"] for s in after)
    d, w = f["daemon_rss"], f["worker_rss"]
    assert d["samples"] == len(after) >= 3 and w["samples"] == len(after)
    assert d["start_mb"] == after[0]["daemon_mb"] and d["end_mb"] == after[-1]["daemon_mb"]
    assert w["start_mb"] == after[0]["worker_mb"] and w["end_mb"] == after[-1]["worker_mb"]
    assert d["growth_pct"] == pytest.approx(100 * (d["end_mb"] - d["start_mb"]) / d["start_mb"])
    assert isinstance(d["slope_mb_per_min"], float) and isinstance(w["slope_mb_per_min"], float)


def test_soak_reports_the_run(soak):
    _, f = soak
    assert f["soak_s"] == SOAK_S and f["duration_s"] >= SOAK_S
    assert f["arm"] == "kinematic" and f["method"] == "policy"
    assert f["planner_restarts"] == 0
    assert f["tasks_done"] >= 1 and 0 <= f["tasks_succeeded"] <= f["tasks_done"]
    assert isinstance(f["questions_asked"], int) and f["questions_asked"] >= 0
    # The loops ran: at least half the nominal ticks and state messages (not a timing criterion).
    assert f["control_ticks"] >= 0.5 * 100 * SOAK_S
    assert f["state_messages_published"] >= 0.5 * 30 * SOAK_S
    assert f["overruns"] >= 0 and f["overrun_pct"] == pytest.approx(100 * f["overruns"] / f["control_ticks"])
    at = f["overrun_at_s"]
    assert len(at) == min(f["overruns"], 100) == len(f["overrun_at_monotonic_s"]) and at == sorted(at)
    assert all(0 < t <= f["duration_s"] for t in at)
    assert 0 <= f["period_err_ms_p99"] <= f["period_err_ms_max"]
    assert f["pub_dropped"] == 0 and f["subscribers"] == {}
    assert f["loop"]["tasks_done"] == f["tasks_done"]


def test_soak_reports_the_machines_own_stalls_or_why_not(soak):
    r, f = soak
    p = f["platform"]
    assert "machine stalls > T/2 (probe, all CPUs)" in r.stdout
    if os.geteuid() != 0:  # the probe needs a real-time priority
        assert "SCHED_FIFO refused" in p["unavailable"]
        return
    assert p["threshold_ms"] == 5.0  # half the 10 ms control period
    assert p["cpus"] == sorted(os.sched_getaffinity(0))
    assert all(n >= 0.5 * 1000 * SOAK_S for n in p["wakeups"])  # 1 kHz per CPU through the soak
    assert p["late_total"] == sum(p["late"]) == len(p["stalls"])
    # Every overrun is looked up among the stalls; a match overlaps it.
    assert len(p["overrun_stalls"]) == len(f["overrun_at_monotonic_s"])
    assert p["overruns_during_stall"] == sum(m is not None for m in p["overrun_stalls"])
    for t, m in zip(f["overrun_at_monotonic_s"], p["overrun_stalls"]):
        if m is not None:
            _, end, late_ms = m
            assert end - late_ms / 1e3 <= t + 0.002 and end >= t - 0.005 - 0.002
    assert f"{p['overruns_during_stall']} during a machine stall" in r.stdout


def test_soak_too_short_for_its_sampling_exits_2(tmp_path):
    r = subprocess.run([*CLI, "bench", "soak", "--duration", "10", "--sample-every", "5", "--no-speech"],
                       check=False, cwd=tmp_path, capture_output=True, text=True, timeout=60)
    assert r.returncode == 2
    assert "--sample-every 5.0 s leaves fewer than 3 samples" in r.stderr
