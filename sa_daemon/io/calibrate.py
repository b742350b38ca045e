"""``sa-daemon calibrate``: measure one person's stick and write it into their profile.

Two phases, timed on the kernel's event timestamps: the person lets go of the stick for ``rest_s`` (its
rest position and noise), then moves it slowly to its limits in every direction for ``move_s`` (the range
they reach, which may be smaller on one side than the other). The kernel reports changes only, so each
axis holds its last value between events, starting from the device's current value (``absinfo``).

From the raw values of each configured axis (``joystick.axes``):

* ``centre``: the time-weighted mean of the rest phase; ``noise``: the largest distance from it then;
* ``low`` / ``high``: the smallest and largest values of the move phase (the rest's extremes included);
* ``deadzone``: the rest noise as a fraction of the smaller half-range, times 3, plus 0.02, within
  0.02-0.3 (a still hand never moves the arm; the range is used from there on);

and the profile's ``[joystick]`` gets ``axes``, ``centre``, ``low``, ``high`` and ``deadzone`` (the rest
of an existing profile is kept). Refused, with the reason, when an axis did not move on both sides of its
centre or its rest noise reaches past half its range.
"""

from __future__ import annotations

import asyncio
import errno
import time
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np
from evdev import ecodes

from ..config import JoystickConfig
from .joystick import _code


class CalibrationError(ValueError):
    """A measurement that cannot be a calibration; the text says what to do."""


@dataclass(frozen=True)
class AxisCalibration:
    """One axis, raw device units: its rest ``centre`` and ``noise``, the ``low``/``high`` it reached."""

    name: str
    centre: float
    noise: float
    low: float
    high: float


@dataclass(frozen=True)
class StickCalibration:
    axes: tuple[AxisCalibration, ...]
    deadzone: float

    def joystick_keys(self) -> dict[str, Any]:
        """The profile's ``[joystick]`` keys."""
        return {
            "axes": [a.name for a in self.axes],
            "centre": [round(a.centre, 3) for a in self.axes],
            "low": [round(a.low, 3) for a in self.axes],
            "high": [round(a.high, 3) for a in self.axes],
            "deadzone": self.deadzone,
        }

    def report(self) -> str:
        rows = [f"  {a.name:<8} centre {a.centre:9.2f}  noise {a.noise:7.2f}  range {a.low:9.2f} .. {a.high:9.2f}"
                for a in self.axes]
        return "\n".join([*rows, f"  deadzone {self.deadzone:.3f}"])


def measure(events: Iterable[tuple[float, int, int]], start: dict[int, float], cfg: JoystickConfig,
            split_t: float, end_t: float) -> StickCalibration:
    """The calibration of the module doc from ``events`` ``(t, code, value)`` of absolute axes (sorted by
    ``t``), each axis's value before the first event (``start``), the end of the rest phase ``split_t``
    and of the move phase ``end_t`` (s, the events' clock)."""
    codes = [_code(n, "ABS_") for n in cfg.axes]
    missing = [n for n, c in zip(cfg.axes, codes) if c not in start]
    if missing:
        raise CalibrationError(f"the device has no axis {', '.join(missing)} (joystick.axes)")
    value = {c: float(start[c]) for c in codes}
    t_prev = None
    rest_sum = dict.fromkeys(codes, 0.0)
    rest_vals: dict[int, list[float]] = {c: [value[c]] for c in codes}
    move_vals: dict[int, list[float]] = {c: [] for c in codes}
    rest_time = 0.0
    for t, code, v in [*events, (end_t, -1, 0)]:
        if t_prev is not None and t > t_prev:
            a, b = t_prev, min(t, split_t)
            if b > a:  # the held values during the rest phase, weighted by how long they held
                rest_time += b - a
                for c in codes:
                    rest_sum[c] += value[c] * (b - a)
        if t_prev is not None and t_prev < split_t <= t:
            for c in codes:  # held into the move phase
                move_vals[c].append(value[c])
        t_prev = t if t_prev is None else max(t_prev, t)
        if code in value and t <= end_t:
            value[code] = float(v)
            (rest_vals if t < split_t else move_vals)[code].append(float(v))
    axes = []
    for name, c in zip(cfg.axes, codes):
        centre = rest_sum[c] / rest_time if rest_time > 0 else value[c]
        noise = max(abs(x - centre) for x in rest_vals[c])
        moved = move_vals[c] or [value[c]]
        lo, hi = min(min(moved), min(rest_vals[c])), max(max(moved), max(rest_vals[c]))
        if not (min(moved) < min(rest_vals[c]) and max(moved) > max(rest_vals[c])):
            raise CalibrationError(f"{name} did not move on both sides of its rest ({centre:g}): move the stick to "
                                   "its limits in every direction during the second phase")
        half = min(centre - lo, hi - centre)
        if noise >= 0.25 * half:
            raise CalibrationError(f"{name} moved during the rest phase (noise {noise:g} of {half:g}): let go of "
                                   "the stick during the first phase")
        axes.append(AxisCalibration(name, centre, noise, lo, hi))
    frac = max(a.noise / min(a.centre - a.low, a.high - a.centre) for a in axes)
    return StickCalibration(tuple(axes), round(float(np.clip(3.0 * frac + 0.02, 0.02, 0.3)), 3))


async def collect(device: Any, until_t: float, timeout_s: float) -> list[tuple[float, int, int]]:
    """Absolute-axis events ``(t, code, value)`` from ``device`` up to its events' time ``until_t`` (s),
    for at most ``timeout_s`` of wall time (a still stick sends nothing; a recorded stream may just end)."""
    out: list[tuple[float, int, int]] = []

    async def read() -> None:
        async for ev in device.async_read_loop():
            t = ev.timestamp()
            if t > until_t:
                return
            if ev.type == ecodes.EV_ABS:
                out.append((t, ev.code, ev.value))

    try:
        await asyncio.wait_for(read(), timeout=timeout_s)
    except TimeoutError:
        pass
    except OSError as e:
        if e.errno != errno.ENODEV:
            raise
    return out


async def calibrate(device: Any, cfg: JoystickConfig, rest_s: float, move_s: float, t_start: float | None = None,
                    say: Any = print) -> StickCalibration:
    """Guide the person through the two phases on ``device`` (an open ``evdev.InputDevice``) and measure.
    ``t_start`` is when the rest phase starts on the events' clock (default: now, the kernel's clock)."""
    caps = dict(device.capabilities().get(ecodes.EV_ABS, []))
    start = {c: float(info.value) for c, info in caps.items()}
    t0 = time.time() if t_start is None else t_start
    say(f"1/2: let go of the stick for {rest_s:g} s ...")
    loop = asyncio.get_running_loop()
    prompt = loop.call_later(rest_s, say, f"2/2: now move the stick slowly to its limits in every direction, "
                                          f"round and round, for {move_s:g} s ...")
    try:
        events = await collect(device, t0 + rest_s + move_s, rest_s + move_s + 1.0)
    finally:
        prompt.cancel()
    return measure(sorted(events), start, cfg, t0 + rest_s, t0 + rest_s + move_s)
