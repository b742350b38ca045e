"""Real-time scheduling for the daemon's event-loop thread (``runtime.realtime_priority``) and its
share of the interpreter lock (``runtime.gil_switch_interval_s``).

On a 2-core wheelchair computer the event loop shares the CPUs with ZeroMQ's I/O thread, the planner
worker, speech and the rest of the system; under the default time-sharing policy a tick is sometimes
started 5-20 ms late because another runnable thread had the core. ``SCHED_FIFO`` lets the loop preempt
them whenever a tick is due; it sleeps between ticks, so the rest of the system keeps the CPUs.

Only the calling thread changes. ``SCHED_RESET_ON_FORK`` makes every thread and process created after
that (a restarted planner worker, the executor's threads) start with the normal policy again, so the
CPU-heavy planner can never run at real-time priority. Setting it needs root or ``LimitRTPRIO`` (the
systemd unit grants it); without permission the daemon runs on with the normal policy and says why.

A real-time policy does not help while the loop waits for the GIL. The daemon's helper threads (speech,
recording, console, xArm I/O) run Python too, and a thread that wants the GIL back waits until the one
holding it has run for ``sys.getswitchinterval()`` (5 ms by default) before it can ask for a hand-over.
One such wait makes a 10 ms tick 5 ms late; two make an overrun. A short interval bounds the wait; it
costs a few more hand-overs per second between busy threads, nothing when only one thread runs. Measured
on this machine (``docs/safety.md``): a helper thread computing in 20 ms bursts gave a 100 Hz loop
overruns in 10 % of its periods at 5 ms, none at 1 ms or 0.5 ms.
"""

from __future__ import annotations

import os
import sys


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


def set_switch_interval(interval_s: float) -> float:
    """Set the interpreter's thread switch interval (s); return the previous one, to restore it."""
    previous = sys.getswitchinterval()
    sys.setswitchinterval(interval_s)
    return previous
