"""Answers that stop being final (``asking.withdraw_yes_s`` and ``asking.withdraw_no_s``, 2 s by default).

A yes is final in the paper's reading (docs/model.md, "A yes is final"), and so is a no (ours); a
misheard or mistaken yes then holds the arm on the wrong object, a mistaken no about the person's goal
keeps the arm from it, and the person can only fight it. With a switch on, the answer is withdrawn once
the person has opposed the assistance in ``blend.opposition_share`` of the control periods with input
over the window: the probabilities stay, and joystick input may move the answered targets again. A yes
is withdrawn first (the no answers stay); the no answers only while no yes holds.
"""

from __future__ import annotations

import numpy as np
import pytest
from helpers import PAPER_REACH_TOML, DaemonProc

from sa_daemon.arm.base import ArmState
from sa_daemon.config import ConfigError, config_from_dict
from sa_daemon.control.controller import Controller
from sa_daemon.model.actions import HO_ACTION
from sa_daemon.world.scene import load_scene

SCENE = load_scene("scene1")
DT = 0.01
START = SCENE.start


def answered(withdraw_yes_s: float) -> Controller:
    """HO assisting after "is it the bowl?" - "yes" and "is it the chips can?" - "no"."""
    ctl = Controller(config_from_dict({"asking": {"withdraw_yes_s": withdraw_yes_s}}), SCENE.goals, "ho", DT)
    for target, answer in (("chips can:side", False), ("bowl:top", True)):
        ctl.ask(target, 0.0)
        ctl.on_answer(answer, 0.0)
    ctl.adopt_fixed()
    return ctl


def against_ho(ctl: Controller) -> np.ndarray:
    """Joystick axes pushing against HO's pull on every axis it moves (as a person heading elsewhere)."""
    b = ctl.belief
    ho = ctl.model.robot_twist(HO_ACTION, b.goals, b.probs, START, np.zeros(6))
    return -np.sign(ho[:3]) * (np.abs(ho[:3]) > 0.01)


def drive(ctl: Controller, axes, seconds: float, t0: float, update_belief: bool = False) -> float:
    st, t = ArmState(START, False, None, None), t0
    while t < t0 + seconds:
        ctl.on_input(axes, t)
        if update_belief:
            ctl.update_belief(START, t)
        ctl.adopt_fixed()  # the HO method's plan, as the evaluation's step loop keeps it
        ctl.tick(st, t)
        t += DT
    return t


def test_a_yes_is_withdrawn_after_a_window_of_opposition_and_nothing_else_changes():
    ctl = answered(1.0)
    assert ctl.belief.confirmed == "bowl:top"
    before = ctl.belief
    away = against_ho(ctl)
    t = drive(ctl, away, 0.4, 0.0)
    assert ctl.belief.confirmed == "bowl:top" and ctl.yes_withdrawn == 0  # under half the window: not yet
    drive(ctl, away, 0.8, t)
    b = ctl.belief
    assert b.confirmed is None and ctl.yes_withdrawn == 1
    np.testing.assert_array_equal(b.log_p, before.log_p)  # the probabilities as they were
    assert b.ruled_out == frozenset({"chips can:side"})  # the "no" stays final
    ctl.reset()
    assert ctl.yes_withdrawn == 0
    again = answered(1.0)
    drive(again, against_ho(again), 1.2, 0.0)
    assert again.yes_withdrawn == 1
    again.new_goals(SCENE.goals)  # a new scene is a new task too
    assert again.yes_withdrawn == 0


def test_a_yes_stays_final_when_off_or_when_the_user_goes_along():
    off = answered(0.0)
    drive(off, against_ho(off), 3.0, 0.0)
    assert off.belief.confirmed == "bowl:top" and off.yes_withdrawn == 0
    along = answered(1.0)
    drive(along, -against_ho(along), 3.0, 0.0)
    assert along.belief.confirmed == "bowl:top" and along.yes_withdrawn == 0


