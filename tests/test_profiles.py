"""Per-person profiles (issue 18, part 2): the file, the stick's calibration and gains, the tremor filter
and its measured delay, the questions a person wants, ``calibrate`` on recorded evdev streams, and
``run --profile`` on a real daemon."""

from __future__ import annotations

import asyncio
import json
import math
import subprocess
import tomllib

import numpy as np
import pytest
from evdev import AbsInfo, ecodes
from helpers import CLI, DaemonProc
from test_joystick import JOY_CAPS, FakeDevice, ev

from sa_daemon.config import Config, ConfigError, JoystickConfig, config_from_dict
from sa_daemon.control.controller import Controller
from sa_daemon.control.lowpass import LowPass
from sa_daemon.io.calibrate import CalibrationError, calibrate, measure
from sa_daemon.io.joystick import AxisRange, JoystickMapper
from sa_daemon.model.model import SharedAutonomyModel
from sa_daemon.profile import load_profile, parse_profile, profile_toml
from sa_daemon.world.scene import load_scene

X, Y, RZ = ecodes.ABS_X, ecodes.ABS_Y, ecodes.ABS_RZ

# -- the file ------------------------------------------------------------------------------------------------


def test_a_profile_sets_only_its_keys_and_round_trips_through_toml(tmp_path):
    p = parse_profile({"name": "alex", "summary": "left hand", "joystick": {"gains": [1.0, 0.8, 0.5], "deadzone": 0.1},
                       "input": {"filter_hz": 3.0}, "blend": {"alpha": 0.3},
                       "speech": {"rate_wpm": 120, "voice": "en-gb-x-rp"},
                       "asking": {"max_per_task": 2, "answer_sources": ["button"]}}, "alex.toml")
    cfg = p.apply(Config())
    assert cfg.joystick.gains == (1.0, 0.8, 0.5) and cfg.joystick.deadzone == 0.1 and cfg.input.filter_hz == 3.0
    assert cfg.blend.alpha == 0.3 and cfg.speech.rate_wpm == 120 and cfg.speech.voice == "en-gb-x-rp"
    assert cfg.asking.max_per_task == 2 and cfg.asking.answer_sources == ("button",)
    untouched = Config().model_dump()
    for section in ("planner", "reward", "safety", "limits", "intent"):
        assert cfg.model_dump()[section] == untouched[section]
    f = tmp_path / "alex.toml"
    f.write_text(profile_toml(p))
    assert load_profile(str(f), "/nowhere").overrides == p.overrides
    (tmp_path / "kim.toml").write_text('name = "kim"\n[blend]\nalpha = 0.6\n')
    assert load_profile("kim", str(tmp_path)).apply(Config()).blend.alpha == 0.6  # a name, in profiles.dir
    # A person who wants to fine-tune alone (section VI-E.4): the yield switches are theirs to set.
    fine = parse_profile({"name": "sam", "blend": {"yield_near_m": 0.05, "opposition_window_s": 1.0}}, "sam.toml")
    assert (fine.apply(Config()).blend.yield_near_m, fine.apply(Config()).blend.opposition_window_s) == (0.05, 1.0)
    churn = parse_profile({"name": "lee", "blend": {"churn_window_s": 8.0, "churn_switches": 4,
                                                   "churn_counts": "driven"}}, "lee.toml")
    b = churn.apply(Config()).blend
    assert (b.churn_window_s, b.churn_switches, b.churn_counts) == (8.0, 4, "driven")
    with pytest.raises(ConfigError, match="churn_switches"):
        parse_profile({"name": "lee", "blend": {"churn_switches": 1}}, "lee.toml").apply(Config())
    steady = parse_profile({"name": "ana", "planner": {"switch_margin": 50.0}}, "ana.toml").apply(Config())
    assert steady.planner.switch_margin == 50.0  # a steadier arm (docs/profiles.md)
    assert steady.planner.model_dump() | {"switch_margin": 0.0} == Config().planner.model_dump()
    corridor = parse_profile({"name": "jo", "move": {"approach_standoff_m": 0.06}}, "jo.toml").apply(Config())
    assert corridor.move.approach_standoff_m == 0.06  # the approach corridor (docs/profiles.md)
    assert corridor.move.model_dump() | {"approach_standoff_m": 0.0} == Config().move.model_dump()
    assert p.keys() == ["asking.answer_sources", "asking.max_per_task", "blend.alpha", "input.filter_hz",
                        "joystick.deadzone", "joystick.gains", "speech.rate_wpm", "speech.voice"]


