"""Evaluation: deterministic trials, parallel = serial, summaries over the right trials, the JSON."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from helpers import SUMMARY_KEYS, TRIAL_KEYS

from sa_daemon.arm.kinematic import KinematicArm
from sa_daemon.config import Config, config_from_dict
from sa_daemon.sim.episode import TrialResult, run_trial
from sa_daemon.sim.evaluate import (
    TrialSpec,
    format_summary,
    run_trials,
    summarise,
    write_results,
)
from sa_daemon.world.scene import load_scene


@pytest.fixture(scope="module")
def scene1():
    return load_scene("scene1")


def _noisy() -> Config:
    return config_from_dict({"sim_user": {"noise_std": 0.1}})


def _clean() -> Config:
    return config_from_dict({"sim_user": {"noise_std": 0.0, "answer_error_rate": 0.0}})


# -- run_trial -----------------------------------------------------------------------------------------


def test_run_trial_is_deterministic_per_seed(scene1):
    cfg = _noisy()
    a = run_trial(scene1, "cup:top", "ho", 3, cfg).metrics()
    b = run_trial(scene1, "cup:top", "ho", 3, cfg).metrics()
    assert a == b


def test_run_trial_differs_across_seeds_for_a_noisy_user(scene1):
    cfg = _noisy()
    a = run_trial(scene1, "cup:top", "ho", 1, cfg)
    b = run_trial(scene1, "cup:top", "ho", 2, cfg)
    assert a.seed == 1 and b.seed == 2
    assert a.joystick_input != b.joystick_input


def test_trial_metrics_record_has_every_metric_and_the_seed(scene1):
    r = run_trial(scene1, "bowl:top", "manual", 7, _noisy())
    assert isinstance(r, TrialResult)
    m = r.metrics()
    for k in TRIAL_KEYS:
        assert k in m
    assert (m["scene"], m["task"], m["method"], m["seed"]) == ("scene1", "bowl:top", "manual", 7)
    assert "timeline" not in m
    json.dumps(m)  # JSON-ready


def test_manual_trial_never_opposes_and_never_asks(scene1):
    for seed in (0, 1):
        r = run_trial(scene1, "cup:top", "manual", seed, _noisy())
        assert r.method == "manual"
        assert r.opposing_pct == 0.0
        assert r.questions == 0


def test_manual_noise_free_user_reaches_its_goal_and_closes(scene1):
    cfg = _clean()
    arms = []

    def factory(scene, c):
        arm = KinematicArm(scene.start, c.limits)
        arms.append(arm)
        return arm

    r = run_trial(scene1, "cup:top", "manual", 0, cfg, arm_factory=factory)
    assert r.success is True
    assert 0.0 < r.completion_time_s < cfg.sim_user.timeout_s
    assert r.mode_changes >= 0 and r.joystick_input > 0.0
    (arm,) = arms
    state = arm.read()
    assert state.gripper_closed is True
    # Closed at (within the closing tolerance of) one of the task's grasp poses.
    goal = scene1.goal("cup:top")
    d = [state.pose.distance(p) for p in goal.poses]
    assert any(
        dt <= cfg.sim_user.close_translation_m and dr <= cfg.sim_user.close_rotation_rad for dt, dr in d
    )


@pytest.mark.parametrize("method", ["manual", "policy"])
def test_timeout_fails_the_trial(scene1, method):
    cfg = config_from_dict({"sim_user": {"timeout_s": 0.5}})
    r = run_trial(scene1, "cup:top", method, 0, cfg)
    assert r.success is False
    assert r.completion_time_s <= 0.5 + 1e-9
    assert r.completion_time_s > 0.0


def test_recorded_timeline_matches_the_trial(scene1):
    cfg = _noisy()
    plans = []
    r = run_trial(scene1, "cup:top", "ho", 0, cfg, record=True, on_plan=lambda _t, s, res: plans.append(res))
    tl = r.timeline
    assert tl is not None
    n = len(tl.t)
    assert n == round(r.completion_time_s * cfg.eval.control_hz)
    for series in (tl.belief, tl.action, tl.opposed, tl.user_twist, tl.robot_twist, tl.mode):
        assert len(series) == n
    assert all(len(b) == len(scene1.targets) for b in tl.belief)
    assert all(math.isclose(sum(b), 1.0, abs_tol=1e-6) for b in tl.belief)
    assert r.opposing_pct == pytest.approx(100.0 * np.mean(tl.opposed))
    assert len(plans) == r.plans > 0
    # Without ``record`` there is no timeline, and the metrics are the same.
    plain = run_trial(scene1, "cup:top", "ho", 0, cfg)
    assert plain.timeline is None
    assert plain.metrics() == r.metrics()


# -- run_trials ----------------------------------------------------------------------------------------

SPECS = [
    TrialSpec("scene1", task, method, seed)
    for task in ("cup:top", "bowl:top")
    for method in ("manual", "ho")
    for seed in (0, 1)
]


@pytest.fixture(scope="module")
def serial():
    return run_trials(SPECS, _noisy(), jobs=1, progress=False)


def test_run_trials_in_spec_order(serial):
    assert len(serial) == len(SPECS)
    for spec, t in zip(SPECS, serial):
        assert (t["scene"], t["task"], t["method"], t["seed"]) == ("scene1", spec.task, spec.method, spec.seed)


def test_run_trials_equals_run_trial(serial, scene1):
    cfg = _noisy()
    s = SPECS[5]
    assert serial[5] == run_trial(scene1, s.task, s.method, s.seed, cfg).metrics()


def test_parallel_run_trials_equals_serial(serial):
    parallel = run_trials(SPECS, _noisy(), jobs=2, progress=False)
    assert parallel == serial


# -- summarise -----------------------------------------------------------------------------------------


def _t(method, seed, success, time_s, modes, inp, opp, pred, qns, task="cup:top", scene="scene1"):
    return {
        "scene": scene, "task": task, "method": method, "seed": seed, "success": success,
        "completion_time_s": time_s, "mode_changes": modes, "joystick_input": inp, "opposing_pct": opp,
        "correct_prediction": pred, "questions": qns,
    }


HAND = [
    _t("policy", 0, True, 10.0, 2, 100.0, 10.0, True, 1),
    _t("ho", 0, False, 100.0, 60, 5000.0, 80.0, False, 0),
    _t("policy", 1, True, 20.0, 4, 300.0, 30.0, False, 3),
    _t("policy", 2, False, 100.0, 50, 9999.0, 90.0, False, 2),
    _t("ho", 1, False, 100.0, 40, 4000.0, 70.0, True, 0),
    _t("policy", 0, True, 8.0, 2, 50.0, 0.0, True, 0, task="bowl:top"),
]


def _row(rows, method, task="cup:top"):
    (r,) = [r for r in rows if r["method"] == method and r["task"] == task]
    return r


def test_summarise_groups_in_first_seen_order():
    rows = summarise(HAND)
    assert [(r["task"], r["method"]) for r in rows] == [("cup:top", "policy"), ("cup:top", "ho"), ("bowl:top", "policy")]
    assert [r["n"] for r in rows] == [3, 2, 1]


def test_summarise_success_metrics_over_successful_trials_only():
    r = _row(summarise(HAND), "policy")
    assert r["completion_time_s"] == pytest.approx(15.0)
    assert r["mode_changes"] == pytest.approx(3.0)
    assert r["joystick_input"] == pytest.approx(200.0)
    assert r["opposing_pct"] == pytest.approx(20.0)
    assert r["completion_time_s_std"] == pytest.approx(5.0)


def test_summarise_rates_over_all_trials():
    r = _row(summarise(HAND), "policy")
    assert r["success_rate"] == pytest.approx(2 / 3)
    assert r["correct_prediction_rate"] == pytest.approx(1 / 3)
    assert r["questions"] == pytest.approx(2.0)  # (1 + 3 + 2) / 3, the failed trial included


def test_summarise_without_successes_has_no_success_metrics():
    r = _row(summarise(HAND), "ho")
    assert r["success_rate"] == 0.0
    for k in ("completion_time_s", "mode_changes", "joystick_input", "opposing_pct"):
        assert r[k] is None
    assert r["correct_prediction_rate"] == pytest.approx(0.5)
    assert r["questions"] == 0.0
    # The table shows a dash for them rather than failing.
    table = format_summary(summarise(HAND))
    ho_line = table.splitlines()[3].split()
    assert ho_line[:2] == ["cup:top", "ho"]
    assert ho_line.count("-") == 4


def test_summary_rows_are_json_ready_with_every_key():
    rows = summarise(HAND)
    for r in rows:
        for k in SUMMARY_KEYS:
            assert k in r
    assert json.loads(json.dumps(rows)) == rows


def test_format_summary_has_one_line_per_row():
    rows = summarise(HAND)
    lines = format_summary(rows).splitlines()
    assert len(lines) == 2 + len(rows)
    assert "task" in lines[0] and "method" in lines[0]
    assert "policy" in lines[2] and "ho" in lines[3] and "bowl:top" in lines[4]


# -- write_results -------------------------------------------------------------------------------------


def test_write_results_json_shape(serial, tmp_path):
    path = tmp_path / "out" / "results.json"
    summary = summarise(serial)
    write_results(path, serial, summary, {"scene": "scene1", "seeds": 2})
    data = json.loads(path.read_text())
    assert data["meta"] == {"scene": "scene1", "seeds": 2}
    assert len(data["trials"]) == len(SPECS)
    for spec, t in zip(SPECS, data["trials"]):
        for k in TRIAL_KEYS:
            assert k in t, k
        assert t["seed"] == spec.seed and t["task"] == spec.task and t["method"] == spec.method
    assert len(data["summary"]) == 4  # 2 tasks x 2 methods
    for row in data["summary"]:
        for k in SUMMARY_KEYS:
            assert k in row, k
        assert row["n"] == 2
        assert 0.0 <= row["success_rate"] <= 1.0
        assert 0.0 <= row["correct_prediction_rate"] <= 1.0
        if row["method"] == "manual":
            assert row["questions"] == 0.0
    assert data["trials"] == serial
