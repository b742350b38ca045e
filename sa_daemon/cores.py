"""The cores this process may run on: the default for worker processes (``sa-daemon eval --jobs``,
``bench voice --jobs``) and rollout threads (``planner.threads = 0``)."""

from __future__ import annotations

import os


def cores() -> int:
    """Cores this process may run on (its CPU affinity mask on Linux; every core elsewhere)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1