@pytest.mark.parametrize("data, key", [
    ({"name": "a", "blend": {"alpha": 0.9}}, "blend.alpha"),  # outside the safe range 0.2-0.8
    ({"name": "a", "blend": {"alpha": 0.1}}, "blend.alpha"),
    ({"name": "a", "planner": {"horizon_s": 1}}, "planner.horizon_s"),  # the planner's model is not a person's
    ({"name": "a", "planner": {"switch_margin": -1}}, "switch_margin"),
    ({"name": "a", "move": {"approach_standoff_m": -0.01}}, "approach_standoff_m"),
    ({"name": "a", "move": {"linear_max_mps": 0.3}}, "move.linear_max_mps"),  # the arm's speed is not a person's
    ({"name": "a", "model": {"alpha": 0.5}}, "model"),  # not a profile section
    ({"name": "a", "speech": {"enabled": False}}, "speech.enabled"),  # not a profile key
    ({"name": "a", "joystick": {"gains": [5, 1, 1]}}, "gains"),
    ({"name": "a", "joystick": {"signs": [1, 0.5, 1]}}, "signs"),
    ({"name": "a", "joystick": {"centre": [1, 2, 3]}}, "centre"),  # without low and high
    ({"name": "a", "asking": {"answer_sources": ["telepathy"]}}, "answer_sources"),
    ({"name": "a", "input": {"filter_hz": -1}}, "filter_hz"),
    ({"name": "a", "blend": {"yield_near_m": 0.9}}, "yield_near_m"),  # above 0.5 m
    ({"summary": "no name"}, "name"),
    ({"name": "a", "reward": {"question": -1.0}}, "reward.question:"),  # the paper's cost is not a person's
    ({"name": "a", "reward": {"question_time_s": 2.5}}, "reward.question_time_s"),  # not whole rollout steps
])
def test_a_bad_profile_is_refused_naming_the_key(data, key):
    with pytest.raises(ConfigError, match=key):
        parse_profile(data, "p.toml")


def test_a_slow_answerer_s_profile_makes_the_planner_charge_their_questions_longer():
    """``[reward] question_time_s``: the arm stands still until the person answers, so the watch model
    charges a slow answerer's question more standing still. Fig. 5's moment (near the cup, top and side
    even, the user turning): the question's value falls with the person's answer time, more than any
    other action's."""
    from test_when_to_ask import GOALS, NEAR_CUP, beliefs

    from sa_daemon.model.actions import ActionKind, Mode
    from sa_daemon.planner.snapshot import Snapshot
    from sa_daemon.planner.solver import Solver

    snap = Snapshot(GOALS, beliefs({"cup:top": 0.49, "cup:side": 0.49}), NEAR_CUP, np.zeros(6), mode=Mode.ROTATION,
                    user_speed=(0.024, 0.0))
    values = {}
    for seconds in (2.0, 4.0):
        cfg = parse_profile({"name": "sam", "reward": {"question_time_s": seconds}}, "sam.toml").apply(Config())
        assert cfg.reward.question == Config().reward.question  # the paper's -5 is not a person's to set
        values[seconds] = Solver(SharedAutonomyModel(cfg)).plan(snap).root_values
    ask = [a for a in values[2.0] if a.kind is ActionKind.QUESTION and a.target == "cup:top"]
    assert ask and values[4.0][ask[0]] < values[2.0][ask[0]] - 1.0
    # A watch's value holds the questions it may ask later, so it falls too, but by less.
    watch = [a for a in values[2.0] if a.kind is not ActionKind.QUESTION]
    assert all(values[2.0][ask[0]] - values[4.0][ask[0]] > values[2.0][a] - values[4.0][a] for a in watch)


