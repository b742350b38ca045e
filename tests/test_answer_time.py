"""A question costs what it costs this person: answer times counted, and the planner charged the learned
time (``asking.learn_answer_time``, ``control/answer_time.py``)."""

from __future__ import annotations

import math
import statistics

import numpy as np
import pytest
from test_when_to_ask import GOALS, NEAR_CUP, beliefs

from sa_daemon.config import Config, config_from_dict
from sa_daemon.control.answer_time import AnswerTime
from sa_daemon.control.controller import Controller
from sa_daemon.model.actions import ActionKind, Mode
from sa_daemon.model.model import SharedAutonomyModel
from sa_daemon.planner.snapshot import Snapshot
from sa_daemon.planner.solver import Solver
from sa_daemon.world.scene import load_scene

LEARN = Config()  # learning is the default since session 39
FIXED = config_from_dict({"asking": {"learn_answer_time": False}})


@pytest.mark.parametrize(("answers", "charged"), [
    ((), 2.0),  # nothing heard yet: the prior
    ((4.0,), 3.0),  # median(2, 4) = 3: one slow answer moves the charge halfway
    ((3.2,), 3.0),  # median(2, 3.2) = 2.6, up to whole 1 s steps
    ((1.5,), 2.0),  # the simulated users' 1.5 s: median 1.75, up to 2, the prior, unchanged
    ((0.8,), 2.0),  # median 1.4, up to 2
    ((0.8, 0.8), 1.0),  # median(2, 0.8, 0.8) = 0.8, at least one step
    ((4.0, 0.8), 2.0),  # median(2, 4, 0.8) = 2
    ((1.0, 1.0, 1.0, 30.0), 1.0),  # a distracted answer among quick ones does not move it
    ((4.0, 3.9, 4.0, 3.8), 4.0),  # a slow answerer, learned: 3.9 up to 4
])
def test_the_charge_is_the_median_of_the_prior_and_the_answers_in_whole_rollout_steps(answers, charged):
    times = AnswerTime(LEARN)
    for a in answers:
        times.record(a)
    assert times.charged_s == pytest.approx(charged)
    assert times.count == len(answers)


def test_without_learning_the_charge_stays_the_configured_one_and_the_suggestion_waits_for_three_answers():
    times = AnswerTime(FIXED)
    for a in (4.0, 3.6):
        times.record(a)
    assert times.charged_s == 2.0 and times.suggested_s is None
    times.record(3.1)
    assert times.charged_s == 2.0 and times.median_s == pytest.approx(3.6) and times.suggested_s == 4.0
    assert times.summary() == {"count": 3, "median_s": 3.6, "charged_s": 2.0, "learning": False, "suggested_s": 4.0}
    assert AnswerTime(LEARN).summary()["learning"] is True


def test_an_impossible_answer_time_is_not_counted_and_a_profile_switch_counts_afresh():
    times = AnswerTime(LEARN)
    for a in (math.nan, math.inf, -1.0):
        times.record(a)
    assert times.count == 0 and times.charged_s == 2.0
    times.record(4.0)
    assert times.charged_s == 3.0
    times.reconfigure(config_from_dict({"reward": {"question_time_s": 1.0}}))
    assert times.count == 0 and times.charged_s == 1.0


def test_a_prior_of_zero_the_commit_model_s_paper_reading_is_not_learned_away():
    times = AnswerTime(config_from_dict({"planner": {"model": "commit"}, "reward": {"question_time_s": 0.0}}))
    times.record(4.0)
    assert times.charged_s == 0.0 and times.median_s == 4.0


def _answer_after(ctl: Controller, after_s: float, t: float) -> float:
    ctl.ask("cup:top", t)
    ctl.on_answer("no", t + after_s)
    return t + after_s


