"""Real-time scheduling for the daemon's event-loop thread (``runtime.realtime_priority``).

On a 2-core wheelchair computer the event loop shares the CPUs with ZeroMQ's I/O thread, the planner
worker, speech and the rest of the system; under the default time-sharing policy a tick is sometimes
started 5-20 ms late because another runnable thread had the core. ``SCHED_FIFO`` lets the loop preempt
them whenever a tick is due; it sleeps between ticks, so the rest of the system keeps the CPUs.

Only the calling thread changes. ``SCHED_RESET_ON_FORK`` makes every thread and process created after
that (a restarted planner worker, the executor's threads) start with the normal policy again, so the
CPU-heavy planner can never run at real-time priority. Setting it needs root or ``LimitRTPRIO`` (the
systemd unit grants it); without permission the daemon runs on with the normal policy and says why.
"""

from __future__ import annotations

import os


def make_realtime(priority: int) -> str | None:
    """Put the calling thread under ``SCHED_FIFO`` at ``priority`` (1-99; 0 does nothing).

    Returns ``None`` on success (or with ``priority`` 0), else why it was not possible.
    """
    if priority <= 0:
        return None
    policy = os.SCHED_FIFO | getattr(os, "SCHED_RESET_ON_FORK", 0)
    try:
        os.sched_setscheduler(0, policy, os.sched_param(priority))
    except OSError as e:
        return f"runtime.realtime_priority {priority}: SCHED_FIFO refused ({e.strerror or e}); running without it"
    return None