def test_the_daemon_counts_a_persons_answer_times_and_suggests_what_their_profile_would_set():
    """``status``'s ``answer_times``: from three answers on, the median answer time rounded up to whole
    rollout steps; a profile switch (another person) counts afresh."""
    import time

    from sa_daemon.runtime.asking import Asker

    cfg = Config()
    ctl = Controller(cfg, load_scene("scene1").goals, "policy", 0.01)
    events: list[dict] = []
    asker = Asker(cfg, ctl, lambda kind, **fields: events.append({"type": kind, **fields}))
    assert ctl.answer_time.summary() == {"count": 0, "median_s": None, "charged_s": 2.0, "learning": True,
                                         "suggested_s": None}
    for target, after in (("cup:top", 2.2), ("bowl:top", 3.4)):
        ctl.ask(target, time.monotonic() - after)
        asker.answer("no", "command")
    assert ctl.answer_time.summary()["count"] == 2 and ctl.answer_time.summary()["suggested_s"] is None
    ctl.ask("chips can:side", time.monotonic() - 2.6)
    asker.answer("yes", "command")
    times = ctl.answer_time.summary()
    assert times["count"] == 3 and times["median_s"] == pytest.approx(2.6, abs=0.05) and times["suggested_s"] == 3.0
    assert times["charged_s"] == 3.0  # learned: median(2, 2.2, 3.4, 2.6) = 2.4, up to whole steps
    # each answer event says what the planner charges from then on: median(2, 2.2) = 2.1 -> 3,
    # median(2, 2.2, 3.4) = 2.2 -> 3, then 3
    assert [e["charged_s"] for e in events if e["type"] == "answer"] == [3.0, 3.0, 3.0]
    ctl.reconfigure(cfg)  # a profile switch, as the daemon makes it (another person)
    asker.reconfigure(cfg)
    assert ctl.answer_time.summary()["count"] == 0


# -- the stick ----------------------------------------------------------------------------------------------


def test_a_calibration_normalises_each_side_of_the_centre_and_gains_scale_after_the_deadzone():
    ranges = {X: AxisRange(0, 255), Y: AxisRange(0, 255), RZ: AxisRange(0, 255)}
    cfg = JoystickConfig(centre=(130.0, 128.0, 128.0), low=(30.0, 0.0, 0.0), high=(200.0, 255.0, 255.0),
                         deadzone=0.0, signs=(1.0, 1.0, 1.0), gains=(1.0, 1.0, 0.5))
    m = JoystickMapper(cfg, ranges)
    for raw, want in ((130, 0.0), (200, 1.0), (165, 0.5), (30, -1.0), (80, -0.5), (255, 1.0), (0, -1.0)):
        m.handle(ev(ecodes.EV_ABS, X, raw))
        assert m.axes()[0] == pytest.approx(want), raw  # (raw - 130) / 70 above, / 100 below, clamped
    m.handle(ev(ecodes.EV_ABS, RZ, 255))
    assert m.axes()[2] == pytest.approx(0.5)  # full deflection times its gain
    m.reset()
    assert np.all(m.axes() == 0.0)  # the calibrated centre is rest


# -- the tremor filter ---------------------------------------------------------------------------------------


