"""The tremor filter: a first-order low-pass on the joystick's three axes (``input.filter_hz``).

``y' = (x - y) / tau`` with ``tau = 1 / (2 pi f_c)``, integrated exactly over each interval for the input
held constant (the kernel reports changes only, so the held value *is* the input):
``y(t + dt) = x + (y(t) - x) exp(-dt / tau)``. Its gain at frequency ``f`` is
``1 / sqrt(1 + (f / f_c)^2)`` and its delay, for inputs well below ``f_c``, is ``tau`` seconds (a 3 Hz
cutoff: 53 ms; a 5 Hz tremor passes at 0.51 of its amplitude). Run at the control rate on the held
stick, it adds half a control period (measured: 58 ms in all at 3 Hz and 100 Hz,
``tests/test_profiles.py``). ``f_c = 0`` is no filter at all.
"""

from __future__ import annotations

import math

import numpy as np

from ..geometry import FloatArray


class LowPass:
    """First-order low-pass of a ``size``-vector, cutoff ``cutoff_hz`` (Hz; 0 = pass through), at rest
    (zero) until the first update."""

    def __init__(self, cutoff_hz: float, size: int = 3) -> None:
        if not (cutoff_hz >= 0 and math.isfinite(cutoff_hz)):
            raise ValueError("cutoff_hz must be a finite number >= 0 (Hz)")
        self._tau = 1.0 / (2.0 * math.pi * cutoff_hz) if cutoff_hz > 0 else 0.0
        self._size = size
        self.reset()

    @property
    def tau_s(self) -> float:
        """The time constant, also the delay for slow inputs (s); 0 without a filter."""
        return self._tau

    def update(self, x: FloatArray, t: float) -> FloatArray:
        """The output at ``t`` (s): the input held since the last update integrated up to ``t``; ``x`` is
        the input from ``t`` on."""
        x = np.asarray(x, dtype=float)
        if self._tau == 0.0:
            return x.copy()
        if self._t is not None:
            dt = max(0.0, t - self._t)
            self._y = self._x + (self._y - self._x) * math.exp(-dt / self._tau)
        self._x, self._t = x.copy(), t
        return self._y.copy()

    def reset(self) -> None:
        """Back to rest: output zero now (a lost device), input zero until the next update."""
        self._y = np.zeros(self._size)
        self._x = np.zeros(self._size)
        self._t: float | None = None
