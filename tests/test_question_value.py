"""``docs/results/question_value.py``: a question against the same trial without it.

The script's claim rests on two things: up to the question the two runs are the same trial, and the
veto hands the controller the plan's best action that is not a question. Both are checked here on a
real Table I trial (Scene 1 ``cup:top``, hasty user, seed 301: one question, at the switch to rotation).
"""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from pathlib import Path

import pytest
from helpers import PAPER_REACH, PAPER_REACH_TOML

from sa_daemon.config import config_from_dict
from sa_daemon.control.controller import Controller
from sa_daemon.model.actions import ActionKind
from sa_daemon.sim.episode import run_trial
from sa_daemon.sim.users import load_user
from sa_daemon.world.scene import load_scene

SCRIPT = Path(__file__).resolve().parents[1] / "docs" / "results" / "question_value.py"
_spec = importlib.util.spec_from_file_location("results_question_value", SCRIPT)
qv = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(qv)

SCENE = load_scene("scene1")
CASE = ("cup:top", "hasty", 301)
PAPER = {"intent": PAPER_REACH}
"""The trial was traced with the paper's reach (the default until session 43); with today's tracked reach
it does not ask."""
ACCEPT_PLAN = Controller.accept_plan
"""The controller's own method, before the script patches it for a vetoed run."""


@pytest.fixture(scope="module")
def asked():
    trial, chosen = qv.run(SCENE, *CASE, config_from_dict(PAPER))
    assert trial.success and trial.asked, "the traced trial asks (docs/results.md, session 35)"
    return trial, chosen


def test_a_question_is_recorded_with_its_margin_mode_and_speed(asked):
    trial, chosen = asked
    t_q = trial.asked[0]["t"]
    hit = [c for c in chosen if abs(c[0] - t_q) < 1e-9]
    assert len(hit) == 1
    _, margin, mode, speed = hit[0]
    assert margin > 0.0  # the plan chose the question: worth more than every other action
    assert mode in ("translation", "rotation") and len(speed) == 2


def test_the_vetoed_run_is_the_same_trial_until_the_question_and_asks_nothing_in_the_window(asked):
    trial, chosen = asked
    t_q = trial.asked[0]["t"]
    cfg = config_from_dict(PAPER)
    alt, alt_chosen = qv.run(SCENE, *CASE, cfg, veto=(t_q, t_q + cfg.planner.horizon_s))
    assert [c[0] for c in alt_chosen if c[0] < t_q] == [c[0] for c in chosen if c[0] < t_q]
    assert not [a for a in alt.asked if t_q <= a["t"] < t_q + cfg.planner.horizon_s]
    assert [a for a in alt.asked if a["t"] < t_q] == [a for a in trial.asked if a["t"] < t_q]
    assert alt.completion_time_s != trial.completion_time_s  # the question changed the trial
    assert Controller.accept_plan is ACCEPT_PLAN  # the patch is undone


def test_the_veto_hands_over_the_best_action_that_is_not_a_question(asked):
    """At the plan that asked, ``without_questions`` is the argmax of the other root values."""
    trial, _ = asked
    t_q = trial.asked[0]["t"]
    seen = {}

    def on_plan(t, snap, result):
        if abs(t - t_q) < 1e-9:
            seen["r"] = result

    run_trial(SCENE, CASE[0], "policy", CASE[2], load_user(CASE[1]).apply(config_from_dict(PAPER)), user_name=CASE[1],
              on_plan=on_plan)
    r = seen["r"]
    assert r.action.kind is ActionKind.QUESTION
    swapped = qv.without_questions(r)
    others = {a: v for a, v in r.root_values.items() if a.kind is not ActionKind.QUESTION}
    assert swapped.action.kind is not ActionKind.QUESTION
    assert swapped.value == max(others.values()) == others[swapped.action]
    assert qv.margin(r) == pytest.approx(r.root_values[r.action] - swapped.value)


def test_the_script_runs_and_summarises(tmp_path):
    out = tmp_path / "qv.json"
    cfg = tmp_path / "paper_reach.toml"
    cfg.write_text(PAPER_REACH_TOML)
    done = subprocess.run([sys.executable, str(SCRIPT), "--scene", "scene1", "--task", "cup:top", "--user", "hasty",
                           "--first-seed", "301", "--seeds", "1", "--config", str(cfg), "--json", str(out)],
                          capture_output=True, text=True, timeout=600, check=True)
    assert "with both runs successful" in done.stdout
    assert "failures without the question" in done.stdout
    assert out.exists() and '"veto_time_s"' in out.read_text()


def test_the_summary_splits_by_answer_and_by_a_predicted_standstill():
    """:func:`summary` over records as ``--json`` writes them: a yes is a question about the task's own
    target; "predicted still" reads the speed of the mode the question was asked in."""
    def row(target, mode, speed, saving):
        return {"task": "cup:top", "target": target, "mode": mode, "user_speed": speed, "margin": 20.0,
                "success": True, "veto_success": True, "time_s": 10.0, "veto_time_s": 10.0 + saving}
    rows = [row("cup:top", "rotation", [0.1, 0.0], 3.0),     # yes, still (not turning)
            row("bowl:top", "rotation", [0.0, 0.05], -1.0),  # no, turning (its linear 0 does not count)
            row("bowl:top", "translation", [0.001, 0.3], -2.0)]  # no, still (not translating)
    lines = qv.summary(rows)
    found = {ln.split(":")[0].strip(): ln for ln in lines if ln.startswith("  ")}
    assert "1 questions, saving mean   3.00 s" in found["answered yes"]
    assert "2 questions, saving mean  -1.50 s" in found["answered no"]
    assert "2 questions, saving mean   0.50 s" in found["predicted still in its mode"]
    assert "1 questions, saving mean  -1.00 s" in found["predicted moving"]
    assert lines[-1] == "failures without the question: 0 added, 0 mended"
