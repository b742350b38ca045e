"""The user's smoothed speed in each part of the twist, which the watch model's predicted user drives at.

Per part ``i`` (0: linear, m/s; 1: angular, rad/s), over the belief ticks in that part's mode, an
exponential average of the twist's norm ``|u_i|`` with time constant ``tau = planner.user_speed_tau_s``:
``v_i += (1 - exp(-dt / tau)) (|u_i| - v_i)``, ``dt`` the time since the last tick (at most 0.1 s, so a
tick after a gap weighs as one of 0.1 s). A tick without input is averaged in as zero
(``planner.user_speed_idle = "decay"``: a pausing user is predicted to stay still) or skipped (``"hold"``).

A part whose mode the user has not been in yet in this task has no average of its own.
``planner.user_speed_unused`` says what it is predicted at: ``"zero"`` (the user is predicted not to move
in it, so at the first switch to rotation mode a watch expects no input and no evidence), or
``"deflection"``: at the other part's deflection, the stick held as far in this mode as in the other,
``v_j / s_j x s_i`` with ``s`` the twist of a full deflection (``input.linear_scale_mps``,
``input.angular_scale_radps``); the part's own average starts from that value at its first tick and then
runs as above (a pause in the new mode decays it as any pause). Before any input both are 0.
"""

from __future__ import annotations

import math
from typing import Literal

import numpy as np

from ..geometry import FloatArray

MAX_TICK_S = 0.1
"""The longest interval one tick is weighed as (s)."""


class UserSpeed:
    """The user's smoothed ``(linear m/s, angular rad/s)`` speed, per part (module doc)."""

    def __init__(self, tau_s: float, idle: Literal["decay", "hold"] = "decay",
                 unused: Literal["zero", "deflection"] = "zero", scale: tuple[float, float] = (1.0, 1.0)) -> None:
        if not (tau_s > 0 and math.isfinite(tau_s)):
            raise ValueError("tau_s must be a finite number > 0 (s)")
        if not all(s > 0 and math.isfinite(s) for s in scale):
            raise ValueError("scale must be two finite numbers > 0 (m/s, rad/s at full deflection)")
        self._tau, self._idle, self._unused = tau_s, idle, unused
        self._scale = np.asarray(scale, dtype=float)
        self.reset()

    def reset(self) -> None:
        """A new task: no input seen in either part."""
        self._v = np.zeros(2)
        self._entered = np.zeros(2, dtype=bool)
        self._t = -math.inf

    @property
    def entered(self) -> tuple[bool, bool]:
        """Whether the user has been in translation, in rotation mode in this task (a tick in it)."""
        return bool(self._entered[0]), bool(self._entered[1])

    @property
    def value(self) -> tuple[float, float]:
        """The predicted speed ``(linear m/s, angular rad/s)``: each part's average, or for a part whose mode
        has not been entered its prediction by ``unused`` (module doc)."""
        v = self._v.copy()
        for i in (0, 1):
            if not self._entered[i]:
                v[i] = self._unused_speed(i)
        return float(v[0]), float(v[1])

    def _unused_speed(self, i: int) -> float:
        """Part ``i``'s prediction before its mode is entered (module doc)."""
        j = 1 - i
        if self._unused == "deflection" and self._entered[j]:
            return float(self._v[j] / self._scale[j] * self._scale[i])
        return 0.0

    def update(self, twist: FloatArray, part: int, t: float) -> None:
        """Average in the user's twist ``(6,)`` (m/s, rad/s) at ``t`` (s), driving part ``part`` (0: linear,
        1: angular: the current mode)."""
        dt = min(max(t - self._t, 0.0), MAX_TICK_S)
        self._t = t
        k = 1.0 - math.exp(-dt / self._tau)
        speed = float(np.linalg.norm(np.asarray(twist, dtype=float)[3 * part:3 * part + 3]))
        if not self._entered[part]:
            self._v[part] = self._unused_speed(part)  # the average starts from the part's prediction
            self._entered[part] = True
        if speed > 0.0 or self._idle == "decay":
            self._v[part] += k * (speed - self._v[part])
