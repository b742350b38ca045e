"""The joystick as the controller holds it: the last sample's three axes (normalised, [-1, 1]), when it
came (s, the caller's clock), how many have come, the mode the axes drive (translation or rotation), and
the tremor filter (``input.filter_hz``, :mod:`.lowpass`) that runs on the held axes at the control rate.
"""

from __future__ import annotations

import math

import numpy as np

from ..config import InputConfig
from ..geometry import FloatArray
from ..model.actions import Mode
from ..model.twists import axes_to_twist
from .lowpass import LowPass


class Stick:
    """One joystick's held state. A sample that is not three finite numbers changes nothing."""

    def __init__(self, cfg: InputConfig) -> None:
        self._cfg = cfg
        self._mode = Mode.TRANSLATION
        self._axes = np.zeros(3)
        self._smooth = LowPass(cfg.filter_hz)  # the tremor filter (0 Hz: none)
        self._axes_out = np.zeros(3)  # the axes after it, as of the last filter step (used when it is on)
        self._t = -math.inf
        self._seq = 0

    @property
    def mode(self) -> Mode:
        """The mode the axes drive."""
        return self._mode

    @property
    def axes(self) -> FloatArray:
        """The last sample, normalised to [-1, 1] (a copy)."""
        return self._axes.copy()

    @property
    def t_input(self) -> float:
        """When the last sample arrived (s; ``-inf``: none, or the device was lost)."""
        return self._t

    @property
    def seq(self) -> int:
        """Counts the samples taken."""
        return self._seq

    @property
    def twist(self) -> FloatArray:
        """The user's twist (m/s, rad/s) of the held axes, after the tremor filter if any, in the mode."""
        axes = self._axes_out if self._smooth.tau_s > 0.0 else self._axes
        return axes_to_twist(axes, self._mode, self._cfg)

    def fresh(self, t: float, stale_s: float) -> bool:
        """A sample arrived within ``stale_s`` (s) of ``t``."""
        return t - self._t <= stale_s

    def sample(self, axes: FloatArray, t: float) -> bool:
        """A sample at ``t`` (s), clipped to [-1, 1]; ``False`` (and nothing changes) unless it is three
        finite numbers."""
        a = np.asarray(axes, dtype=float)
        if a.shape != (3,) or not np.all(np.isfinite(a)):
            return False
        self._axes = np.clip(a, -1.0, 1.0)
        self._t = t
        self._seq += 1
        return True

    def hold(self, t: float) -> None:
        """The device reports changes only and is connected: its held axes are current at ``t`` (s)."""
        self._t = t

    def lose(self) -> None:
        """The device is gone: axes zero, the filter at rest and the input stale at once."""
        self._axes = np.zeros(3)
        self._axes_out = np.zeros(3)
        self._smooth.reset()  # zero at once, no glide
        self._t = -math.inf

    def filter(self, t: float) -> None:
        """Run the tremor filter up to ``t`` (s) on the held axes (nothing without one)."""
        if self._smooth.tau_s > 0.0:
            self._axes_out = self._smooth.update(self._axes, t)

    def set_mode(self, mode: Mode) -> bool:
        """Drive ``mode`` from now on; ``True`` if it changed."""
        mode = Mode(mode)
        changed = mode is not self._mode
        self._mode = mode
        return changed

    def reconfigure(self, cfg: InputConfig) -> None:
        """A person's new input settings; a new filter starts at rest, as at start-up."""
        self._cfg = cfg
        self._smooth = LowPass(cfg.filter_hz)
        self._axes_out = np.zeros(3)
