"""Joystick input: JoystickMapper on real ``evdev.InputEvent`` objects, and EvdevJoystick with a fake
device at the hardware boundary (there is no /dev/input here)."""

from __future__ import annotations

import asyncio
import errno

import evdev
import numpy as np
import pytest
from evdev import AbsInfo, InputEvent, ecodes
from hypothesis import given
from hypothesis import strategies as st

from sa_daemon.config import JoystickConfig
from sa_daemon.io.joystick import (
    AxisRange,
    Button,
    EvdevJoystick,
    JoystickMapper,
    smooth_deadzone,
)

X, Y, RZ = ecodes.ABS_X, ecodes.ABS_Y, ecodes.ABS_RZ
SYM = {X: AxisRange(-1000, 1000), Y: AxisRange(-1000, 1000), RZ: AxisRange(-1000, 1000)}


def ev(type_: int, code: int, value: int, sec: int = 0, usec: int = 0) -> InputEvent:
    return InputEvent(sec, usec, type_, code, value)


def absev(code: int, value: int) -> InputEvent:
    return ev(ecodes.EV_ABS, code, value)


def key(code: int, value: int) -> InputEvent:
    return ev(ecodes.EV_KEY, code, value)


def cfg(**kw) -> JoystickConfig:
    base = {"signs": (1.0, 1.0, 1.0), "deadzone": 0.0}
    base.update(kw)
    return JoystickConfig(**base)


# -- normalisation -------------------------------------------------------------------------------------


def test_axes_normalise_min_centre_max_of_each_range():
    ranges = {X: AxisRange(0, 255), Y: AxisRange(-512, 511), RZ: AxisRange(0, 1023)}
    m = JoystickMapper(cfg(), ranges)
    np.testing.assert_allclose(m.axes(), [0, 0, 0], atol=1e-12)  # centred before any event
    for code, r in ranges.items():
        i = [X, Y, RZ].index(code)
        m.handle(absev(code, r.min))
        assert m.axes()[i] == pytest.approx(-1.0)
        m.handle(absev(code, r.max))
        assert m.axes()[i] == pytest.approx(1.0)
    m.handle(absev(X, 191))  # 3/4 of 0..255 (raw 191.25)
    assert m.axes()[0] == pytest.approx(2 * 191 / 255 - 1)
    m.handle(absev(RZ, 0))
    np.testing.assert_allclose(m.axes(), [2 * 191 / 255 - 1, 1.0, -1.0])


def test_values_beyond_the_range_are_clamped():
    m = JoystickMapper(cfg(), {X: AxisRange(0, 255), Y: AxisRange(-512, 511), RZ: AxisRange(0, 1023)})
    m.handle(absev(X, 5000))
    m.handle(absev(Y, -40000))
    m.handle(absev(RZ, 1024))
    np.testing.assert_allclose(m.axes(), [1.0, -1.0, 1.0])
    assert np.all(np.abs(m.axes()) <= 1.0)


def test_empty_range_is_refused():
    with pytest.raises(ValueError, match="empty range"):
        JoystickMapper(cfg(), {X: AxisRange(0, 255), Y: AxisRange(7, 7), RZ: AxisRange(0, 1023)})


# -- deadzone ------------------------------------------------------------------------------------------


def test_smooth_deadzone_values():
    dz = 0.2
    assert smooth_deadzone(0.0, dz) == 0.0
    assert smooth_deadzone(0.1, dz) == 0.0
    assert smooth_deadzone(-0.2, dz) == 0.0
    assert smooth_deadzone(0.2 + 1e-9, dz) == pytest.approx(1e-9 / 0.8, abs=1e-12)  # continuous at dz
    assert smooth_deadzone(0.6, dz) == pytest.approx(0.5)  # (0.6 - 0.2) / 0.8
    assert smooth_deadzone(-0.6, dz) == pytest.approx(-0.5)
    assert smooth_deadzone(1.0, dz) == pytest.approx(1.0)
    assert smooth_deadzone(-1.0, dz) == pytest.approx(-1.0)


@given(
    st.floats(-1, 1, allow_nan=False),
    st.floats(-1, 1, allow_nan=False),
    st.floats(0, 0.95, allow_nan=False),
)
def test_smooth_deadzone_is_odd_monotone_and_bounded(a, b, dz):
    fa, fb = smooth_deadzone(a, dz), smooth_deadzone(b, dz)
    assert -1.0 <= fa <= 1.0
    assert smooth_deadzone(-a, dz) == pytest.approx(-fa)
    if a <= b:
        assert fa <= fb + 1e-12
    assert abs(fa - fb) <= abs(a - b) / (1 - dz) + 1e-9  # Lipschitz: no jump anywhere