def test_the_tremor_filter_delays_slow_motion_by_its_time_constant_and_damps_tremor_as_a_first_order_lowpass():
    """Measured on signals sampled at the daemon's control rate (100 Hz): the delay of a 0.2 Hz sine by
    cross-correlation, and the amplitude left of a 5 Hz tremor (the simulated users' ``tremor_hz``)."""
    fc, dt = 3.0, 0.01
    tau = 1.0 / (2.0 * math.pi * fc)
    t = np.arange(0.0, 20.0, dt)

    def run(x: np.ndarray) -> np.ndarray:
        f = LowPass(fc)
        return np.array([f.update(np.array([v, 0.0, 0.0]), ti)[0] for ti, v in zip(t, x)])

    w = 2 * np.pi * 0.2
    y = run(np.sin(w * t))
    # the phase of the output against the input, by least squares on sin and cos, after the start-up
    a, b = np.linalg.lstsq(np.column_stack((np.sin(w * t), np.cos(w * t)))[500:], y[500:], rcond=None)[0]
    delay = -math.atan2(b, a) / w
    tremor = run(np.sin(2 * np.pi * 5.0 * t))
    gain = (tremor[500:].max() - tremor[500:].min()) / 2
    print(f"filter 3 Hz at 100 Hz: delay {delay * 1e3:.1f} ms (tau {tau * 1e3:.1f} ms + half a period), "
          f"5 Hz tremor kept {gain:.2f}")
    # 1 / (2 pi fc) = 53 ms, plus half a control period: the input waits for the next tick (a hold)
    assert delay == pytest.approx(tau + dt / 2, abs=0.002)
    assert gain == pytest.approx(1 / math.sqrt(1 + (5 / fc) ** 2), abs=0.03)
    assert np.array_equal(LowPass(0.0).update(np.ones(3), 1.0), np.ones(3))  # 0 Hz: no filter


def test_the_controller_filters_the_stick_and_a_lost_device_is_zero_at_once():
    scene = load_scene("scene1")
    cfg = config_from_dict({"input": {"filter_hz": 2.0}})
    ctl = Controller(cfg, scene.goals, "manual", 0.01)
    from sa_daemon.arm.base import ArmState

    st = ArmState(scene.start, False, None, None)
    ctl.adopt_fixed()
    ctl.on_input([1.0, 0.0, 0.0], 0.0)
    ctl.tick(st, 0.0)
    speeds = []
    for k in range(1, 30):
        ctl.hold_input(k * 0.01)
        ctl.tick(st, k * 0.01)
        speeds.append(ctl.user_twist[0])
    tau = 1 / (2 * math.pi * 2.0)
    assert speeds[0] < 0.2 * cfg.input.linear_scale_mps  # not the full step at once
    assert speeds[-1] == pytest.approx(cfg.input.linear_scale_mps * (1 - math.exp(-0.29 / tau)), rel=0.05)
    ctl.lose_input()
    assert np.all(ctl.user_twist == 0.0)


# -- the questions a person wants ----------------------------------------------------------------------------


def test_max_per_task_caps_the_questions_the_planner_may_still_ask():
    from sa_daemon.planner.solver import Solver

    scene = load_scene("scene1")
    cfg = config_from_dict({"asking": {"max_per_task": 1}, "planner": {"model": "commit"},
                            "reward": {"question_time_s": 0.0}})
    ctl = Controller(cfg, scene.goals, "policy", 0.01)
    snap = ctl.snapshot(scene.start, None)
    assert snap.questions_left == 1
    ctl.ask("cup:top", 0.0)
    ctl.on_answer(False, 1.0)
    snap = ctl.snapshot(scene.start, None)
    assert snap.questions_left == 0
    r = Solver(SharedAutonomyModel(cfg)).plan(snap)
    assert all(a.kind.value != "question" for a in r.root_values), "a question was still considered"


# -- calibrate on recorded streams ---------------------------------------------------------------------------


