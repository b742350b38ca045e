"""The evaluation across users: summary rows per (scene, task, user, method) with bootstrap intervals and
failure counts, paired comparisons of policy with known answers, the named suites, and the command line
(``--user``, ``--suite``, bad profiles refused naming the key)."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from helpers import PAPER_REACH

from sa_daemon.config import Config, config_from_dict
from sa_daemon.planner.snapshot import Snapshot
from sa_daemon.sim.episode import question_record, run_trial
from sa_daemon.sim.evaluate import (
    TrialSpec,
    compare,
    format_summary,
    question_measures,
    rule_line,
    run_trials,
    summarise,
)
from sa_daemon.sim.suites import SUITES, suite
from sa_daemon.world.goalset import GoalSet
from sa_daemon.world.holding import OUTSIDE
from sa_daemon.world.scene import load_scene


def _trial(method: str, seed: int, time_s: float | None, success: bool = True, user: str = "calibrated",
           task: str = "cup:top", questions: int = 0, failure: str = "", kind: str = "") -> dict:
    """A hand-made trial record (the keys ``run_trial().metrics()`` has)."""
    return {"scene": "scene1", "task": task, "user": user, "method": method, "seed": seed, "success": success,
            "failure": "" if success else (failure or "timeout"),
            "failure_kind": "" if success else (kind or "timeout"), "completion_time_s": time_s if success else 100.0,
            "mode_changes": 1, "joystick_input": 10.0 * (time_s or 0.0), "opposing_pct": 0.0,
            "correct_prediction": success, "questions": questions, "final_target_p": 1.0, "plans": 1}


# -- summaries ----------------------------------------------------------------------------------------


def test_rows_are_per_user_with_intervals_and_failure_counts():
    trials = [_trial("policy", s, 10.0 + s) for s in range(6)]
    trials += [_trial("policy", s, None, success=False, user="hasty", failure="the TCP is 0.02 m outside the object", kind=OUTSIDE)
               for s in range(3)]
    trials += [_trial("policy", s, 12.0, user="hasty") for s in range(3, 6)]
    rows = summarise(trials)
    assert [(r["user"], r["method"]) for r in rows] == [("calibrated", "policy"), ("hasty", "policy")]
    cal, hasty = rows
    assert cal["n"] == 6 and cal["n_success"] == 6 and cal["failures"] == {}
    assert cal["completion_time_s"] == pytest.approx(12.5)
    lo, hi = cal["ci95"]["completion_time_s"]
    assert lo < 12.5 < hi and 10.0 <= lo and hi <= 15.0
    assert hasty["n_success"] == 3 and hasty["success_rate"] == 0.5
    assert hasty["failures"] == {"closed outside the object": 3}
    assert hasty["ci95"]["completion_time_s"] == [12.0, 12.0]  # over the successes only
    json.dumps(rows)  # JSON-ready
    assert "rule_judged" not in cal and "rule_judged" not in hasty  # no lift decided: rows as before


def test_a_physics_run_counts_where_the_holding_rule_and_the_lift_disagree():
    """Records from a physics arm carry the rule's verdict on each close (``rule_held``); the row counts
    the closes the rule holds that did not lift and the lifted ones it fails, and the run prints it."""
    cases = [(True, True), (True, True), (True, False), (False, True), (False, True), (False, False)]
    trials = [_trial("ho", s, 10.0, success=ok, kind="not lifted") | {"rule_held": rule}
              for s, (ok, rule) in enumerate(cases)]
    trials.append(_trial("ho", 6, None, success=False))  # a time-out: nothing closed, no verdict
    (row,) = summarise(trials)
    assert (row["rule_judged"], row["rule_held_not_lifted"], row["rule_failed_lifted"]) == (6, 2, 1)
    assert rule_line([row]) == ("holding rule against the lift, on the 6 closes a lift decided: the rule holds 2 "
                                "that did not lift and fails 1 that did (the kinematic arm's success is the rule)")
    assert rule_line(summarise(trials[-1:])) is None


def test_a_user_column_appears_only_for_a_population():
    one = summarise([_trial("policy", 0, 10.0)])
    assert "user" not in format_summary(one).splitlines()[0]
    two = summarise([_trial("policy", 0, 10.0), _trial("policy", 0, 11.0, user="hasty")])
    assert "user" in format_summary(two).splitlines()[0]


# -- comparisons ---------------------------------------------------------------------------------------


def test_policy_faster_on_every_seed_is_significant_after_holm():
    """Ten matched seeds, policy 5 s faster on each: exact two-sided Wilcoxon p = 2/1024; the family of
    this (scene, task, user) has 6 metrics against one baseline; Holm multiplies the smallest p by the
    number of tests with a p-value."""
    trials = [_trial("policy", s, 10.0 + 0.1 * s) for s in range(10)]
    trials += [_trial("manual", s, 15.0 + 0.2 * s) for s in range(10)]
    rows = compare(trials)
    assert {r["baseline"] for r in rows} == {"manual"} and all(r["method"] == "policy" for r in rows)
    t = next(r for r in rows if r["metric"] == "completion_time_s")
    assert t["n_pairs"] == 10 and t["median_diff"] == pytest.approx(-5.45)
    assert t["p_value"] == pytest.approx(2 / 1024)
    tested = [r for r in rows if r["p_value"] is not None]  # Holm's family: every test with a p-value
    assert t["p_holm"] == pytest.approx(len(tested) * 2 / 1024) and t["stars"] == "*"
    same = next(r for r in rows if r["metric"] == "mode_changes")
    assert same["p_value"] == 1.0 and same["stars"] == ""


def test_comparisons_pair_by_seed_and_skip_failed_trials_for_time():
    trials = [_trial("policy", s, 10.0) for s in range(4)] + [_trial("ho", s, 20.0) for s in range(4)]
    trials[1] = _trial("policy", 1, None, success=False)
    rows = compare(list(reversed(trials)))
    t = next(r for r in rows if r["metric"] == "completion_time_s")
    assert t["n_pairs"] == 3 and t["median_diff"] == -10.0
    s = next(r for r in rows if r["metric"] == "success")
    assert s["n_pairs"] == 4


def test_no_policy_no_comparisons():
    assert compare([_trial("manual", 0, 10.0), _trial("ho", 0, 9.0)]) == []


# -- real trials ---------------------------------------------------------------------------------------


def test_run_trials_carries_the_user_and_measures_speed():
    specs = [TrialSpec("scene1", "cup:top", "manual", 0, u) for u in ("calibrated", "rotate-first")]
    trials = run_trials(specs, Config(), progress=False)
    assert [t["user"] for t in trials] == ["calibrated", "rotate-first"]
    assert all("wall_s" not in t for t in trials)
    assert trials[0]["completion_time_s"] != trials[1]["completion_time_s"]
    speed = trials.speed
    assert speed is not None and speed.trials == 2 and speed.realtime_factor_min > 1.0


def test_a_bad_profile_fails_before_any_trial_runs(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text('name = "bad"\n[sim_user]\nmax_deflection = 2.0\n[sources]\nmax_deflection = "x"\n')
    with pytest.raises(Exception, match=r"sim_user\.max_deflection"):
        run_trials([TrialSpec("scene1", "cup:top", "manual", 0, str(bad))], Config(), progress=False)


# -- suites --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", sorted(SUITES))
def test_every_suite_names_scenes_tasks_and_methods_that_exist(name):
    s = suite(name)
    assert s.parts and s.seeds >= 10
    for part in s.parts:
        scene = load_scene(part.scene)
        for task in part.tasks:
            scene.goal(task)
        assert part.methods
    if s.paper_questions:
        assert set(s.paper_questions) == {t for p in s.parts for t in p.tasks}


def test_the_suites_are_the_papers_experiments():
    assert suite("table1").parts[0].tasks == ("cup:top",) and len(suite("table1").parts[0].methods) == 8
    assert sum(len(p.tasks) for p in suite("fig7").parts) == 8  # Table III
    assert suite("study-simple").paper_questions == {"bottle:side": 0.41, "spoon:top": 1.12, "cup:top": 1.24}
    assert list(suite("study-complex").paper_questions.values()) == [0.4, 0.8, 0.92]
    with pytest.raises(KeyError, match="suites: "):
        suite("fig8")


# -- command line --------------------------------------------------------------------------------------


def _cli(*args: str, cwd=None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "sa_daemon.cli", *args], check=False, capture_output=True, text=True,
                          timeout=300, cwd=cwd)


def test_eval_with_users_writes_rows_comparisons_and_intervals(tmp_path):
    out = tmp_path / "r.json"
    r = _cli("eval", "--scene", "scene1", "--task", "bowl:top", "--method", "manual", "--method", "policy",
             "--user", "calibrated", "--user", "hasty", "--seeds", "2", "--jobs", "1", "--quiet", "--json", str(out))
    assert r.returncode == 0, r.stderr
    assert "hasty" in r.stdout and "stars:" in r.stdout and "real time" in r.stdout
    data = json.loads(out.read_text())
    assert {(s["user"], s["method"]) for s in data["summary"]} == {
        (u, m) for u in ("calibrated", "hasty") for m in ("manual", "policy")}
    assert all("ci95" in s and "n_success" in s for s in data["summary"])
    assert data["comparisons"] and {c["baseline"] for c in data["comparisons"]} == {"manual"}
    assert data["meta"]["users"] == ["calibrated", "hasty"] and len(data["trials"]) == 8


def test_eval_refuses_an_unknown_profile_key_naming_it(tmp_path):
    bad = tmp_path / "u.toml"
    bad.write_text('name = "u"\n[sim_user]\nmax_deflexion = 0.5\n[sources]\nmax_deflexion = "typo"\n')
    r = _cli("eval", "--scene", "scene1", "--task", "cup:top", "--method", "manual", "--user", str(bad),
             "--seeds", "1", "--quiet")
    assert r.returncode == 2
    assert "sim_user.max_deflexion" in r.stderr and str(bad) in r.stderr


def test_eval_needs_a_scene_or_a_suite():
    r = _cli("eval", "--quiet")
    assert r.returncode == 2 and "--suite" in r.stderr


# -- when and what policy asks (issue 16's measures) ---------------------------------------------------


def _asked(t: float, over_uniform: float, rank: int, target_rank: int | None = None) -> dict:
    q = {"t": t, "target": "cup:top", "p_max": over_uniform / 4, "over_uniform": over_uniform, "object_rank": rank}
    return q if target_rank is None else {**q, "target_rank": target_rank}


def test_question_measures_count_near_uniform_questions_object_ranks_first_times_and_early_choices():
    a = {**_trial("policy", 0, 10.0), "asked": [_asked(0.8, 1.01, 3), _asked(3.0, 2.0, 1)],
         "early_plans": {"move": 7, "none": 1, "question": 1}}
    b = {**_trial("policy", 1, 12.0), "asked": [_asked(2.0, 1.5, 2)], "early_plans": {"ho": 9, "question": 1}}
    c = {**_trial("policy", 2, 11.0), "asked": [], "early_plans": {"ho": 10}}
    m = question_measures([a, b, c])
    assert m["questions_near_uniform"] == pytest.approx(1 / 3)  # one, in the first trial
    assert m["questions_top2"] == pytest.approx(2 / 3)  # ranks 3, 1, 2
    assert m["questions_top_target"] is None  # records from before session 33 lack the target's rank
    assert m["first_question_s"] == pytest.approx((0.8 + 2.0) / 2)  # over the trials that asked
    assert m["early_passive"] == pytest.approx((1 + 9 + 10) / 29)
    assert question_measures([_trial("policy", 0, 10.0)]) == dict.fromkeys(m)  # old records: nothing
    d = {**_trial("policy", 3, 9.0), "asked": [_asked(1.0, 2.0, 3, 1), _asked(2.0, 2.0, 1, 2)]}
    assert question_measures([d])["questions_top_target"] == pytest.approx(1 / 2)


def test_a_question_record_ranks_the_target_apart_from_its_object():
    # Scene 1's targets: cup:top, cup:side, chips can:side, bowl:top. The bowl is the likeliest target,
    # but the cup's two grasps together make the cup the likeliest object
    scene = load_scene("scene1")
    snap = Snapshot(GoalSet(scene.goals), np.array([0.25, 0.25, 0.2, 0.3]), scene.start, np.zeros(6))
    bowl, cup_side, chips = (question_record(snap, t, 1.0) for t in ("bowl:top", "cup:side", "chips can:side"))
    assert (bowl["target_rank"], bowl["object_rank"]) == (1, 2)
    assert (cup_side["target_rank"], cup_side["object_rank"]) == (2, 1)  # tied with cup:top: the better rank
    assert (chips["target_rank"], chips["object_rank"]) == (4, 3)
    assert bowl["p_max"] == pytest.approx(0.3) and bowl["over_uniform"] == pytest.approx(1.2)


def test_a_trial_records_each_question_with_the_belief_it_was_asked_on():
    # the first of a few trials that asks at all (the point is the record, not whether this one asks; the
    # paper's reach, the default until session 43, asks on these seeds)
    cfg = config_from_dict({"intent": PAPER_REACH})
    trials = (run_trial(load_scene("scene1"), task, "policy", seed, cfg)
              for task in ("cup:top", "cup:side") for seed in range(4))
    r = next((t for t in trials if t.questions > 0), None)
    assert r is not None, "no question in 8 cup trials"
    assert len(r.asked) == r.questions > 0
    assert [q["t"] for q in r.asked] == sorted(q["t"] for q in r.asked)
    for q in r.asked:
        assert 1.0 <= q["over_uniform"] <= 4.0 and q["p_max"] == pytest.approx(q["over_uniform"] / 4, abs=1e-5)
        assert q["object_rank"] >= 1 and q["target_rank"] >= 1
    assert 0 < sum(r.early_plans.values()) <= 20  # plans every 0.1 s, none while a question waits
    assert ("question" in r.early_plans) == (r.asked[0]["t"] < 2.0)
