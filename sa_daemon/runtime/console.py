"""The daemon's console lines (events, progress) written by a thread, never by the event loop.

A ``print`` to stderr blocks when stderr is slow: a file during disk writeback, a full pipe, journald
under load. Measured in a 200 s soak with the event loop under ``SCHED_FIFO``: a 59 ms control period in
which the loop's thread used 0.7 ms of CPU, at the moment it printed a ``question`` event; the rest of
the time it waited in ``write``. So lines go into a bounded queue and one thread writes them; when the
queue is full (the console cannot keep up) lines are dropped and counted, the loop never waits.
"""

from __future__ import annotations

import queue
import sys
import threading
from typing import TextIO

_CLOSE = object()


class Console:
    """Write lines to ``stream`` (default stderr) from a background thread (see module doc)."""

    def __init__(self, stream: TextIO | None = None, max_lines: int = 1000) -> None:
        self.stream = stream if stream is not None else sys.stderr
        self.dropped = 0
        self._q: queue.Queue = queue.Queue(maxsize=max_lines)
        self._thread = threading.Thread(target=self._run, name="sa-console", daemon=True)
        self._thread.start()

    def write(self, line: str) -> None:
        """Queue one line (without its newline); never blocks."""
        try:
            self._q.put_nowait(line)
        except queue.Full:
            self.dropped += 1

    def _run(self) -> None:
        while (line := self._q.get()) is not _CLOSE:
            try:
                self.stream.write(line + "\n")
                self.stream.flush()
            except (OSError, ValueError):  # a closed or broken stream: nothing left to tell
                self.dropped += 1

    def close(self, timeout_s: float = 2.0) -> None:
        """Write what is queued, then stop the thread (waits at most about ``timeout_s``). Idempotent."""
        if self._thread.is_alive():
            try:
                self._q.put(_CLOSE, timeout=timeout_s)
            except queue.Full:
                return
            self._thread.join(timeout_s)
