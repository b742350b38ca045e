"""The planner in a separate, spawned worker process, supervised from the daemon's event loop.

The daemon never waits on the worker: :meth:`PlannerWorker.request` writes one pickled
:class:`~.snapshot.Snapshot` to a pipe and returns; the result arrives through a reader callback on
the pipe's file descriptor. One request is in flight at a time. The process is *spawned* (a fresh
interpreter, not a fork of the loaded daemon with its sockets, threads and arm), says hello with its
pid when ready, and answers each snapshot with ``("plan", seq, PlanResult, ms)`` or
``("error", seq, text)``. The daemon decides when a worker is late, hung or dead and calls
:meth:`restart`.
"""

from __future__ import annotations

import asyncio
import multiprocessing as mp
import time
from collections.abc import Callable
from dataclasses import dataclass
from enum import Enum
from multiprocessing.connection import Connection

from .snapshot import PlanResult, Snapshot


class WorkerStatus(str, Enum):
    """Published as ``planner.status``."""

    IDLE = "idle"  # a rule-based method: no planning needed
    STARTING = "starting"
    OK = "ok"
    LATE = "late"  # the last request missed its deadline; the last action is kept for one period
    RESTARTING = "restarting"  # killed (hung or dead) and being replaced
    FAILED = "failed"  # the last plan raised; the daemon falls back to no-assist


def _worker_main(conn: Connection, cfg_data: dict) -> None:
    """Entry point of the worker process: build the solver, then answer snapshots until EOF/None."""
    import os

    from ..config import config_from_dict
    from ..model.model import SharedAutonomyModel
    from .kernel import warm_up
    from .solver import Solver

    cfg = config_from_dict(cfg_data, "planner worker")
    # Below the daemon's priority: when both share a core, the scheduler lets the control loop run
    # first (the planner is anytime and has a deadline anyway).
    try:
        os.nice(cfg.runtime.worker_nice)
    except OSError:
        pass
    solver = Solver(SharedAutonomyModel(cfg))
    warm_up(cfg)  # compiled on this machine's first run (seconds), loaded from numba's cache after
    try:
        conn.send(("hello", os.getpid()))
        while True:
            try:
                msg = conn.recv()
            except (EOFError, OSError):
                return
            if msg is None:
                return
            seq, snap = msg
            t0 = time.perf_counter()
            try:
                result = solver.plan(snap)
            except Exception as e:  # noqa: BLE001 - any failure is reported, the worker lives on
                conn.send(("error", seq, f"{type(e).__name__}: {e}"))
                continue
            conn.send(("plan", seq, result, (time.perf_counter() - t0) * 1e3))
    except OSError:  # BrokenPipeError: the daemon stopped or replaced us meanwhile
        return


@dataclass
class PlanReply:
    """A plan received from the worker: request ``seq``, the snapshot it was computed on (its goal set is
    the one the result's move indexes), the result, solve time (ms) and the round-trip time (request to
    receipt, ms)."""

    seq: int
    snapshot: Snapshot
    result: PlanResult
    solve_ms: float
    round_trip_ms: float


class PlannerWorker:
    """Parent-side handle of one planner process (see module doc). Use from the event loop only."""

    def __init__(
        self,
        cfg_data: dict,
        on_reply: Callable[[PlanReply | str], None],
        on_exit: Callable[[], None] = lambda: None,
    ) -> None:
        """``on_reply`` receives each plan (or an error text); ``on_exit`` is called when the pipe
        closes because the process died."""
        self._cfg_data = cfg_data
        self._on_reply = on_reply
        self._on_exit = on_exit
        self._ctx = mp.get_context("spawn")
        self._proc: mp.process.BaseProcess | None = None
        self._conn: Connection | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self.pid: int | None = None
        self.ready = False
        self.restarts = 0
        self.started_at = 0.0
        self._seq = 0
        self.in_flight: tuple[int, float, Snapshot] | None = None  # (seq, sent at time.monotonic s, snapshot)

    # -- lifecycle -------------------------------------------------------------------------------------

    def start(self) -> None:
        """Spawn the process (returns at once; ``ready`` turns true on its hello)."""
        self._loop = asyncio.get_running_loop()
        parent, child = self._ctx.Pipe(duplex=True)
        proc = self._ctx.Process(target=_worker_main, args=(child, self._cfg_data), daemon=True, name="sa-planner")
        proc.start()
        child.close()
        self._proc, self._conn = proc, parent
        self.pid, self.ready, self.in_flight = proc.pid, False, None
        self.started_at = time.monotonic()
        self._loop.add_reader(parent.fileno(), self._readable)

    def _detach(self) -> None:
        if self._conn is not None and self._loop is not None:
            self._loop.remove_reader(self._conn.fileno())
            self._conn.close()
        self._conn = None

    def stop(self, timeout_s: float = 1.0) -> None:
        """Ask the worker to exit, then kill it if it does not (blocks at most ``timeout_s``)."""
        proc = self._proc
        if self._conn is not None:
            try:
                self._conn.send(None)
            except (OSError, BrokenPipeError):
                pass
        self._detach()
        if proc is not None:
            proc.join(timeout_s)
            if proc.is_alive():
                proc.kill()
                proc.join(1.0)
        self._proc, self.ready, self.in_flight = None, False, None

    def reconfigure(self, cfg_data: dict) -> None:
        """Plan with a new configuration from now on: a new process (the old one is killed)."""
        self._cfg_data = cfg_data
        self.restart()

    def restart(self) -> None:
        """Kill the current process at once (hung or dead) and spawn a new one."""
        self._detach()
        if self._proc is not None and self._proc.is_alive():
            self._proc.kill()
            self._proc.join(1.0)
        self.restarts += 1
        self.start()

    @property
    def alive(self) -> bool:
        return self._proc is not None and self._proc.is_alive() and self._conn is not None

    # -- requests --------------------------------------------------------------------------------------

    def request(self, snap: Snapshot) -> bool:
        """Send ``snap`` unless the worker is not ready or a request is in flight; ``True`` if sent."""
        if not self.ready or self.in_flight is not None or self._conn is None:
            return False
        self._seq += 1
        sent = time.monotonic()  # before the write: the woken worker may run before we get the CPU back
        try:
            self._conn.send((self._seq, snap))
        except (OSError, BrokenPipeError):
            return False
        self.in_flight = (self._seq, sent, snap)
        return True

    def _readable(self) -> None:
        conn = self._conn
        if conn is None:
            return
        try:
            while conn.poll():
                self._handle(conn.recv())
        except (EOFError, OSError):
            self._detach()  # the process died
            self.ready, self.in_flight = False, None
            self._on_exit()

    def _handle(self, msg: tuple) -> None:
        if msg[0] == "hello":
            self.pid, self.ready = int(msg[1]), True
            return
        seq = msg[1]
        if self.in_flight is None or seq != self.in_flight[0]:
            return  # an answer to a request given up on
        _, sent, snap = self.in_flight
        self.in_flight = None
        if msg[0] == "plan":
            self._on_reply(PlanReply(seq, snap, msg[2], float(msg[3]), (time.monotonic() - sent) * 1e3))
        else:
            self._on_reply(f"plan failed: {msg[2]}")