def test_mapper_applies_the_deadzone_after_normalising():
    m = JoystickMapper(cfg(deadzone=0.2), SYM)  # raw / 1000 = normalised value
    m.handle(absev(X, 150))
    m.handle(absev(Y, -200))
    m.handle(absev(RZ, 600))
    np.testing.assert_allclose(m.axes(), [0.0, 0.0, 0.5])
    m.handle(absev(X, 1000))
    m.handle(absev(Y, -1000))
    np.testing.assert_allclose(m.axes(), [1.0, -1.0, 0.5])
    m.handle(absev(X, 201))
    assert 0 < m.axes()[0] < 0.01


# -- signs, mapping, buttons ---------------------------------------------------------------------------


def test_signs_and_axis_mapping_from_the_config():
    c = cfg(axes=("ABS_RY", "ABS_X", "ABS_THROTTLE"), signs=(-1.0, 1.0, -1.0))
    ranges = {ecodes.ABS_RY: AxisRange(0, 100), X: AxisRange(-100, 100), ecodes.ABS_THROTTLE: AxisRange(0, 10)}
    m = JoystickMapper(c, ranges)
    m.handle(absev(ecodes.ABS_RY, 100))
    np.testing.assert_allclose(m.axes(), [-1.0, 0.0, 0.0])
    m.handle(absev(X, -50))
    np.testing.assert_allclose(m.axes(), [-1.0, -0.5, 0.0])
    m.handle(absev(ecodes.ABS_THROTTLE, 10))
    np.testing.assert_allclose(m.axes(), [-1.0, -0.5, -1.0])
    m.handle(absev(Y, 1000))  # not a configured axis here
    m.handle(absev(RZ, 1000))
    np.testing.assert_allclose(m.axes(), [-1.0, -0.5, -1.0])


def test_default_config_flips_y():
    m = JoystickMapper(JoystickConfig(deadzone=0.0), SYM)
    m.handle(absev(Y, 1000))  # stick pulled toward the user
    np.testing.assert_allclose(m.axes(), [0.0, -1.0, 0.0])


def test_buttons_map_on_press_only():
    c = JoystickConfig()
    m = JoystickMapper(c, SYM)
    for b in Button:
        code = ecodes.ecodes[getattr(c, f"button_{b.value}")]
        assert m.handle(key(code, 1)) is b
        assert m.handle(key(code, 2)) is None  # autorepeat
        assert m.handle(key(code, 0)) is None  # release


def test_buttons_follow_the_config():
    c = JoystickConfig(button_yes="BTN_SOUTH", button_no="BTN_EAST", button_mode="BTN_TR")
    m = JoystickMapper(c, SYM)
    assert m.handle(key(ecodes.BTN_SOUTH, 1)) is Button.YES
    assert m.handle(key(ecodes.BTN_EAST, 1)) is Button.NO
    assert m.handle(key(ecodes.BTN_TR, 1)) is Button.MODE
    assert m.handle(key(ecodes.BTN_TRIGGER, 1)) is None  # the default mode button is no longer mapped


def test_unknown_codes_and_other_event_types_are_ignored():
    m = JoystickMapper(cfg(), SYM)
    m.handle(absev(X, 500))
    before = m.axes().copy()
    assert m.handle(key(ecodes.BTN_BASE6, 1)) is None
    assert m.handle(key(ecodes.KEY_A, 1)) is None
    assert m.handle(absev(ecodes.ABS_HAT0X, 1)) is None
    assert m.handle(ev(ecodes.EV_SYN, ecodes.SYN_REPORT, 0)) is None
    assert m.handle(ev(ecodes.EV_REL, ecodes.REL_X, 5)) is None
    assert m.handle(ev(ecodes.EV_MSC, ecodes.MSC_SCAN, 589825)) is None
    np.testing.assert_array_equal(m.axes(), before)


def test_reset_centres_every_axis():
    m = JoystickMapper(cfg(), {X: AxisRange(0, 255), Y: AxisRange(-512, 511), RZ: AxisRange(0, 1023)})
    for c in (X, Y, RZ):
        m.handle(absev(c, 100000))
    m.reset()
    np.testing.assert_allclose(m.axes(), [0, 0, 0], atol=1e-12)


