"""FixedRate and PeriodStats on the daemon's own event loop (``rate.new_event_loop``)."""

from __future__ import annotations

import asyncio
import time
from itertools import pairwise

import pytest

from sa_daemon.runtime.rate import FixedRate, PeriodStats, new_event_loop

SUMMARY_KEYS = {"rate_hz", "period_err_ms_p50", "period_err_ms_p99", "period_err_ms_max", "overrun_fraction", "skipped"}


def _run(coro):
    loop = new_event_loop()
    try:
        return loop.run_until_complete(coro)
    finally:
        loop.close()


def _busy(seconds: float) -> None:
    end = time.perf_counter() + seconds
    while time.perf_counter() < end:
        pass


def test_new_event_loop_is_a_select_loop():
    loop = new_event_loop()
    try:
        assert isinstance(loop, asyncio.SelectorEventLoop)
        assert type(loop._selector).__name__ == "SelectSelector"  # sub-millisecond timeouts
    finally:
        loop.close()


def test_rate_must_be_positive():
    for hz in (0, -5, float("nan")):
        with pytest.raises(ValueError):
            FixedRate(hz)


def test_ticks_stay_on_the_fixed_grid_despite_work_per_tick():
    """Each tick does 3 ms of work at 50 Hz: a limiter that sleeps one period after the work would run
    at ~43 Hz (14 % slow); the fixed grid keeps the mean rate at 50 Hz and never ticks before a grid point."""
    hz, n = 50.0, 40
    period = 1.0 / hz

    async def main():
        r = FixedRate(hz)
        out = []
        for _ in range(n):
            t = await r.tick()
            out.append((t, r.stats.skipped))
            _busy(0.003)
        return r, out

    r, out = _run(main())
    last_t, last_skipped = out[-1]
    origin = r._next - (n - 1 + last_skipped) * period  # grid point 0 (the first tick's slot)
    t0 = out[0][0]
    for i, (t, skipped) in enumerate(out):
        grid = origin + (i + skipped) * period  # the grid point this tick belongs to
        assert t >= grid - 1e-6, f"tick {i} came {grid - t:.6f} s before its grid point"
    grid_rate = (n - 1 + last_skipped) / (last_t - t0)
    assert grid_rate == pytest.approx(hz, rel=0.05)
    # The published rate counts the ticks that ran: equal to nominal when none was skipped.
    s = r.stats.summary()
    assert r.stats.ticks == n - 1
    assert s["rate_hz"] == pytest.approx(hz * (n - 1) / (n - 1 + last_skipped), rel=0.05)
    assert r.dt == pytest.approx(period)


def test_a_stall_skips_ticks_instead_of_bursting():
    hz = 100.0
    period = 1.0 / hz

    async def main():
        r = FixedRate(hz)
        for _ in range(5):
            await r.tick()
        before = r.stats.skipped
        time.sleep(6 * period)  # noqa: ASYNC251 - a blocking call stalls the loop for six periods
        after_stall = []
        for _ in range(6):
            after_stall.append(await r.tick())
        return r, before, after_stall

    r, before, ticks = _run(main())
    assert r.stats.skipped - before >= 4  # the lost slots are counted ...
    # ... and not made up for: the first tick after the stall is immediate, then one per period (a burst
    # would deliver the lost ticks at once, all six within a fraction of a period).
    span = ticks[-1] - ticks[0]
    assert span >= (len(ticks) - 2.5) * period, f"burst of catch-up ticks: {[b - a for a, b in pairwise(ticks)]}"
    assert r.stats.overruns >= 1  # the stalled period itself is an overrun
    assert r.stats.summary()["skipped"] == float(r.stats.skipped)


def test_a_pause_before_a_stats_reset_is_not_counted_after_it():
    """The daemon resets its figures once running, right after a full garbage collection: that pause
    belongs to start-up, not to the first period of the running loop."""

    async def main():
        r = FixedRate(100.0)
        for _ in range(3):
            await r.tick()
        time.sleep(0.05)  # noqa: ASYNC251 - the start-up pause
        r.reset_stats()
        for _ in range(5):
            await r.tick()
        return r

    r = _run(main())
    assert r.stats.overruns == 0 and r.stats.ticks == 4  # 5 ticks close 4 periods
    assert max(r.stats.periods_s.values()) < 0.015


def test_period_stats_counts_overruns_and_summarises():
    st = PeriodStats(nominal_s=0.01)
    for p in (0.010, 0.011, 0.0149, 0.0151, 0.030, 0.009):
        st.add(p)
    st.skipped = 2
    assert st.ticks == 6
    assert st.overruns == 2  # > 1.5 x nominal: 15.1 ms and 30 ms
    s = st.summary()
    assert set(s) == SUMMARY_KEYS
    assert s["overrun_fraction"] == pytest.approx(2 / 6)
    assert s["skipped"] == 2.0
    assert s["rate_hz"] == pytest.approx(1.0 / (sum((0.010, 0.011, 0.0149, 0.0151, 0.030, 0.009)) / 6))
    assert s["period_err_ms_max"] == pytest.approx(20.0)
    assert s["period_err_ms_p50"] == pytest.approx(2.95)  # errors 0, 1, 1, 4.9, 5.1, 20 ms
    assert 0 <= s["period_err_ms_p50"] <= s["period_err_ms_p99"] <= s["period_err_ms_max"]


def test_empty_stats_summary_has_the_same_keys():
    st = PeriodStats(nominal_s=0.01)
    st.skipped = 3
    s = st.summary()
    assert set(s) == SUMMARY_KEYS
    assert s["rate_hz"] == 0.0 and s["overrun_fraction"] == 0.0
    assert s["skipped"] == 3.0


def test_period_ring_is_bounded():
    st = PeriodStats(nominal_s=0.01, keep=100)
    for _ in range(1000):
        st.add(0.01)
    assert st.ticks == 1000
    assert len(st.periods_s) == 100
    assert st.summary()["rate_hz"] == pytest.approx(100.0)
    for _ in range(100):  # the ring holds the latest samples only
        st.add(0.02)
    assert st.summary()["rate_hz"] == pytest.approx(50.0)


def test_ring_memory_is_fixed_and_it_keeps_the_last_samples():
    from sa_daemon.runtime.rate import Ring

    r = Ring(4)
    buf = r._buf
    assert len(r) == 0 and r.values().size == 0
    for v in range(10):
        r.append(float(v))
    assert r._buf is buf and buf.size == 4  # no reallocation however many samples arrive
    assert sorted(r.values().tolist()) == [6.0, 7.0, 8.0, 9.0]
    r.clear()
    assert len(r) == 0
    with pytest.raises(ValueError):
        Ring(0)


def test_overruns_keep_when_they_ended_the_latest_only():
    from sa_daemon.runtime.rate import OVERRUN_TIMES_KEPT, PeriodStats

    s = PeriodStats(0.01)
    s.add(0.010, at=1.0)
    s.add(0.016, at=2.0)  # an overrun: > 1.5 periods
    s.add(0.015, at=3.0)  # exactly 1.5 periods is not
    s.add(0.020)  # an overrun whose time is unknown is counted only
    assert s.overruns == 2 and list(s.overrun_at.values()) == [2.0]
    for k in range(OVERRUN_TIMES_KEPT + 5):
        s.add(0.03, at=10.0 + k)
    kept = sorted(s.overrun_at.values())
    assert s.overruns == OVERRUN_TIMES_KEPT + 7 and len(kept) == OVERRUN_TIMES_KEPT
    assert kept[-1] == 10.0 + OVERRUN_TIMES_KEPT + 4  # the newest survive
