"""Joystick input through python-evdev: a pure event mapper and a thin device reader.

:class:`JoystickMapper` turns ``evdev.InputEvent`` objects into normalised axes and button intents;
it touches no device and is what the tests drive. :class:`EvdevJoystick` opens the device (by path or
name), reads it with ``async_read_loop`` on the event loop, and survives it disappearing: ``ENODEV``
zeroes the axes at once, reports ``lost``, and the device is looked for every ``poll_s`` until it
returns (evdev has no hotplug API).
"""

from __future__ import annotations

import asyncio
import errno
import logging
from collections.abc import Callable
from dataclasses import dataclass
from enum import Enum
from typing import Any

import numpy as np
from evdev import InputEvent, ecodes

from ..config import JoystickConfig

log = logging.getLogger(__name__)


class Button(str, Enum):
    """Button intents (config ``joystick.button_*``)."""

    MODE = "mode"
    GRIPPER = "gripper"
    YES = "yes"
    NO = "no"
    ASSIST = "assist"
    STOP = "stop"
    OTHER = "other"


@dataclass(frozen=True)
class AxisRange:
    """The kernel's range of one absolute axis (``evdev.AbsInfo``'s ``min``/``max``)."""

    min: int
    max: int


def smooth_deadzone(v: float, dz: float) -> float:
    """0 within ``dz``, then ``(|v| - dz) / (1 - dz)`` with ``v``'s sign: continuous, reaching 1 at 1."""
    a = abs(v)
    return 0.0 if a <= dz else float(np.sign(v)) * (a - dz) / (1.0 - dz)


def _code(name: str, kind: str, key: str = "joystick") -> int:
    code = ecodes.ecodes.get(name)
    if code is None or not name.startswith(kind):
        raise ValueError(f"{key}: {name!r} is not an evdev {kind} code")
    return int(code)


def check_codes(cfg: JoystickConfig) -> None:
    """Refuse (``ValueError`` naming the key) an axis or button name that is not an evdev code of its kind;
    the daemon checks this before it starts anything, since no device could ever match such a config."""
    for name in cfg.axes:
        _code(name, "ABS_", "joystick.axes")
    for b in Button:
        _code(getattr(cfg, f"button_{b.value}"), "BTN_", f"joystick.button_{b.value}")


class JoystickMapper:
    """Map evdev events to 3 normalised axes in [-1, 1] and button presses.

    ``ranges`` gives each configured axis code's kernel range (from ``device.absinfo(code)``). The
    kernel does not clamp, so values are clamped here.
    """

    def __init__(self, cfg: JoystickConfig, ranges: dict[int, AxisRange]) -> None:
        self.cfg = cfg
        self.axis_codes = [_code(n, "ABS_") for n in cfg.axes]
        missing = [n for n, c in zip(cfg.axes, self.axis_codes) if c not in ranges]
        if missing:
            raise ValueError(f"joystick: the device has no axis {', '.join(missing)} (joystick.axes)")
        self.ranges = [ranges[c] for c in self.axis_codes]
        if any(r.max <= r.min for r in self.ranges):
            raise ValueError("joystick: an axis reports an empty range (absinfo max <= min)")
        self.signs = np.asarray(cfg.signs, dtype=float)
        self.gains = np.asarray(cfg.gains, dtype=float)
        self.buttons = {
            _code(getattr(cfg, f"button_{b.value}"), "BTN_"): b for b in Button
        }
        # (low, centre, high) raw values per axis: a person's calibration (sa-daemon calibrate), else the
        # kernel's range with its middle as the centre
        if cfg.centre is not None and cfg.low is not None and cfg.high is not None:
            self.spans = [tuple(map(float, t)) for t in zip(cfg.low, cfg.centre, cfg.high, strict=True)]
        else:
            self.spans = [(float(r.min), (r.min + r.max) / 2.0, float(r.max)) for r in self.ranges]
        self._raw = [c for _, c, _ in self.spans]

    def reset(self) -> None:
        """Centre every axis (device lost: the user's twist must be zero at once)."""
        self._raw = [c for _, c, _ in self.spans]

    def axes(self) -> np.ndarray:
        """The three axes: normalised on each side of the centre (a calibration may be asymmetric),
        clamped, deadzoned, times the gain, clamped again, signed."""
        out = np.empty(3)
        for i, (raw, (lo, c, hi)) in enumerate(zip(self._raw, self.spans)):
            v = (raw - c) / (hi - c) if raw >= c else (raw - c) / (c - lo)
            v = min(1.0, max(-1.0, v))
            out[i] = self.signs[i] * min(1.0, max(-1.0, self.gains[i] * smooth_deadzone(v, self.cfg.deadzone)))
        return out

    def handle(self, ev: InputEvent) -> Button | None:
        """Take one event; return the button pressed by it (presses only, not releases or repeats)."""
        if ev.type == ecodes.EV_ABS and ev.code in self.axis_codes:
            self._raw[self.axis_codes.index(ev.code)] = float(ev.value)
        elif ev.type == ecodes.EV_KEY and ev.value == 1:
            return self.buttons.get(ev.code)
        return None