def test_the_controller_charges_the_planner_what_this_person_takes_across_tasks():
    """The snapshot carries the learned time; a new task keeps it (the same person), a profile switch
    does not (another person), and without learning the snapshot carries the configured time."""
    goals = load_scene("scene1").goals
    pose = load_scene("scene1").start
    ctl = Controller(LEARN, goals, "policy", 0.01)
    ctl.resume()  # the stop self-test is not required here; snapshots need no pending test
    assert ctl.snapshot(pose, None).question_time_s == 2.0
    _answer_after(ctl, 4.0, 10.0)
    assert ctl.snapshot(pose, None).question_time_s == 3.0
    ctl.reset()
    assert ctl.snapshot(pose, None).question_time_s == 3.0 and ctl.answer_time.count == 1
    ctl.reconfigure(LEARN)
    assert ctl.snapshot(pose, None).question_time_s == 2.0 and ctl.answer_time.count == 0
    fixed = Controller(FIXED, goals, "policy", 0.01)
    _answer_after(fixed, 4.0, 10.0)
    assert fixed.snapshot(pose, None).question_time_s == 2.0 and fixed.answer_time.median_s == 4.0


def test_the_planner_charges_the_snapshot_s_question_time_as_the_configured_one():
    """Fig. 5's moment (near the cup, top and side even, the user turning): planned with the snapshot's
    ``question_time_s = 4`` every action is worth what it is worth with ``reward.question_time_s = 4``,
    and a question is worth less than with 2 s."""
    snap = Snapshot(GOALS, beliefs({"cup:top": 0.49, "cup:side": 0.49}), NEAR_CUP, np.zeros(6), mode=Mode.ROTATION,
                    user_speed=(0.024, 0.0), budget_s=None)  # to the proven optimum: no clock in the values
    slow = Snapshot(snap.goals, snap.probs, snap.pose, snap.user_twist, mode=snap.mode, user_speed=snap.user_speed,
                    budget_s=None, question_time_s=4.0)
    by_snapshot = Solver(SharedAutonomyModel(Config())).plan(slow).root_values
    by_config = Solver(SharedAutonomyModel(config_from_dict({"reward": {"question_time_s": 4.0}}))).plan(snap).root_values
    default = Solver(SharedAutonomyModel(Config())).plan(snap).root_values
    assert by_snapshot.keys() == by_config.keys()
    assert all(by_snapshot[a] == pytest.approx(by_config[a], abs=1e-9) for a in by_config)
    ask = next(a for a in default if a.kind is ActionKind.QUESTION and a.target == "cup:top")
    assert by_snapshot[ask] < default[ask] - 1.0


def test_a_snapshot_carries_its_question_time_through_its_plain_form_and_refuses_a_bad_one():
    snap = Snapshot(GOALS, beliefs({}), NEAR_CUP, np.zeros(6), question_time_s=3.0)
    assert Snapshot.from_dict(snap.to_dict()).question_time_s == 3.0
    assert Snapshot.from_dict({**snap.to_dict(), "question_time_s": None}).question_time_s is None
    for bad in (math.nan, -1.0, math.inf):
        with pytest.raises(ValueError, match="question_time_s"):
            Snapshot(GOALS, beliefs({}), NEAR_CUP, np.zeros(6), question_time_s=bad)


def test_an_evaluation_trial_records_each_question_s_charge_and_answer_and_the_charge_follows_the_answers():
    """The hesitant user (answers after 0.8-4 s), in trials where it is asked more than once: the first
    question is charged the prior, every later one what its earlier answers give, and after a slow first
    answer a later question is charged more (Scene 2's spoon, seed 1700: 2 s, then 3 s; trials found on the
    session 43 default's seeds 1700+)."""
    from sa_daemon.config import load_config
    from sa_daemon.control.answer_time import whole_steps
    from sa_daemon.sim.episode import run_trial
    from sa_daemon.sim.users import load_user

    cfg = load_user("hesitant").apply(load_config(None))
    cases = (("scene2", "spoon:top_vertical", 1700), ("scene2", "spoon:top_vertical", 1707),
             ("study-simple", "cup:top", 1712))
    asked = [run_trial(load_scene(scene), task, "policy", seed, cfg, user_name="hesitant").asked
             for scene, task, seed in cases]
    assert sum(len(a) >= 2 for a in asked) >= 2, "the hesitant user was asked twice in fewer than two trials"
    for questions in asked:
        for k, q in enumerate(questions):
            assert q["answer"] in ("yes", "no") and 0.8 - 1e-6 <= q["answered_after_s"] <= 4.0 + 1.0 / cfg.eval.control_hz
            earlier = [2.0, *(a["answered_after_s"] for a in questions[:k])]
            assert q["charged_s"] == pytest.approx(whole_steps(statistics.median(earlier), 1.0))
    assert any(q["charged_s"] > 2.0 for questions in asked for q in questions)
