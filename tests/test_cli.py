"""The ``sa-daemon`` command line, run as a real subprocess."""

from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from helpers import COMMIT_MODEL_TOML, SUMMARY_KEYS, TRIAL_KEYS

TIMEOUT_S = 180
BENCH_KEYS = ("solve_ms_p50", "solve_ms_p99", "agreement_at_budget", "peer_agreement_at_budget", "belief_update_us_p50")


def _cmd(*args: str) -> list[str]:
    return [sys.executable, "-m", "sa_daemon.cli", *args]


def _run(args: list[str], cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run(args, cwd=cwd, capture_output=True, text=True, timeout=TIMEOUT_S, env=os.environ.copy(),
                          check=False)


# -- eval ----------------------------------------------------------------------------------------------


def test_eval_prints_a_table_and_writes_json(tmp_path):
    out = tmp_path / "res" / "eval.json"
    r = _run(
        _cmd("eval", "--scene", "scene1", "--task", "cup:top", "--method", "manual", "--method", "ho",
             "--seeds", "1", "--jobs", "1", "--quiet", "--json", str(out)),
        tmp_path,
    )
    assert r.returncode == 0, r.stderr
    lines = r.stdout.splitlines()
    header = lines[0].split()
    for col in ("task", "method", "n", "success"):
        assert col in header
    rows = [ln.split() for ln in lines if ln.startswith("cup:top")]
    assert [row[1] for row in rows] == ["manual", "ho"]
    assert all(row[2] == "1" for row in rows)  # n = 1 seed
    assert f"wrote {out}" in r.stdout
    assert "trials" not in r.stderr  # --quiet: no progress bar

    data = json.loads(out.read_text())
    assert len(data["trials"]) == 2
    for t, method in zip(data["trials"], ["manual", "ho"]):
        for k in TRIAL_KEYS:
            assert k in t, k
        assert (t["scene"], t["task"], t["method"], t["seed"]) == ("scene1", "cup:top", method, 0)
    assert [s["method"] for s in data["summary"]] == ["manual", "ho"]
    for s in data["summary"]:
        for k in SUMMARY_KEYS:
            assert k in s, k
        assert s["scene"] == "scene1" and s["task"] == "cup:top" and s["n"] == 1
    manual = data["summary"][0]
    assert manual["questions"] == 0.0
    assert data["trials"][0]["opposing_pct"] == 0.0
    assert data["meta"]["scene"] == "scene1" and data["meta"]["seeds"] == 1


def test_eval_more_seeds_merged_with_an_earlier_run_equal_one_run_with_all_seeds(tmp_path):
    """``--first-seed`` and ``--merge``: seeds 0-1, then 2 merged, give the trials, summary and paired
    tests of one run of seeds 0-2 (results depend only on the seeds); a trial measured twice, another
    config or another arm is refused before anything runs, and no file is written."""
    base = ("eval", "--scene", "scene1", "--task", "chips can:side", "--method", "ho", "--method", "policy",
            "--jobs", "1", "--quiet")
    one, first, both = tmp_path / "one.json", tmp_path / "first.json", tmp_path / "both.json"
    assert _run(_cmd(*base, "--seeds", "3", "--json", str(one)), tmp_path).returncode == 0
    assert _run(_cmd(*base, "--seeds", "2", "--json", str(first)), tmp_path).returncode == 0
    r = _run(_cmd(*base, "--seeds", "1", "--first-seed", "2", "--merge", str(first), "--json", str(both)), tmp_path)
    assert r.returncode == 0, r.stderr
    a, b = json.loads(one.read_text()), json.loads(both.read_text())
    strip = lambda ts: sorted(({k: v for k, v in t.items() if k != "wall_s"} for t in ts),
                              key=lambda t: (t["method"], t["seed"]))
    assert strip(a["trials"]) == strip(b["trials"]) and len(a["trials"]) == 6
    assert a["summary"] == b["summary"] and a["comparisons"] and a["comparisons"] == b["comparisons"]
    assert b["meta"]["seeds"] == 3 and b["meta"]["merged"] == [str(first)]
    refused = tmp_path / "refused.json"
    overlap = _run(_cmd(*base, "--seeds", "2", "--first-seed", "1", "--merge", str(first), "--json", str(refused)),
                   tmp_path)
    assert overlap.returncode == 2 and "2 trials measured twice" in overlap.stderr and "'ho', 1)" in overlap.stderr
    cfg = tmp_path / "gradient.toml"
    cfg.write_text('[ho]\ngenerator = "gradient"\n')
    other = _run(_cmd("--config", str(cfg), *base, "--seeds", "2", "--first-seed", "2", "--merge", str(first),
                      "--json", str(refused)), tmp_path)
    assert other.returncode == 2 and "first difference: ho.generator" in other.stderr
    arm = _run(_cmd(*base, "--seeds", "1", "--first-seed", "2", "--arm", "mujoco", "--merge", str(first),
                    "--json", str(refused)), tmp_path)
    assert arm.returncode == 2 and "kinematic arm" in arm.stderr
    assert not refused.exists()


def test_eval_bad_grasp_type_exits_2_naming_it(tmp_path):
    out = tmp_path / "x.json"
    r = _run(_cmd("eval", "--scene", "scene1", "--task", "cup:tap", "--seeds", "1", "--jobs", "1", "--quiet",
                  "--json", str(out)), tmp_path)
    assert r.returncode == 2
    assert "tap" in r.stderr and "grasp type" in r.stderr
    assert "Traceback" not in r.stderr
    assert not out.exists()


def test_eval_unknown_target_exits_2_listing_the_available_ones(tmp_path):
    r = _run(_cmd("eval", "--scene", "scene1", "--task", "teapot:top", "--seeds", "1", "--jobs", "1", "--quiet"),
             tmp_path)
    assert r.returncode == 2
    assert "teapot:top" in r.stderr and "cup:top" in r.stderr
    assert "Traceback" not in r.stderr


def test_eval_unknown_scene_exits_2_with_a_clear_message(tmp_path):
    r = _run(_cmd("eval", "--scene", "no-such-scene", "--seeds", "1", "--jobs", "1", "--quiet"), tmp_path)
    assert r.returncode == 2
    assert "no-such-scene" in r.stderr
    assert "scene" in r.stderr.replace("no-such-scene", "")
    assert "scene1" in r.stderr  # lists the built-in ones
    assert "Traceback" not in r.stderr
    assert r.stdout == ""


def test_bad_config_key_exits_2_naming_the_key(tmp_path):
    cfg = tmp_path / "bad.toml"
    cfg.write_text("[sim_user]\nnoise_std = 0.0\nreaction_dealy_s = 0.1\n")
    r = _run(_cmd("--config", str(cfg), "eval", "--scene", "scene1", "--task", "cup:top", "--seeds", "1",
                  "--jobs", "1", "--quiet"), tmp_path)
    assert r.returncode == 2
    assert "sim_user.reaction_dealy_s" in r.stderr
    assert "unknown key" in r.stderr
    assert "Traceback" not in r.stderr


def test_bad_config_value_exits_2_naming_the_key(tmp_path):
    cfg = tmp_path / "bad.toml"
    cfg.write_text("[reward]\nbeta = -1.0\n")
    r = _run(_cmd("--config", str(cfg), "eval", "--scene", "scene1", "--seeds", "1", "--jobs", "1", "--quiet"),
             tmp_path)
    assert r.returncode == 2
    assert "reward.beta" in r.stderr
    assert "Traceback" not in r.stderr


def test_eval_with_a_valid_config_file_uses_it(tmp_path):
    cfg = tmp_path / "short.toml"
    cfg.write_text("[sim_user]\ntimeout_s = 0.5\n")
    out = tmp_path / "short.json"
    r = _run(_cmd("--config", str(cfg), "eval", "--scene", "scene1", "--task", "cup:top", "--method", "manual",
                  "--seeds", "1", "--jobs", "1", "--quiet", "--json", str(out)), tmp_path)
    assert r.returncode == 0, r.stderr
    data = json.loads(out.read_text())
    assert data["meta"]["config"]["sim_user"]["timeout_s"] == 0.5
    (t,) = data["trials"]
    assert t["success"] is False and t["completion_time_s"] <= 0.5 + 1e-9


# -- bench planner -------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def bench_runs(tmp_path_factory):
    """The planner benchmarks, run at the same time (each takes seconds)."""
    d = tmp_path_factory.mktemp("bench")
    commit = d / "commit.toml"  # the pomdp_py peer plans the commit model
    commit.write_text(COMMIT_MODEL_TOML)
    jobs = {
        "no_peer": (_cmd("bench", "planner", "--scene", "scene1", "--samples", "4", "--no-peer",
                         "--json", str(d / "no_peer.json")), d / "no_peer.json"),
        "peer": (_cmd("bench", "planner", "--scene", "scene1", "--samples", "3", "--config", str(commit),
                      "--json", str(d / "peer.json")), d / "peer.json"),
        "watch_peer": (_cmd("bench", "planner", "--scene", "scene1", "--samples", "3",
                            "--json", str(d / "watch_peer.json")), d / "watch_peer.json"),
    }
    procs = {
        k: subprocess.Popen(cmd, cwd=d, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        for k, (cmd, _) in jobs.items()
    }
    out = {}
    try:
        for k, p in procs.items():
            stdout, stderr = p.communicate(timeout=TIMEOUT_S)
            out[k] = (p.returncode, stdout, stderr, jobs[k][1])
    finally:
        for p in procs.values():
            if p.poll() is None:
                p.kill()
                p.wait()
    return out


def _check_bench_json(path: Path) -> dict:
    data = json.loads(path.read_text())
    for k in BENCH_KEYS:
        assert k in data, k
    for k, v in data.items():
        if isinstance(v, (int, float)) and not isinstance(v, bool):
            assert math.isfinite(v), k
    assert data["solve_ms_p50"] > 0 and data["solve_ms_p99"] >= data["solve_ms_p50"]
    assert 0.0 <= data["agreement_at_budget"] <= 1.0
    assert data["belief_update_us_p50"] > 0
    assert data["scene"] == "scene1"
    return data


def test_bench_planner_without_peer(bench_runs):
    rc, stdout, stderr, path = bench_runs["no_peer"]
    assert rc == 0, stderr
    assert "planner benchmark: scene1" in stdout
    data = _check_bench_json(path)
    assert data["samples"] == 4 and data["model"] == "watch"  # the default planner
    assert data["peer_agreement_at_budget"] is None


def test_bench_planner_with_peer(bench_runs):
    rc, stdout, stderr, path = bench_runs["peer"]
    assert rc == 0, stderr
    data = _check_bench_json(path)
    assert data["samples"] == 3 and data["model"] == "commit"
    peer = data["peer_agreement_at_budget"]
    assert isinstance(peer, (int, float)) and 0.0 <= peer <= 1.0
    assert "POUCT" in stdout


def test_bench_planner_with_peer_on_the_watch_model(bench_runs):
    rc, stdout, stderr, path = bench_runs["watch_peer"]
    assert rc == 0, stderr
    data = _check_bench_json(path)
    assert data["samples"] == 3 and data["model"] == "watch" and data["peer"] == "pomdp_py POUCT"
    peer = data["peer_agreement_at_budget"]
    assert isinstance(peer, (int, float)) and 0.0 <= peer <= 1.0
    assert "peer (pomdp_py POUCT) agreement" in stdout


def test_bench_planner_unknown_scene_exits_2(tmp_path):
    r = _run(_cmd("bench", "planner", "--scene", "nowhere", "--samples", "1", "--no-peer"), tmp_path)
    assert r.returncode == 2
    assert "nowhere" in r.stderr and "Traceback" not in r.stderr


# -- scenes and usage ----------------------------------------------------------------------------------


def test_scenes_lists_the_builtin_scenes(tmp_path):
    exe = shutil.which("sa-daemon")
    r = _run([exe, "scenes"] if exe else _cmd("scenes"), tmp_path)
    assert r.returncode == 0, r.stderr
    names = {ln.split(":")[0] for ln in r.stdout.splitlines() if ln and not ln.startswith(" ")}
    assert {"scene1", "scene2", "study-simple"} <= names
    assert "cup:top" in r.stdout


def test_unknown_method_is_a_usage_error(tmp_path):
    r = _run(_cmd("eval", "--scene", "scene1", "--method", "telepathy", "--seeds", "1"), tmp_path)
    assert r.returncode == 2
    assert "telepathy" in r.stderr


def test_no_command_is_a_usage_error(tmp_path):
    r = _run(_cmd(), tmp_path)
    assert r.returncode == 2
    assert "usage" in r.stderr.lower()