def ranges_of(device: Any, codes: list[int]) -> dict[int, AxisRange]:
    """Axis ranges of an open ``evdev.InputDevice`` for ``codes`` (those it has)."""
    caps = dict(device.capabilities().get(ecodes.EV_ABS, []))
    return {c: AxisRange(caps[c].min, caps[c].max) for c in codes if c in caps}


class EvdevJoystick:
    """Read a real device and feed ``on_axes(axes)``, ``on_button(button)`` and ``on_link(up, text)``."""

    def __init__(
        self,
        cfg: JoystickConfig,
        on_axes: Callable[[np.ndarray], None],
        on_button: Callable[[Button], None],
        on_link: Callable[[bool, str], None],
    ) -> None:
        check_codes(cfg)
        self.cfg = cfg
        self.on_axes, self.on_button, self.on_link = on_axes, on_button, on_link
        self.mapper: JoystickMapper | None = None
        self._ranges: dict[int, AxisRange] = {}  # every absolute axis of the connected device
        self.device_name: str | None = None
        self.connected = False

    def reconfigure(self, cfg: JoystickConfig) -> None:
        """A person's mapping and calibration from now on; ``ValueError`` (and nothing changes) if the
        connected device lacks an axis it names."""
        check_codes(cfg)
        mapper = None
        if self.mapper is not None and self.connected:
            mapper = JoystickMapper(cfg, dict(zip(self.mapper.axis_codes, self.mapper.ranges)) | self._ranges)
        self.cfg = cfg
        if mapper is not None:
            self.mapper = mapper

    def _find(self) -> tuple[Any | None, str | None]:
        """The first device with the configured axes and stop button, or ``None`` and why a device that
        has the axes was passed over (it lacks the stop button: the person could not stop the arm)."""
        import evdev

        want = self.cfg.device
        stop = _code(self.cfg.button_stop, "BTN_", "joystick.button_stop")
        why = None
        for path in evdev.list_devices():
            try:
                dev = evdev.InputDevice(path)
            except OSError:
                continue
            if want and want not in (path, dev.name):
                dev.close()
                continue
            try:
                JoystickMapper(self.cfg, ranges_of(dev, [_code(n, "ABS_") for n in self.cfg.axes]))
            except ValueError:
                dev.close()
                continue
            if stop not in dev.capabilities().get(ecodes.EV_KEY, []):
                why = f"joystick {dev.name} at {path} has no {self.cfg.button_stop} (joystick.button_stop): not used"
                dev.close()
                continue
            return dev, None
        return None, why

    async def run(self) -> None:
        """Read forever (cancel to stop), re-finding the device whenever it disappears."""
        announced_missing = False
        while True:
            dev, why = self._find()
            if dev is None:
                if not announced_missing:
                    self.on_link(False, why or f"no joystick {self.cfg.device or '(any)'} found; looking every "
                                 f"{self.cfg.poll_s} s")
                    announced_missing = True
                await asyncio.sleep(self.cfg.poll_s)
                continue
            announced_missing = False
            self._ranges = ranges_of(dev, sorted({c for c, _ in dev.capabilities().get(ecodes.EV_ABS, [])}))
            self.mapper = JoystickMapper(self.cfg, ranges_of(dev, [_code(n, "ABS_") for n in self.cfg.axes]))
            self.device_name, self.connected = dev.name, True
            if self.cfg.grab:
                dev.grab()
            self.on_link(True, f"joystick {dev.name} at {dev.path}")
            try:
                async for ev in dev.async_read_loop():
                    button = self.mapper.handle(ev)
                    if button is not None:
                        self.on_button(button)
                    elif ev.type == ecodes.EV_ABS:
                        self.on_axes(self.mapper.axes())
            except OSError as e:
                if e.errno != errno.ENODEV:
                    log.warning("joystick read failed: %s", e)
            finally:
                self.connected = False
                self.mapper.reset()
                self.on_axes(np.zeros(3))
                self.on_link(False, f"joystick {self.device_name} lost")
                try:
                    dev.close()
                except OSError:
                    pass
