"""The compiled rollouts (:func:`.kernel.roll`) split over threads.

:func:`.kernel.roll` releases the GIL and computes each rollout alone, so a plan's rollouts can be cut
into pieces and shared by threads with outputs that do not depend on the cut. Many start poses are
shared one start at a time: each thread walks the starts from its own place round the ring and claims
every start it finds unclaimed (inside :func:`.kernel.roll`), all in compiled code, so a thread never waits for
the GIL between starts and the calling thread may do other work meanwhile (:meth:`Pending.join` later).
Few starts are cut into blocks of the user's goals taken from one queue.
"""

from __future__ import annotations

import itertools
import os
import threading
from concurrent.futures import Future, ThreadPoolExecutor

import numpy as np

from ..config import Config
from ..cores import cores
from ..geometry import FloatArray
from .kernel import roll


class Pending:
    """:func:`.kernel.roll` over ``threads`` threads (it releases the GIL): ``threads - 1`` of a process-wide
    pool start now, this thread takes its share at :meth:`join`, which returns when every rollout is done.
    ``inputs`` are :func:`.kernel.roll`'s inputs up to ``rp``, ``outputs`` its six outputs. ``background``:
    this thread will run Python before joining, so the pool's threads are let into compiled code first
    (else they would wait for the GIL). Each rollout is computed alone, so the outputs do not depend on
    the cut."""

    def __init__(self, threads: int, inputs: tuple, outputs: tuple[FloatArray, ...], background: bool = False) -> None:
        self._inputs, self._outputs = inputs, outputs
        C, G = self._C, self._G = len(inputs[0]), len(inputs[3])  # positions, kp
        n = max(1, threads)
        self._futures: list[Future] = []
        self._claimed: np.ndarray | None = None
        if C >= 2 * n:  # one start at a time: the pool's threads forward from evenly spaced starts, this one
            # backward from the last (where it meets them latest)
            self._claimed = np.zeros(C, dtype=np.bool_)
            ring = np.arange(C)
            work = [self._starts_work(np.roll(ring, -(k * C // (n - 1)))) for k in range(n - 1)]
            self._own = ring[::-1].copy()
        else:  # few starts: blocks of the user's goals from one queue
            edges = np.linspace(0, G, min(G, n) + 1).round().astype(int)
            self._queue = itertools.pairwise(edges)  # next() on it is atomic under the GIL: each block taken once
            work = [self._block_work] * (min(n, len(edges) - 1) - 1)
        if not work:
            return
        started = [threading.Event() for _ in work]
        pool = _pool(n - 1)
        for fn, ev in zip(work, started, strict=True):
            self._futures.append(pool.submit(_signal_then, ev, fn))
        if background:  # let them reach compiled code before this thread goes back to Python, rolling out
            # starts meanwhile (a thread wakes in about 0.1 ms, about what a start takes)
            taken = 0
            while self._claimed is not None and taken < C and not all(ev.is_set() for ev in started):
                self._roll(self._own[taken:taken + 1], self._claimed, 0, G)
                taken += 1
            for ev in started:
                ev.wait()

    def _starts_work(self, order: np.ndarray):
        return lambda: self._roll(order, self._claimed, 0, self._G)

    def _roll(self, order: np.ndarray, claimed: np.ndarray, g_lo: int, g_hi: int) -> None:
        roll(*self._inputs, order, claimed, g_lo, g_hi, *self._outputs)

    def _block_work(self) -> None:
        for lo, hi in self._queue:  # every start, for the block's goals
            self._roll(np.arange(self._C), np.zeros(self._C, dtype=np.bool_), int(lo), int(hi))

    def join(self) -> None:
        """Take this thread's share, then wait for the others (idempotent)."""
        if self._claimed is not None:
            self._roll(self._own, self._claimed, 0, self._G)
        else:
            self._block_work()
        for f in self._futures:
            f.result()
        self._futures = []

    def cancel(self) -> None:
        """Claim every start left and wait for the starts in progress: the outputs are not to be read."""
        if self._claimed is not None:
            self._claimed[:] = True
        else:
            for _ in self._queue:
                pass
        for f in self._futures:
            f.result()
        self._futures = []


def _signal_then(event: threading.Event, fn) -> None:
    event.set()
    fn()


_POOL: list[tuple[int, ThreadPoolExecutor]] = []
"""The process's rollout threads and their number (made on first use, replaced by a larger pool if asked)."""
if hasattr(os, "register_at_fork"):  # a forked child has none of the parent's threads: it makes its own pool
    os.register_at_fork(after_in_child=_POOL.clear)


def _pool(workers: int) -> ThreadPoolExecutor:
    """The pool, with at least ``workers`` threads."""
    if not _POOL or _POOL[0][0] < workers:
        _POOL[:] = [(workers, ThreadPoolExecutor(max_workers=workers, thread_name_prefix="sa-rollouts"))]
    return _POOL[0][1]


def threads(cfg: Config) -> int:
    """``planner.threads``, 0 read as one per core this process may use."""
    return cfg.planner.threads or cores()
