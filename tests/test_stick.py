"""The joystick as the controller holds it (``control/stick.py``): samples, freshness, mode, tremor filter."""

from __future__ import annotations

import math

import numpy as np

from sa_daemon.config import config_from_dict
from sa_daemon.control.stick import Stick
from sa_daemon.model.actions import Mode


def _stick(**inp) -> Stick:
    return Stick(config_from_dict({"input": inp}).input)


def test_a_sample_is_clipped_and_a_malformed_one_changes_nothing():
    s = _stick()
    assert s.sample([2.0, -3.0, 0.5], 1.0)
    assert np.allclose(s.axes, [1.0, -1.0, 0.5]) and s.t_input == 1.0 and s.seq == 1
    for bad in ([np.nan, 0.0, 0.0], [0.1, 0.2], [[0.1, 0.2, 0.3]], [math.inf, 0.0, 0.0]):
        assert not s.sample(bad, 2.0)
    assert np.allclose(s.axes, [1.0, -1.0, 0.5]) and s.t_input == 1.0 and s.seq == 1
    held = s.axes
    held[0] = 0.0  # a copy: the stick's own axes do not change
    assert s.axes[0] == 1.0


def test_freshness_holding_and_losing_the_device():
    s = _stick()
    assert not s.fresh(0.0, 0.2)  # nothing yet
    s.sample([0.3, 0.0, 0.0], 1.0)
    assert s.fresh(1.2, 0.2) and not s.fresh(1.21, 0.2)
    s.hold(2.0)  # a device that reports changes only, still connected
    assert s.fresh(2.1, 0.2) and s.seq == 1
    s.lose()
    assert not s.fresh(2.0, 0.2) and not np.any(s.axes) and not np.any(s.twist)


def test_the_twist_follows_the_mode_in_si_units():
    cfg = config_from_dict({}).input
    s = Stick(cfg)
    s.sample([1.0, 0.0, 0.0], 0.0)
    assert s.mode is Mode.TRANSLATION
    assert np.isclose(s.twist[0], cfg.linear_scale_mps) and not np.any(s.twist[3:])
    assert s.set_mode(Mode.ROTATION) and not s.set_mode(Mode.ROTATION)
    assert not np.any(s.twist[:3]) and np.isclose(np.linalg.norm(s.twist[3:]), cfg.angular_scale_radps)


def test_the_tremor_filter_delays_a_step_and_a_new_setting_starts_it_at_rest():
    s = _stick(filter_hz=3.0)
    s.sample([1.0, 0.0, 0.0], 0.0)
    s.filter(0.0)
    assert not np.any(s.twist)  # at rest: the step has not passed yet
    tau = 1.0 / (2.0 * math.pi * 3.0)
    s.filter(tau)
    lin = config_from_dict({}).input.linear_scale_mps
    assert np.isclose(s.twist[0], lin * (1.0 - math.exp(-1.0)))  # one time constant: 63 %
    s.reconfigure(config_from_dict({"input": {"filter_hz": 3.0}}).input)
    assert not np.any(s.twist)
    s.reconfigure(config_from_dict({}).input)  # no filter: the held axes as they are
    assert np.isclose(s.twist[0], lin)
