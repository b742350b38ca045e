"""The simulated user as a real-time input backend (``--input sim``).

It drives the same pipeline as a joystick: every belief tick it looks at the arm, moves its stick (and
switches mode) like the evaluation's user, answers a pending question after ``answer_delay_s``, and
closes the gripper at its goal. Tasks run back to back: after a grasp the scene is reset and the next
task of the list starts.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..config import Config
from ..geometry import Pose
from ..model.actions import Mode
from ..sim.episode import desired_pose
from ..sim.success import Outcome, grasp_outcome, scene_object
from ..sim.user import SimulatedUser
from ..world.scene import Scene


@dataclass(frozen=True)
class SimSample:
    """One sample of the simulated user: axes in [-1, 1], mode, and whether it closes the gripper."""

    axes: np.ndarray
    mode: Mode
    close: bool


class SimInput:
    """Cycle through ``tasks`` with a fresh :class:`SimulatedUser` per task (seeded per run and task)."""

    def __init__(self, scene: Scene, tasks: list[str], cfg: Config, dt: float, seed: int = 0) -> None:
        if not tasks:
            raise ValueError("the simulated user needs at least one task (--task object:grasp_type)")
        for t in tasks:
            scene.goal(t)  # raises a SceneError naming the unknown task
        self.scene, self.tasks, self.cfg, self.dt, self.seed = scene, tasks, cfg, dt, seed
        self.index = -1
        self.user: SimulatedUser | None = None
        self.task_started = 0.0

    @property
    def task(self) -> str | None:
        return self.tasks[self.index % len(self.tasks)] if self.index >= 0 else None

    def next_task(self, start: Pose, now: float) -> str:
        """Begin the next task (wrapping around) from the arm's ``start`` pose; return its name."""
        self.index += 1
        task = self.tasks[self.index % len(self.tasks)]
        rng = np.random.default_rng([self.seed, self.index])
        goal = self.scene.goal(task)
        want = desired_pose(goal, start, self.cfg, rng, obj=scene_object(self.scene, goal.object))
        self.user = SimulatedUser(task, want, self.cfg.sim_user, self.cfg.input, rng, self.dt)
        self.task_started = now
        return task

    def sample(self, pose: Pose, listening: bool, blocked: bool = False) -> SimSample:
        """The user's stick at this instant (call once per belief tick); ``blocked``: the safety
        pipeline halted the last command (the user is told, as the ``safety`` field tells a UI)."""
        assert self.user is not None, "next_task() first"
        inp = self.user.act(pose, listening=listening, blocked=blocked)
        return SimSample(np.asarray(inp.axes, dtype=float), inp.mode, bool(inp.close))

    def answer(self, target: str) -> bool | str:
        assert self.user is not None
        return self.user.answer(target, self.cfg.asking.third_answer)

    def answers_by(self, qid: int, asked_at: float, t: float) -> bool:
        """Whether the user has answered question ``qid``, asked at ``asked_at``, by ``t`` (s)."""
        assert self.user is not None
        return self.user.answers_by(qid, asked_at, t)

    def outcome(self, closed_at: Pose | None) -> Outcome:
        """The task's outcome with the gripper closed at ``closed_at`` (``None``: it timed out): the
        geometric rule of ``world/holding.py`` (``sim/success.py``), on every arm."""
        assert self.task is not None
        return grasp_outcome(self.scene, self.task, closed_at)
