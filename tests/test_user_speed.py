"""The user's predicted speed per part (``control/user_speed.py``), and what a mode not yet entered is
predicted at (``planner.user_speed_unused``): ``zero`` (the default) or the other mode's deflection.

Session 35 found 26 of 46 Table I questions (Scene 1 ``cup:top``, 8 users, seeds 300-304) chosen in
rotation mode with the predicted angular speed 0: right after a user's first switch to rotation the
watch expects no input at all, so watching tells nothing and a question is the only evidence left.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from sa_daemon.config import ConfigError, config_from_dict
from sa_daemon.control.controller import Controller
from sa_daemon.control.user_speed import UserSpeed
from sa_daemon.model.actions import Mode
from sa_daemon.model.model import SharedAutonomyModel
from sa_daemon.planner.snapshot import Snapshot
from sa_daemon.planner.watch import WatchSearch
from sa_daemon.world.scene import load_scene

SCENE = load_scene("scene1")
SCALE = (0.2, 0.4)  # input.linear_scale_mps, input.angular_scale_radps (the defaults)
DT = 0.025


def _twist(lin=(0.0, 0.0, 0.0), ang=(0.0, 0.0, 0.0)) -> np.ndarray:
    return np.array([*lin, *ang], dtype=float)


def _drive(s: UserSpeed, twist: np.ndarray, part: int, t: float, seconds: float) -> float:
    for _ in range(round(seconds / DT)):
        t += DT
        s.update(twist, part, t)
    return t


def test_zero_is_the_exponential_average_and_a_mode_not_entered_stays_still():
    """Ticks of ``dt``: ``v += (1 - exp(-dt / tau)) (|u| - v)``, computed here step by step on its own
    (the first tick, after no tick at all, weighs as 0.1 s); the angular part, never entered, is
    predicted at 0."""
    s = UserSpeed(1.0, "decay", "zero", SCALE)
    rng = np.random.default_rng(3)
    v, t = 0.0, 0.0
    for i in range(120):
        t += DT
        u = rng.uniform(-0.1, 0.1, 3)
        s.update(_twist(lin=u), 0, t)
        v += (1.0 - math.exp(-(0.1 if i == 0 else DT) / 1.0)) * (np.linalg.norm(u) - v)
    assert s.value[0] == pytest.approx(v, rel=1e-12)
    assert s.value[1] == 0.0 and s.entered == (True, False)


def test_deflection_predicts_a_mode_not_entered_at_the_other_modes_deflection():
    """Translating steadily at half deflection (0.1 m/s of 0.2 at full), rotation is predicted at half
    deflection too (0.2 rad/s of 0.4); entering rotation starts its average there."""
    s = UserSpeed(0.5, "decay", "deflection", SCALE)
    t = _drive(s, _twist(lin=(0.1, 0.0, 0.0)), 0, 0.0, 8.0)  # 16 time constants: at speed
    assert s.value[0] == pytest.approx(0.1, rel=1e-6)
    assert s.value[1] == pytest.approx(0.2, rel=1e-6) and s.entered == (True, False)
    s.update(_twist(ang=(0.0, 0.0, 0.2)), 1, t + DT)  # in rotation at the predicted speed: no jump
    assert s.value[1] == pytest.approx(0.2, rel=1e-6) and s.entered == (True, True)
    assert s.value[0] == pytest.approx(0.1, rel=1e-6)  # the other part keeps its own average


@pytest.mark.parametrize("idle", ["decay", "hold"])
def test_a_pause_in_the_new_mode_decays_its_prediction_as_any_pause(idle):
    """Entered without input (the user switched and waits): ``decay`` averages the zeros in from the
    prediction, 1 s at ``tau`` = 1 s leaves ``e^-1`` of it; ``hold`` keeps it."""
    s = UserSpeed(1.0, idle, "deflection", SCALE)
    t = _drive(s, _twist(lin=(0.05, 0.0, 0.0)), 0, 0.0, 20.0)
    predicted = s.value[1]
    assert predicted == pytest.approx(0.1, rel=1e-6)
    _drive(s, _twist(), 1, t, 1.0)
    expected = predicted * (math.exp(-1.0) if idle == "decay" else 1.0)
    assert s.value[1] == pytest.approx(expected, rel=1e-6)


def test_before_any_input_both_parts_are_still_and_reset_forgets_the_task():
    s = UserSpeed(1.0, "decay", "deflection", SCALE)
    assert s.value == (0.0, 0.0)
    _drive(s, _twist(lin=(0.1, 0.0, 0.0)), 0, 0.0, 2.0)
    assert s.value[1] > 0.0
    s.reset()
    assert s.value == (0.0, 0.0) and s.entered == (False, False)


@pytest.mark.parametrize(("tau", "scale"), [(0.0, SCALE), (math.nan, SCALE), (1.0, (0.2, 0.0)), (1.0, (math.inf, 1))])
def test_bad_parameters_are_refused(tau, scale):
    with pytest.raises(ValueError):
        UserSpeed(tau, "decay", "deflection", scale)


def test_the_option_is_refused_by_name_when_malformed():
    with pytest.raises(ConfigError, match=r"planner\.user_speed_unused"):
        config_from_dict({"planner": {"user_speed_unused": "other"}})


@pytest.mark.parametrize("unused", ["zero", "deflection"])
def test_the_controllers_snapshot_carries_the_prediction_after_a_switch(unused):
    """2 s of the stick at 0.3 toward +x, then a switch to rotation: the snapshot's angular speed is 0
    (``zero``) or the translation's deflection on the angular scale (``deflection``)."""
    cfg = config_from_dict({"planner": {"user_speed_unused": unused}})
    ctl = Controller(cfg, SCENE.goals, "policy", DT)
    t = 0.0
    for _ in range(80):
        t += DT
        assert ctl.on_input([0.3, 0.0, 0.0], t)
        ctl.update_belief(SCENE.start, t)
    lin = ctl.user_speed[0]
    assert lin == pytest.approx(0.3 * cfg.input.linear_scale_mps * (1 - math.exp(-2.0)), rel=0.05)
    ctl.set_mode(Mode.ROTATION)
    ang = ctl.user_speed[1]
    want = lin / cfg.input.linear_scale_mps * cfg.input.angular_scale_radps if unused == "deflection" else 0.0
    assert ang == pytest.approx(want, rel=1e-9)


def test_the_watch_expects_evidence_in_rotation_only_from_a_user_predicted_to_turn():
    """In rotation mode, a watched second's predicted input is the turn toward each goal at the angular
    speed: at 0 rad/s it carries no evidence (every branch's belief is the root's), at 0.1 rad/s it does.
    What ``user_speed_unused = "deflection"`` changes at the first switch to rotation."""
    model = SharedAutonomyModel(config_from_dict({"planner": {"threads": 1}}))
    goals = model.initial_belief(SCENE.goals).goals
    b0 = np.full(len(goals), 1.0 / len(goals))
    pose = SCENE.start
    spread = {}
    for w in (0.0, 0.1):
        snap = Snapshot(goals, b0, pose, np.zeros(6), mode=Mode.ROTATION, budget_s=None, user_speed=(0.03, w))
        ws = WatchSearch(model, snap)
        B = ws.child_beliefs(ws.root_rollouts(), ws.watched)
        spread[w] = float(np.abs(B - b0[None]).max())
    assert spread[0.0] < 1e-9
    assert spread[0.1] > 1e-3