def _stream(t0: float, rest_noise: int = 2) -> list:
    """A recorded session: rest near (130, 125, 128) with a little noise, then circles that reach
    (30..200) on x, (0..250) on y and the full twist range on rz."""
    rng = np.random.default_rng(3)
    out = []
    for k in range(30):  # 3 s rest, 10 Hz of noise
        for code, c in ((X, 130), (Y, 125), (RZ, 128)):
            out.append(ev(ecodes.EV_ABS, code, c + int(rng.integers(-rest_noise, rest_noise + 1)),
                          *divmod_us(t0 + 0.1 * k)))
    for k in range(80):  # 8 s of circles
        a = 2 * np.pi * k / 20
        x = 130 + (70 if np.cos(a) > 0 else 100) * np.cos(a)
        y = 125 + 125 * np.sin(a)
        z = 128 + 127 * np.sin(a / 2)
        for code, v in ((X, x), (Y, y), (RZ, z)):
            out.append(ev(ecodes.EV_ABS, code, round(v), *divmod_us(t0 + 3.0 + 0.1 * k)))
    return out


def divmod_us(t: float) -> tuple[int, int]:
    sec = int(t)
    return sec, round((t - sec) * 1e6)


def test_measure_finds_centre_noise_and_the_asymmetric_range():
    t0 = 1_700_000_000.0
    events = [(e.timestamp(), e.code, e.value) for e in _stream(t0)]
    start = {X: 131.0, Y: 125.0, RZ: 128.0}
    cal = measure(events, start, JoystickConfig(), t0 + 3.0, t0 + 11.0)
    x, y, _ = cal.axes
    assert x.centre == pytest.approx(130, abs=1.0) and x.noise <= 3
    assert (x.low, x.high) == (30.0, 200.0) and (y.low, y.high) == (0.0, 250.0)
    assert 0.02 <= cal.deadzone <= 0.2
    keys = cal.joystick_keys()
    assert keys["axes"] == ["ABS_X", "ABS_Y", "ABS_RZ"] and keys["low"][0] == 30.0
    still = [(t, c, v) for t, c, v in events if t < t0 + 3.0]
    with pytest.raises(CalibrationError, match="did not move on both sides"):
        measure(still, start, JoystickConfig(), t0 + 3.0, t0 + 11.0)


def test_calibrate_reads_a_recorded_device_and_its_profile_drives_the_mapper(tmp_path):
    t0 = 1_700_000_000.0
    caps = {**JOY_CAPS, X: AbsInfo(130, 0, 255, 0, 0, 0), Y: AbsInfo(125, 0, 255, 0, 0, 0),
            RZ: AbsInfo(128, 0, 255, 0, 0, 0)}
    dev = FakeDevice("/dev/input/event5", "Recorded Stick", caps, _stream(t0))
    said: list[str] = []
    cal = asyncio.run(calibrate(dev, JoystickConfig(), 3.0, 8.0, t_start=t0, say=said.append))
    assert said[0].startswith("1/2") and cal.axes[0].low == 30.0
    prof = parse_profile({"name": "rec", "joystick": cal.joystick_keys()}, "rec.toml")
    jcfg = prof.apply(Config()).joystick
    m = JoystickMapper(jcfg, {X: AxisRange(0, 255), Y: AxisRange(0, 255), RZ: AxisRange(0, 255)})
    m.handle(ev(ecodes.EV_ABS, X, 30))
    assert m.axes()[0] == pytest.approx(-1.0)  # the person's own limit is full deflection


# -- run --profile on a real daemon ---------------------------------------------------------------------------