# -- configuration errors ------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "kw, name",
    [
        ({"axes": ("ABS_X", "ABS_Y", "ABS_NOPE")}, "ABS_NOPE"),
        ({"axes": ("BTN_TRIGGER", "ABS_Y", "ABS_RZ")}, "BTN_TRIGGER"),  # exists, but is not an axis
        ({"button_stop": "BTN_NOPE"}, "BTN_NOPE"),
        ({"button_yes": "ABS_X"}, "ABS_X"),  # an axis is not a button
    ],
)
def test_config_naming_a_bad_code_is_refused_naming_it(kw, name):
    with pytest.raises(ValueError, match=name):
        JoystickMapper(JoystickConfig(**kw), SYM)


def test_device_lacking_an_axis_is_refused_naming_it():
    with pytest.raises(ValueError, match="ABS_RZ"):
        JoystickMapper(JoystickConfig(), {X: AxisRange(0, 255), Y: AxisRange(0, 255)})


# -- EvdevJoystick with a fake device ------------------------------------------------------------------


def _absinfo(lo: int, hi: int) -> AbsInfo:
    return AbsInfo(value=(lo + hi) // 2, min=lo, max=hi, fuzz=0, flat=0, resolution=0)


#: The default config's six buttons (the kernel lists every key a device has in its capabilities).
ALL_BUTTONS = tuple(ecodes.ecodes[getattr(JoystickConfig(), f"button_{b.value}")] for b in Button)


class FakeDevice:
    """What EvdevJoystick uses of ``evdev.InputDevice``; ``events`` are yielded, then ENODEV (unplugged),
    or, with ``events=None``, the read loop waits until cancelled (a device that stays)."""

    def __init__(self, path: str, name: str, abs_caps: dict[int, AbsInfo], events: list[InputEvent] | None,
                 keys: tuple[int, ...] = ALL_BUTTONS):
        self.path, self.name = path, name
        self._abs = abs_caps
        self._events = events
        self.keys = keys
        self.closed = self.grabbed = False
        self.unplug = lambda: None

    def capabilities(self, verbose: bool = False, absinfo: bool = True):
        caps = {ecodes.EV_KEY: list(self.keys)}
        if self._abs:
            caps[ecodes.EV_ABS] = list(self._abs.items())
        return caps

    async def async_read_loop(self):
        if self._events is None:
            await asyncio.Event().wait()
        for e in self._events:
            await asyncio.sleep(0)
            yield e
        self.unplug()  # the kernel removes the node, then the read fails
        raise OSError(errno.ENODEV, "No such device")

    def grab(self):
        self.grabbed = True

    def close(self):
        self.closed = True


JOY_CAPS = {X: _absinfo(0, 255), Y: _absinfo(0, 255), RZ: _absinfo(-128, 127), ecodes.ABS_HAT0X: _absinfo(-1, 1)}


class FakeBus:
    """``evdev.list_devices`` and ``evdev.InputDevice`` over a dict of plugged devices."""

    def __init__(self):
        self.plugged: dict[str, FakeDevice] = {}
        self.opened: list[FakeDevice] = []

    def list_devices(self):
        return sorted(self.plugged)

    def open(self, path):
        if path not in self.plugged:
            raise FileNotFoundError(errno.ENOENT, "No such file or directory", path)
        d = self.plugged[path]
        dev = FakeDevice(d.path, d.name, d._abs, d._events, d.keys)
        dev.unplug = lambda: self.plugged.pop(path, None)
        self.opened.append(dev)
        return dev


@pytest.fixture
def bus(monkeypatch):
    b = FakeBus()
    monkeypatch.setattr(evdev, "list_devices", b.list_devices)
    monkeypatch.setattr(evdev, "InputDevice", b.open)
    return b


async def _until(pred, timeout_s: float = 10.0) -> None:
    loop = asyncio.get_running_loop()
    end = loop.time() + timeout_s
    while not pred():
        if loop.time() > end:
            raise AssertionError("condition not met in time")
        await asyncio.sleep(0.005)


async def test_evdev_joystick_reports_axes_zeroes_on_unplug_and_reconnects(bus):
    calls: list[tuple] = []
    c = JoystickConfig(poll_s=0.02, deadzone=0.0, grab=True)
    joy = EvdevJoystick(
        c,
        on_axes=lambda a: calls.append(("axes", tuple(np.round(a, 6)))),
        on_button=lambda b: calls.append(("button", b)),
        on_link=lambda up, text: calls.append(("link", up, text)),
    )
    bus.plugged["/dev/input/event3"] = FakeDevice("/dev/input/event3", "AT keyboard", {}, None)  # no axes
    bus.plugged["/dev/input/event7"] = FakeDevice(
        "/dev/input/event7", "Fake Stick", JOY_CAPS,
        [absev(X, 255), ev(ecodes.EV_SYN, 0, 0), absev(Y, 0), key(ecodes.BTN_TRIGGER, 1),
         key(ecodes.BTN_TRIGGER, 0), absev(RZ, -128)],
    )
    task = asyncio.create_task(joy.run())
    try:
        # Connected, read, then unplugged: the link goes down and the axes are zeroed.
        await _until(lambda: any(c[0] == "link" and c[1] is False for c in calls))
        assert calls[0][:2] == ("link", True) and "Fake Stick" in calls[0][2]
        assert ("axes", (1.0, 0.0, 0.0)) in calls
        assert ("axes", (1.0, 1.0, 0.0)) in calls  # default signs: y flipped (raw 0 = -1)
        assert ("button", Button.MODE) in calls
        assert ("axes", (1.0, 1.0, -1.0)) in calls
        i_lost = next(i for i, c in enumerate(calls) if c[0] == "link" and c[1] is False)
        assert calls[i_lost - 1] == ("axes", (0.0, 0.0, 0.0)), "axes must be zeroed at once, before anything else"
        assert "lost" in calls[i_lost][2]
        assert joy.connected is False
        np.testing.assert_array_equal(joy.mapper.axes(), np.zeros(3))
        keyboard = next(d for d in bus.opened if d.name == "AT keyboard")
        assert keyboard.closed  # looked at and put back
        stick = next(d for d in bus.opened if d.name == "Fake Stick")
        assert stick.grabbed and stick.closed

        # Gone from the bus: announced once while looking for it.
        assert "/dev/input/event7" not in bus.plugged
        await _until(lambda: any(c[0] == "link" and "no joystick" in c[2] for c in calls))
        await asyncio.sleep(0.1)  # several polls
        assert sum(c[0] == "link" and "no joystick" in c[2] for c in calls) == 1
        n = len(calls)

        # Plugged again: reconnected, and its events are read again.
        bus.plugged["/dev/input/event9"] = FakeDevice("/dev/input/event9", "Fake Stick", JOY_CAPS, None)
        await _until(lambda: any(c[0] == "link" and c[1] is True for c in calls[n:]))
        assert joy.connected and joy.device_name == "Fake Stick"
        assert "/dev/input/event9" in next(c for c in calls[n:] if c[0] == "link")[2]
    finally:
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)
    # Cancelling (daemon shutdown) also zeroes the axes.
    assert calls[-2:] == [("axes", (0.0, 0.0, 0.0)), calls[-1]] and calls[-1][:2] == ("link", False)