def test_after_the_withdrawal_the_joystick_moves_the_answered_target_again():
    """Held final, the bowl keeps its total whatever the input says; withdrawn, input heading away from it
    takes probability from it."""
    share = {}
    for window in (0.0, 1.0):
        ctl = answered(window)
        p0 = ctl.belief.target_probabilities()["bowl:top"]
        drive(ctl, against_ho(ctl), 4.0, 0.0, update_belief=True)
        share[window] = (p0, ctl.belief.target_probabilities()["bowl:top"])
    assert share[0.0][1] == pytest.approx(share[0.0][0], abs=1e-9)
    assert share[1.0][1] < 0.5 * share[1.0][0]


def test_a_bad_window_is_refused_naming_the_key():
    with pytest.raises(ConfigError, match="asking.withdraw_yes_s"):
        config_from_dict({"asking": {"withdraw_yes_s": -1.0}})


def denied(withdraw_no_s: float, withdraw_yes_s: float = 0.0, yes: str | None = None) -> Controller:
    """HO assisting after "is it the bowl?" - "no" (and, with ``yes``, "is it ``yes``?" - "yes")."""
    cfg = config_from_dict({"asking": {"withdraw_no_s": withdraw_no_s, "withdraw_yes_s": withdraw_yes_s}})
    ctl = Controller(cfg, SCENE.goals, "ho", DT)
    for target, answer in (("bowl:top", False), *(((yes, True),) if yes else ())):
        ctl.ask(target, 0.0)
        ctl.on_answer(answer, 0.0)
    ctl.adopt_fixed()
    return ctl


def toward_bowl() -> np.ndarray:
    """Joystick axes (translation) toward the bowl's nearest grasp from the start."""
    bowl = SCENE.goal("bowl:top")
    aim = min((p.position for p in bowl.poses), key=lambda q: float(np.linalg.norm(q - START.position)))
    d = aim - START.position
    return d / np.abs(d).max()


def test_a_no_is_withdrawn_after_a_window_of_opposition_and_nothing_else_changes():
    ctl = denied(1.0)
    before = ctl.belief
    assert before.ruled_out == frozenset({"bowl:top"}) and before.confirmed is None
    away = against_ho(ctl)
    t = drive(ctl, away, 0.4, 0.0)
    assert ctl.belief.ruled_out and ctl.no_withdrawn == 0  # under half the window: not yet
    drive(ctl, away, 0.8, t)
    b = ctl.belief
    assert b.ruled_out == frozenset() and ctl.no_withdrawn == 1 and ctl.yes_withdrawn == 0
    np.testing.assert_array_equal(b.log_p, before.log_p)  # the probabilities as they were
    assert b.confirmed is None
    ctl.reset()
    assert ctl.no_withdrawn == 0


def test_a_no_stays_final_when_off_when_the_user_goes_along_and_while_a_yes_holds():
    off = denied(0.0)
    drive(off, against_ho(off), 3.0, 0.0)
    assert off.belief.ruled_out == frozenset({"bowl:top"}) and off.no_withdrawn == 0
    along = denied(1.0)
    drive(along, -against_ho(along), 3.0, 0.0)
    assert along.belief.ruled_out == frozenset({"bowl:top"}) and along.no_withdrawn == 0
    held = denied(1.0, yes="cup:top")  # a yes holds and only the no answers may be withdrawn: nothing is
    drive(held, against_ho(held), 3.0, 0.0)
    assert held.belief.confirmed == "cup:top" and held.belief.ruled_out == frozenset({"bowl:top"})
    both = denied(1.0, withdraw_yes_s=1.0, yes="cup:top")  # both on: the yes goes first, then the no
    t = drive(both, against_ho(both), 0.8, 0.0)  # half a window of opposition for each, one after the other
    assert both.belief.confirmed is None and both.belief.ruled_out == frozenset({"bowl:top"})
    drive(both, against_ho(both), 0.4, t)
    assert (both.yes_withdrawn, both.no_withdrawn) == (1, 1) and both.belief.ruled_out == frozenset()


