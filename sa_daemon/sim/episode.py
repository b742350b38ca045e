"""One evaluation trial: simulated user, belief, planner and arm in simulated time.

Each control step (``eval.control_hz``, 40 Hz = the paper's 0.025 s joystick sampling) the user acts on
what it sees, the belief takes the joystick sample, every ``planner.period_s`` the planner picks an action
(deterministically: it stops at ``eval.node_budget`` belief evaluations, never at a clock), the model turns
the action into a blended twist and the arm moves. A question stops the robot until the user answers.
The trial ends when the user closes the gripper (success if it is at its desired pose, a pose of the
task's goal) or at ``sim_user.timeout_s``. An arm with a physical check (``lift_test``, the MuJoCo arm)
must also lift the task's object after closing for the trial to succeed.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from functools import partial

import numpy as np

from ..arm.base import Arm
from ..arm.factory import make_arm
from ..arm.kinematic import KinematicArm
from ..arm.reach import reachable_scene
from ..config import Config
from ..geometry import Pose
from ..planner.actions import NO_ASSIST, Action, ActionKind, Mode
from ..planner.goals import Goal
from ..planner.model import SharedAutonomyModel
from ..planner.scene import Scene
from ..planner.snapshot import PlanResult, Snapshot
from ..planner.solver import Solver
from . import metrics
from .user import SimulatedUser

ArmFactory = Callable[[Scene, Config], Arm]


def kinematic_arm(scene: Scene, cfg: Config) -> Arm:
    return KinematicArm(scene.start, cfg.limits)


def arm_factory(backend: str) -> ArmFactory:
    """A picklable factory of ``backend`` arms (``kinematic``, ``mujoco``), see ``arm.factory.make_arm``."""
    return kinematic_arm if backend == "kinematic" else partial(make_arm, backend)


@dataclass
class Timeline:
    """Per control step records, for plots (Fig. 4)."""

    t: list[float] = field(default_factory=list)
    belief: list[list[float]] = field(default_factory=list)  # per scene target
    action: list[str] = field(default_factory=list)
    opposed: list[bool] = field(default_factory=list)
    user_twist: list[list[float]] = field(default_factory=list)
    robot_twist: list[list[float]] = field(default_factory=list)
    mode: list[str] = field(default_factory=list)


@dataclass
class TrialResult:
    """Metrics of one trial (section IV) and, optionally, its timeline."""

    scene: str
    task: str
    method: str
    seed: int
    success: bool
    completion_time_s: float
    mode_changes: int
    joystick_input: float
    opposing_pct: float
    correct_prediction: bool
    questions: int
    final_target_p: float
    plans: int
    targets: list[str] = field(default_factory=list)
    timeline: Timeline | None = None

    def metrics(self) -> dict:
        """The JSON record of the trial (without the timeline)."""
        return {
            k: getattr(self, k)
            for k in (
                "scene", "task", "method", "seed", "success", "completion_time_s", "mode_changes",
                "joystick_input", "opposing_pct", "correct_prediction", "questions", "final_target_p", "plans",
            )
        }


def desired_pose(goal: Goal, start: Pose, cfg: Config, rng: np.random.Generator, choice: str) -> Pose:
    """The user's wanted pose: the goal's pose closest to the start, or a seeded random one."""
    if choice == "random":
        return goal.poses[int(rng.integers(len(goal.poses)))]
    return goal.desired_pose(start, cfg.intent.rotation_weight_m_per_rad)


def run_trial(
    scene: Scene,
    task: str,
    method: str,
    seed: int,
    cfg: Config,
    arm_factory: ArmFactory = kinematic_arm,
    record: bool = False,
    pose_choice: str = "closest",
    on_plan: Callable[[Snapshot, PlanResult], None] | None = None,
) -> TrialResult:
    """Run one trial of ``task`` (``"object:grasp_type"``) with ``method``; deterministic per ``seed``."""
    rng = np.random.default_rng(seed)
    model = SharedAutonomyModel(cfg)
    solver = Solver(model)
    arm = arm_factory(scene, cfg)
    if arm.kinematics is not None:  # an arm with joints: only the poses it can reach (arm/reach.py)
        scene = reachable_scene(scene, arm.kinematics, cfg.safety.joint_margin_rad)
    goal = scene.goal(task)
    dt = 1.0 / cfg.eval.control_hz
    user = SimulatedUser(task, desired_pose(goal, scene.start, cfg, rng, pose_choice), cfg.sim_user, cfg.input, rng, dt)
    belief = model.initial_belief(scene.goals)
    plan_every = max(1, round(cfg.planner.period_s / dt))
    asked: set[str] = set()
    action: Action = NO_ASSIST
    plan_goals = belief.goals
    question: str | None = None
    answer_at = 0.0
    n_steps = int(np.ceil(cfg.sim_user.timeout_s / dt))
    axes: list = []
    modes: list[str] = []
    opposed: list[bool] = []
    plans = 0
    closed = False
    timeline = Timeline() if record else None
    targets = scene.targets
    step = 0
    for step in range(n_steps):
        t = step * dt
        pose = arm.read().pose
        inp = user.act(pose, listening=question is not None)
        if inp.close:
            arm.command_gripper(True)
            closed = True
            break
        u = inp.twist(cfg.input)
        belief = model.update_input(belief, pose, u)
        if question is not None and t >= answer_at:
            belief = model.update_answer(belief, question, user.answer(question))
            question = None  # the action is still the question: re-plan now
        if question is None and (step % plan_every == 0 or action.kind is ActionKind.QUESTION):
            snap = Snapshot(
                belief.goals, belief.probs, pose, u, inp.mode, frozenset(asked), method,
                budget_s=None, node_budget=cfg.eval.node_budget,
            )
            result = solver.plan(snap)
            plans += 1
            if on_plan is not None:
                on_plan(snap, result)
            action, plan_goals = result.action, belief.goals
            if action.kind is ActionKind.QUESTION:
                question = action.target
                asked.add(question)
                answer_at = t + cfg.sim_user.answer_delay_s
        if plan_goals is not belief.goals:
            action, plan_goals = model.remap_action(action, plan_goals, belief.goals, pose), belief.goals
        cmd = model.command(action, belief.goals, belief.probs, pose, u, method)
        axes.append(inp.axes)
        modes.append(inp.mode.value)
        opposed.append(cmd.opposed)
        arm.command_twist(cmd.total_twist)
        arm.step(dt)
        if timeline is not None:
            tp = belief.target_probabilities()
            timeline.t.append(t)
            timeline.belief.append([tp[x] for x in targets])
            timeline.action.append(cmd.action.label)
            timeline.opposed.append(cmd.opposed)
            timeline.user_twist.append(u.tolist())
            timeline.robot_twist.append(cmd.robot_twist.tolist())
            timeline.mode.append(inp.mode.value)
    elapsed = len(axes) * dt
    final_p = belief.target_probabilities()[task]
    success = closed and user.at_goal(arm.read().pose)
    lift_test = getattr(arm, "lift_test", None)
    if success and callable(lift_test):
        success = lift_test() == goal.object  # physics: the gripper must hold the task's object
    arm.close()
    return TrialResult(
        scene=scene.name,
        task=task,
        method=method,
        seed=seed,
        success=bool(success),
        completion_time_s=round(elapsed, 6),
        mode_changes=metrics.mode_changes([Mode.TRANSLATION.value] + modes),
        joystick_input=metrics.joystick_input(axes),
        opposing_pct=metrics.opposing_pct(opposed),
        correct_prediction=metrics.correct_prediction(final_p),
        questions=len(asked),
        final_target_p=final_p,
        plans=plans,
        targets=targets,
        timeline=timeline,
    )