def test_run_with_a_profile_applies_it_announces_it_and_refuses_answers_from_a_source_it_turned_off(tmp_path):
    prof = tmp_path / "pat.toml"
    prof.write_text('name = "pat"\n[asking]\nanswer_sources = ["button", "voice"]\n[blend]\nalpha = 0.4\n')
    d = DaemonProc(tmp_path / "d", "--method", "policy", "--duration", "600", "--no-speech", "--profile", str(prof),
                   config='[planner]\nmodel = "commit"\n[reward]\nquestion_time_s = 0.0\n'
                          '[sim_user]\nanswer_delay_s = 60.0\n')
    try:
        d.wait_ready()
        _, e = d.collector.event("profile", timeout_s=30)
        assert e["name"] == "pat" and e["keys"] == ["asking.answer_sources", "blend.alpha"]
        d.collector.state(lambda s: s["question"], timeout_s=60, what="a pending question")
        r = subprocess.run([*CLI, "answer", "yes", "--cmd", d.cmd], capture_output=True, text=True, timeout=60,
                           check=False)
        assert r.returncode == 1 and "answers by command are off" in json.loads(r.stdout)["error"]
    finally:
        d.close()
    bad = tmp_path / "bad.toml"
    bad.write_text('name = "x"\n[blend]\nalpha = 0.95\n')
    r = subprocess.run([*CLI, "run", "--profile", str(bad), "--duration", "1"], capture_output=True, text=True,
                       timeout=60, check=False)
    assert r.returncode == 2 and "blend.alpha" in r.stderr
    assert tomllib.loads(prof.read_text())["name"] == "pat"


# -- switching profile on a running daemon, through the protocol and the page ----------------------------------


def test_set_profile_switches_between_tasks_and_is_refused_while_the_arm_moves(tmp_path):
    import asyncio as aio

    import aiohttp
    from test_web import WebProc

    pdir = tmp_path / "profiles"
    pdir.mkdir()
    (pdir / "sam.toml").write_text('name = "sam"\n[blend]\nalpha = 0.3\n[speech]\nrate_wpm = 120\n')
    (pdir / "broken.toml").write_text('name = "broken"\n[blend]\nalpha = 0.95\n')
    d = DaemonProc(tmp_path / "d", "--method", "ho", "--duration", "600", "--no-speech",
                   config=f'[profiles]\ndir = "{pdir}"\n')
    try:
        d.wait_ready()
        c = d.collector
        c.state(lambda s: any(s["command_twist"]), timeout_s=30, what="the arm moving")
        r = d.request({"cmd": "set_profile", "profile": "sam"})
        assert not r["ok"] and "the arm is moving" in r["error"]
        st = d.request({"cmd": "status"})
        assert st["profile"] is None and st["profiles"] == ["broken", "sam"]
        for bad, why in (("../etc/passwd", "no path"), ("nobody", "cannot read"), ("broken", "blend.alpha")):
            assert d.request({"cmd": "stop"})["ok"]
            c.state(lambda s: not any(s["command_twist"]), timeout_s=10, start=len(c))
            r = d.request({"cmd": "set_profile", "profile": bad})
            assert not r["ok"] and why in r["error"], r
        i = len(c)
        r = d.request({"cmd": "set_profile", "profile": "sam"})
        assert r == {"ok": True, "profile": "sam", "keys": ["blend.alpha", "speech.rate_wpm"]}
        _, e = c.event("profile", timeout_s=10, start=i)
        assert e["name"] == "sam"
        c.event("planner_restart", timeout_s=10, start=i, reason="profile switched")
        assert d.request({"cmd": "status"})["profile"] == "sam"
        # the page offers the profiles and switches too
        w = WebProc(tmp_path / "web", d)
        try:
            w.wait_listening()

            async def run():
                async with aiohttp.ClientSession() as s, s.ws_connect(w.url + "/ws") as ws:
                    await ws.send_str('{"cmd": "set_profile", "profile": "sam"}')
                    while True:
                        m = json.loads((await ws.receive(timeout=10)).data)
                        if m["type"] == "reply":
                            return m

            assert aio.run(run())["profile"] == "sam"
        finally:
            w.close()
    finally:
        d.close()


def test_calibrate_without_the_device_says_so_and_writes_nothing(tmp_path):
    r = subprocess.run([*CLI, "calibrate", "--device", "/dev/input/event99", "--profile", str(tmp_path / "p.toml")],
                       capture_output=True, text=True, timeout=60, check=False)
    assert r.returncode == 2 and "no input device '/dev/input/event99'" in r.stderr
    assert not (tmp_path / "p.toml").exists()
