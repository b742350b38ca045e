"""The planner worker: a real spawned process, answered over its pipe, killed, stopped and replaced."""

from __future__ import annotations

import asyncio
import os
import signal
import time

import numpy as np
import pytest
from helpers import process_gone

from sa_daemon.config import Config
from sa_daemon.model.actions import ActionKind, Mode
from sa_daemon.model.model import SharedAutonomyModel
from sa_daemon.planner.snapshot import PlanResult, Snapshot
from sa_daemon.planner.worker import PlannerWorker, PlanReply
from sa_daemon.world.scene import load_scene

START_TIMEOUT_S = 60.0  # a spawned interpreter importing numpy/scipy on a loaded 2-core machine


def _snapshot(**kw) -> Snapshot:
    scene = load_scene("scene1")
    belief = SharedAutonomyModel(Config()).initial_belief(scene.goals)
    return Snapshot(belief.goals, belief.probs, scene.start, np.zeros(6), Mode.TRANSLATION, frozenset(), "policy",
                    budget_s=0.1, **kw)


class Harness:
    def __init__(self) -> None:
        self.replies: asyncio.Queue = asyncio.Queue()
        self.exits = 0
        self.worker = PlannerWorker(Config().model_dump(mode="json"), self.replies.put_nowait, self._on_exit)

    def _on_exit(self) -> None:
        self.exits += 1

    async def ready(self, timeout_s: float = START_TIMEOUT_S) -> None:
        end = time.monotonic() + timeout_s
        while not self.worker.ready:
            assert time.monotonic() < end, "worker did not say hello"
            await asyncio.sleep(0.02)

    async def plan(self, snap: Snapshot, timeout_s: float = 30.0) -> PlanReply | str:
        assert self.worker.request(snap)
        return await asyncio.wait_for(self.replies.get(), timeout_s)


@pytest.fixture
async def harness():
    h = Harness()
    h.worker.start()
    try:
        yield h
    finally:
        h.worker.stop()


async def test_worker_answers_a_snapshot_with_a_plan(harness):
    w = harness.worker
    assert w.pid is not None and w.pid != os.getpid()
    await harness.ready()
    assert w.request(_snapshot())
    reply = await asyncio.wait_for(harness.replies.get(), 30.0)
    assert isinstance(reply, PlanReply), reply
    assert isinstance(reply.result, PlanResult)
    assert reply.result.action.kind in set(ActionKind)
    assert reply.solve_ms > 0
    assert reply.round_trip_ms >= reply.solve_ms - 0.01  # the round trip contains the solve
    assert w.in_flight is None
    # One request at a time: a second one is refused while the first is in flight.
    assert w.request(_snapshot())
    assert not w.request(_snapshot())
    reply2 = await asyncio.wait_for(harness.replies.get(), 30.0)
    assert isinstance(reply2, PlanReply) and reply2.seq == reply.seq + 1


async def test_a_failing_plan_is_reported_and_the_worker_lives_on(harness):
    await harness.ready()
    bad = _snapshot(node_budget=10)
    object.__setattr__(bad, "method", "no-such-method")  # the solver raises on it
    reply = await harness.plan(bad)
    assert isinstance(reply, str) and reply.startswith("plan failed:")
    assert harness.worker.alive
    assert isinstance(await harness.plan(_snapshot()), PlanReply)


async def test_restart_after_sigkill_gives_a_new_pid_that_answers(harness):
    w = harness.worker
    await harness.ready()
    old = w.pid
    os.kill(old, signal.SIGKILL)
    end = time.monotonic() + 10
    while harness.exits == 0:  # the pipe closes: noticed without any request
        assert time.monotonic() < end, "worker death not noticed"
        await asyncio.sleep(0.01)
    assert not w.alive and not w.ready
    assert not w.request(_snapshot())  # nobody to send to
    w.restart()
    assert w.restarts == 1
    await harness.ready()
    assert w.pid != old and w.alive
    assert isinstance(await harness.plan(_snapshot()), PlanReply)
    assert process_gone(old)


async def test_a_stopped_worker_is_replaced_by_restart(harness):
    w = harness.worker
    await harness.ready()
    old = w.pid
    os.kill(old, signal.SIGSTOP)
    try:
        assert w.request(_snapshot())
        with pytest.raises(asyncio.TimeoutError):
            await asyncio.wait_for(harness.replies.get(), 0.5)  # hung: no answer
        assert w.alive  # alive but silent: only the daemon's deadline can tell
        w.restart()  # SIGKILL works on a stopped process
        end = time.monotonic() + 10
        while not process_gone(old):
            assert time.monotonic() < end, "stopped worker was not killed"
            await asyncio.sleep(0.02)
        assert w.in_flight is None and w.pid != old
        await harness.ready()
        reply = await harness.plan(_snapshot())
        assert isinstance(reply, PlanReply)
        assert harness.replies.empty()  # the old request's answer never arrives late
    finally:
        if not process_gone(old):
            os.kill(old, signal.SIGKILL)


async def test_stop_ends_the_process():
    h = Harness()
    h.worker.start()
    await h.ready()
    pid = h.worker.pid
    h.worker.stop()
    assert not h.worker.alive
    end = time.monotonic() + 10
    while not process_gone(pid):
        assert time.monotonic() < end
        await asyncio.sleep(0.02)
    assert h.exits == 0  # an orderly stop is not reported as a crash
