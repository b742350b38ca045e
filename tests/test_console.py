"""The console thread: the event loop's lines are written in order by another thread, and a stream
that blocks never makes the writer wait."""

from __future__ import annotations

import io
import threading
import time

from sa_daemon.runtime.console import Console


class _Stuck(io.StringIO):
    """A stream whose writes block until released, like stderr on a full pipe."""

    def __init__(self) -> None:
        super().__init__()
        self.release = threading.Event()

    def write(self, s: str) -> int:
        self.release.wait()
        return super().write(s)


def test_lines_arrive_in_order_once_closed():
    out = io.StringIO()
    c = Console(out)
    for i in range(200):
        c.write(f"line {i}")
    c.close()
    assert out.getvalue().splitlines() == [f"line {i}" for i in range(200)]
    assert c.dropped == 0


def test_a_blocked_stream_never_blocks_the_writer_and_overflow_is_counted():
    out = _Stuck()
    c = Console(out, max_lines=10)
    t0 = time.perf_counter()
    for i in range(100):
        c.write(f"line {i}")
    took = time.perf_counter() - t0
    assert took < 0.5  # 100 writes against a stream that accepts nothing (they take microseconds)
    assert c.dropped >= 100 - 10 - 1  # the queue holds 10, the thread holds at most one
    out.release.set()
    c.close()
    lines = out.getvalue().splitlines()
    assert lines == [f"line {i}" for i in range(len(lines))]  # what was kept is the first lines, in order


def test_close_is_idempotent_and_bounded_with_a_stuck_stream():
    out = _Stuck()
    c = Console(out, max_lines=2)
    c.write("a")
    time.sleep(0.05)  # the thread takes "a" and blocks in write
    c.write("b")
    c.write("c")  # the queue is full now
    t0 = time.perf_counter()
    c.close(timeout_s=0.2)
    c.close(timeout_s=0.2)
    assert time.perf_counter() - t0 < 2.0
    out.release.set()
