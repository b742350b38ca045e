"""The simulated user's tasks inside the running daemon (``--input sim``).

Every belief tick the user (``siminput.py``) looks at the arm and moves its stick, answers a pending
question after ``sim_user.answer_delay_s``, and closes the gripper at its goal. A task ends with the close
or at ``sim_user.timeout_s``; one second later the arm is reset to the start (rebuilt if it cannot reset),
the controller starts a fresh task, and the next task of the list begins. With ``exit_when_done`` and no
duration the daemon stops once every task has been done once.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from ..model.actions import Mode
from .siminput import SimInput

if TYPE_CHECKING:
    from .daemon import Daemon

TASK_PAUSE_S = 1.0
"""Between a task's end and the next one's start (s): the grasp stays visible on the page and in a
recording."""


class SimTasks:
    """Runs ``sim``'s tasks back to back on daemon ``d``; ``done`` lists the finished ones."""

    def __init__(self, d: Daemon, sim: SimInput) -> None:
        self._d, self.sim = d, sim
        self.done: list[dict[str, Any]] = []
        self._next_at: float | None = None  # time.monotonic() s

    @property
    def task(self) -> str | None:
        return self.sim.task

    def begin(self) -> None:
        """Start the next task from the arm's current pose."""
        d = self._d
        assert d.arm_state is not None
        self.sim.next_task(d.arm_state.pose, d.now())
        d.event("task", task=self.sim.task)

    def tick(self, mono: float) -> None:
        """One belief tick of the user (``mono``: ``time.monotonic()`` s). The first task begins once the
        daemon is ready (planner worker, speech and voice up): until then the user's hand is off the stick,
        so a task's time and assistance are those of the running daemon, not of its start-up."""
        d, sim = self._d, self.sim
        assert d.arm_state is not None
        if sim.task is None:  # the daemon begins the first task as it announces ready, if the arm was up
            if not d.ready:
                return
            self.begin()
        if self._next_at is not None:
            if mono >= self._next_at:
                self._turn_over()
            return
        pose = d.arm_state.pose
        q = d.ctl.question
        if q is not None and sim.answers_by(q.qid, q.asked_at, mono):
            d.asker.answer(sim.answer(q.target), source="sim")
        s = sim.sample(pose, listening=d.ctl.question is not None, blocked=d.ctl.last.refused)
        timed_out = d.now() - sim.task_started > d.cfg.sim_user.timeout_s
        if s.close or timed_out:
            d.set_axes(np.zeros(3), mono)
            if s.close:
                d.set_gripper(True)
            outcome = sim.outcome(pose if s.close else None)
            done = {"task": sim.task, "success": outcome.success, "failure": outcome.reason, "failure_kind": outcome.kind,
                    "time_s": round(d.now() - sim.task_started, 3), "questions": len(d.ctl.asked),
                    "timed_out": timed_out and not s.close}
            self.done.append(done)
            d.event("task_done", **done)
            self._next_at = mono + TASK_PAUSE_S
            return
        d.set_mode(s.mode)
        d.set_axes(s.axes, mono)

    def _turn_over(self) -> None:
        d = self._d
        self._next_at = None
        if d.opts.exit_when_done and d.opts.duration_s is None and len(self.done) >= len(self.sim.tasks):
            d.request_stop("all tasks done")
            return
        if d.pending_scene is not None:  # a scene from perception, sent for this task
            d.apply_scene(*d.pending_scene)
        d.reset_arm()
        had_question = d.ctl.question is not None
        d.set_mode(Mode.TRANSLATION)
        d.ctl.use_arm(d.arm.kinematics if d.arm is not None else None)
        d.ctl.reset()
        if had_question:
            d.asker.cleared()
        self.begin()
