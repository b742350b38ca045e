"""The compiled rollouts (:func:`.kernel.roll`) split over threads.

:func:`.kernel.roll` releases the GIL and computes each rollout alone, so a plan's rollouts can be cut
into blocks and shared by threads with outputs that do not depend on the cut. This thread and a
process-wide pool take the blocks from one queue.
"""

from __future__ import annotations

import itertools
import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from ..config import Config
from ..cores import cores
from ..geometry import FloatArray
from .kernel import roll


def roll_split(threads: int, inputs: tuple, outputs: tuple[FloatArray, ...]) -> None:
    """:func:`.kernel.roll` over ``threads`` threads (it releases the GIL): this thread and a process-wide pool
    take blocks of rollouts from one queue until none is left. Many starts are cut into blocks of starts
    (``BLOCKS_PER_THREAD`` a thread, so a thread that finishes early takes another), few into one block of
    the user's goals a thread. ``inputs`` are :func:`.kernel.roll`'s inputs up to ``rp``, ``outputs`` its six
    outputs. Each rollout is computed alone, so the outputs do not depend on the blocks (what a block
    shares between its rollouts it computes itself)."""
    C, G = len(inputs[0]), len(inputs[3])  # positions, kp
    n = max(1, threads)
    if C >= 2 * n:
        edges = np.linspace(0, C, min(C, BLOCKS_PER_THREAD * n) + 1).round().astype(int)
        blocks = [(lo, hi, 0, G) for lo, hi in itertools.pairwise(edges)]
    else:
        edges = np.linspace(0, G, min(G, n) + 1).round().astype(int)
        blocks = [(0, C, lo, hi) for lo, hi in itertools.pairwise(edges)]
    if len(blocks) == 1 or n == 1:
        for block in blocks:
            roll(*inputs, *block, *outputs)
        return
    queue = iter(blocks)  # next() on it is atomic under the GIL: each block is taken once

    def work() -> None:
        for block in queue:
            roll(*inputs, *block, *outputs)

    futures = [_pool(n - 1).submit(work) for _ in range(min(n, len(blocks)) - 1)]
    work()
    for f in futures:
        f.result()


BLOCKS_PER_THREAD = 4
"""Blocks of starts a thread takes on average in :func:`roll_split` (more: better balance, more calls)."""

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
