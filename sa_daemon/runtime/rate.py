"""Fixed-rate ticks for asyncio loops, with period statistics.

Why not ``loop_rate_limiters.AsyncRateLimiter`` (the well-kept choice, measured here on 2 cores):
it waits by polling ``asyncio.sleep(1e-5)`` and then spins for the last 0.5 ms, and it schedules the
next tick from the time the current one woke, so a late tick shifts every later one. On CPython's
default epoll loop (millisecond timeouts) its 100 Hz period error was p99 0.66 ms at 8 % of a core; on a
microsecond-precise ``select`` loop its polling took 42 % of a core. :class:`FixedRate` keeps an absolute
grid (tick ``k`` is due at ``t0 + k * period``), sleeps once to ``spin_s`` before the tick and spins only
that last bit, and counts overruns and skipped ticks so the daemon can publish them. Its precision comes
from :func:`new_event_loop`, whose ``select``-based selector honours sub-millisecond timeouts.
"""

from __future__ import annotations

import asyncio
import selectors
import time
from dataclasses import dataclass, field

import numpy as np


def new_event_loop() -> asyncio.AbstractEventLoop:
    """An event loop whose timers are precise to microseconds.

    CPython 3.11's epoll selector rounds every timeout up to a whole millisecond, which alone makes a
    100 Hz loop jitter by up to 1 ms; ``select(2)`` takes a ``timeval``. The daemon has a handful of
    file descriptors, far below ``select``'s 1024 limit.
    """
    return asyncio.SelectorEventLoop(selectors.SelectSelector())


class Ring:
    """The last ``size`` samples in a preallocated float array: memory is constant from the first
    sample, however long the daemon runs (a soak measures RSS growth; a growing list would show)."""

    def __init__(self, size: int) -> None:
        if size < 1:
            raise ValueError("a ring needs room for at least one sample")
        self._buf = np.zeros(size)
        self._n = 0

    def append(self, value: float) -> None:
        self._buf[self._n % self._buf.size] = value
        self._n += 1

    def values(self) -> np.ndarray:
        """A copy of the kept samples (oldest first is not guaranteed: they are for statistics)."""
        return self._buf[: len(self)].copy()

    def clear(self) -> None:
        self._n = 0

    def __len__(self) -> int:
        return min(self._n, self._buf.size)


#: Overrun times a :class:`PeriodStats` keeps (the latest; older ones are only counted).
OVERRUN_TIMES_KEPT = 100


@dataclass
class PeriodStats:
    """Tick-to-tick periods of one loop (the last ``keep`` in a :class:`Ring`, for percentiles)."""

    nominal_s: float
    keep: int = 20000
    periods_s: Ring = field(init=False)
    ticks: int = 0
    overruns: int = 0  # periods longer than 1.5 x nominal
    skipped: int = 0  # whole ticks missed because a tick ran late
    #: When the last overruns ended (``time.monotonic`` s, at most :data:`OVERRUN_TIMES_KEPT`), to set
    #: them beside other logs: the machine's own latency, a fault, a question.
    overrun_at: Ring = field(init=False)

    def __post_init__(self) -> None:
        self.periods_s = Ring(self.keep)
        self.overrun_at = Ring(OVERRUN_TIMES_KEPT)

    def add(self, period_s: float, at: float | None = None) -> None:
        """Count one period (s) that ended at ``at`` (``time.monotonic`` s, when known)."""
        self.ticks += 1
        if period_s > 1.5 * self.nominal_s:
            self.overruns += 1
            if at is not None:
                self.overrun_at.append(at)
        self.periods_s.append(period_s)

    def summary(self) -> dict[str, float]:
        """``rate_hz``, period error percentiles (ms) and the overrun fraction."""
        p = self.periods_s.values()
        if p.size == 0:
            return {"rate_hz": 0.0, "period_err_ms_p50": 0.0, "period_err_ms_p99": 0.0, "period_err_ms_max": 0.0,
                    "overrun_fraction": 0.0, "skipped": float(self.skipped)}
        err = np.abs(p - self.nominal_s) * 1e3
        return {
            "rate_hz": float(1.0 / p.mean()),
            "period_err_ms_p50": float(np.percentile(err, 50)),
            "period_err_ms_p99": float(np.percentile(err, 99)),
            "period_err_ms_max": float(err.max()),
            "overrun_fraction": self.overruns / max(1, self.ticks),
            "skipped": float(self.skipped),
        }


class FixedRate:
    """Await :meth:`tick` once per cycle to run at ``hz`` on a fixed time grid.

    A tick that is more than one period late is not made up for: the grid jumps to the next future
    slot (``skipped`` counts the lost ticks), so a stall never causes a burst of catch-up ticks.
    """

    def __init__(self, hz: float, spin_s: float = 2e-4, start: float | None = None) -> None:
        """``start`` (``time.monotonic`` s) places the grid: loops given starts a few ms apart never
        fall due together, so a tick's work never delays another loop's tick (default: the first
        call to :meth:`tick`)."""
        if not hz > 0:
            raise ValueError("rate must be positive (Hz)")
        self.period_s = 1.0 / hz
        self.spin_s = spin_s
        self.stats = PeriodStats(self.period_s)
        self._next: float | None = None if start is None else start - self.period_s
        self._last: float | None = None

    @property
    def dt(self) -> float:
        """The nominal period (s)."""
        return self.period_s

    def reset_stats(self) -> None:
        """Start the figures afresh: the next tick starts a period instead of closing one, so a
        start-up pause before it (a full garbage collection) is not counted as the running loop's."""
        self.stats = PeriodStats(self.period_s)
        self._last = None

    async def tick(self) -> float:
        """Sleep until the next grid point; return the time (``time.monotonic``, s) it was reached."""
        now = time.monotonic()
        if self._next is None:
            self._next = now
        else:
            self._next += self.period_s
            if now - self._next > self.period_s:
                missed = int((now - self._next) // self.period_s)
                self.stats.skipped += missed
                self._next += missed * self.period_s
        wait = self._next - now - self.spin_s
        if wait > 0:
            await asyncio.sleep(wait)
        while time.monotonic() < self._next:
            pass
        now = time.monotonic()
        if self._last is not None:
            self.stats.add(now - self._last, now)
        self._last = now
        return now