async def test_evdev_joystick_opens_only_the_configured_device(bus):
    links: list[tuple[bool, str]] = []
    c = JoystickConfig(device="Right Stick", poll_s=0.02)
    joy = EvdevJoystick(c, lambda a: None, lambda b: None, lambda up, text: links.append((up, text)))
    bus.plugged["/dev/input/event1"] = FakeDevice("/dev/input/event1", "Left Stick", JOY_CAPS, None)
    task = asyncio.create_task(joy.run())
    try:
        await _until(lambda: links)
        assert links[0][0] is False and "Right Stick" in links[0][1]
        bus.plugged["/dev/input/event2"] = FakeDevice("/dev/input/event2", "Right Stick", JOY_CAPS, None)
        await _until(lambda: any(up for up, _ in links))
        assert joy.device_name == "Right Stick"
        assert all(d.closed for d in bus.opened if d.name == "Left Stick")
    finally:
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)


async def test_a_joystick_without_the_stop_button_is_not_used_and_says_why(bus):
    """The person's stop button is part of the joystick: a device lacking it is passed over, reported."""
    links: list[tuple[bool, str]] = []
    joy = EvdevJoystick(JoystickConfig(poll_s=0.02), lambda a: None, lambda b: None,
                        lambda up, text: links.append((up, text)))
    no_stop = tuple(k for k in ALL_BUTTONS if k != ecodes.BTN_PINKIE)
    bus.plugged["/dev/input/event4"] = FakeDevice("/dev/input/event4", "Two Button Stick", JOY_CAPS, None, no_stop)
    task = asyncio.create_task(joy.run())
    try:
        await _until(lambda: links)
        why = "joystick Two Button Stick at /dev/input/event4 has no BTN_PINKIE (joystick.button_stop): not used"
        assert links[0] == (False, why)
        assert not joy.connected and all(d.closed for d in bus.opened)
        bus.plugged["/dev/input/event5"] = FakeDevice("/dev/input/event5", "Full Stick", JOY_CAPS, None)
        await _until(lambda: joy.connected)
        assert joy.device_name == "Full Stick"
    finally:
        task.cancel()
        await asyncio.gather(task, return_exceptions=True)