def test_after_the_withdrawal_input_toward_the_denied_target_raises_it_again():
    """Held final, the bowl keeps the share its "no" left it whatever the input says; withdrawn after the
    person fought the arm, input heading to it brings it back."""
    share = {}
    for window in (0.0, 1.0):
        ctl = denied(window)
        p0 = ctl.belief.target_probabilities()["bowl:top"]
        t = drive(ctl, against_ho(ctl), 1.2, 0.0)  # the person fights the arm: the no goes (if it may)
        drive(ctl, toward_bowl(), 4.0, t, update_belief=True)  # then heads for the bowl
        share[window] = (p0, ctl.belief.target_probabilities()["bowl:top"], ctl.no_withdrawn)
    assert share[0.0][1] == pytest.approx(share[0.0][0], abs=1e-9) and share[0.0][2] == 0
    assert share[1.0][2] == 1 and share[1.0][1] > 0.5


def test_a_bad_no_window_is_refused_naming_the_key():
    with pytest.raises(ConfigError, match="asking.withdraw_no_s"):
        config_from_dict({"asking": {"withdraw_no_s": 31.0}})


def test_a_daemon_whose_user_always_answers_wrongly_withdraws_the_yes_and_finishes_the_task(tmp_path):
    """The real daemon (policy, Scene 1 ``cup:top``) with a simulated user who answers every question
    wrongly: the first wrong "yes" is withdrawn, published as ``yes_withdrawn``, and the task still
    ends in a success."""
    d = DaemonProc(tmp_path, "--duration", "120", "--no-speech",
                   config="[asking]\nwithdraw_yes_s = 1.0\n[sim_user]\nanswer_error_rate = 1.0\n"
                       # the paper's reach (the default until session 43): this trial asks under it
                       + PAPER_REACH_TOML)
    try:
        d.wait_ready()
        c = d.collector
        i, yes = c.event("answer", timeout_s=90, value="yes")
        assert yes["goal"] != "cup:top"  # wrong, as configured
        j, gone = c.event("yes_withdrawn", timeout_s=30, start=i, goal=yes["goal"])
        assert 0.5 <= gone["t"] - yes["t"] <= 10.0  # at least half the window of opposition, then at once
        _, done = c.event("task_done", timeout_s=90, start=j)
        assert done["success"] is True and done["timed_out"] is False
    finally:
        d.close()


def test_a_daemon_whose_user_always_answers_wrongly_withdraws_its_no_and_finishes_the_task(tmp_path):
    """The real daemon with a user who answers every question wrongly, on the task whose first question
    is about the person's goal in every recorded trial (Scene 1 ``chips can:side``, the rotate-first
    user): the wrong "no" is withdrawn once the person has opposed the arm, published as ``no_withdrawn``
    naming it, and the task still ends in a success."""
    run = ("--arm", "kinematic", "--input", "sim", "--scene", "scene1", "--task", "chips can:side",
           "--user", "rotate-first")
    d = DaemonProc(tmp_path, "--duration", "150", "--no-speech", run=run,
                   config="[asking]\nwithdraw_no_s = 1.0\n[sim_user]\nanswer_error_rate = 1.0\n")
    try:
        d.wait_ready()
        c = d.collector
        i, no = c.event("answer", timeout_s=90, value="no")
        assert no["goal"] == "chips can:side"  # wrong, as configured
        j, gone = c.event("no_withdrawn", timeout_s=30, start=i)
        assert gone["goals"] == ["chips can:side"] and 0.5 <= gone["t"] - no["t"] <= 20.0
        _, done = c.event("task_done", timeout_s=90, start=j)
        assert done["success"] is True and done["timed_out"] is False
    finally:
        d.close()
