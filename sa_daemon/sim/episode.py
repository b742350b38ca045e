"""One evaluation trial: simulated user, the product's controller, planner and arm in simulated time.

Each control step (``eval.control_hz``, 40 Hz = the paper's 0.025 s joystick sampling) the user acts on
what it sees (including whether the safety pipeline refused its last command, as the daemon tells it),
the :class:`~..control.controller.Controller` takes the joystick sample and updates the belief, every
``planner.period_s`` the planner picks an action (deterministically: it stops at ``eval.node_budget``
belief evaluations, never at a clock), and the controller's tick - the blended twist through the same
safety pipeline as ``sa-daemon run`` - moves the arm. A question stops the robot until the user answers.
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
from ..control.controller import Controller
from ..control.outputs import answer_word
from ..geometry import Pose
from ..model.actions import Mode
from ..planner.snapshot import PlanResult, Snapshot
from ..planner.solver import Solver
from ..world.goals import Goal, parse_target
from ..world.holding import holds
from ..world.scene import Scene, SceneObject
from . import metrics
from .success import grasp_outcome, scene_object
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
    command_twist: list[list[float]] = field(default_factory=list)  # after the safety pipeline
    safety: list[str] = field(default_factory=list)  # the pipeline's status (most severe code)
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
    failure: str = ""  # why it failed, with numbers (sim/success.py); "" for a success
    failure_kind: str = ""  # the same as one of sim.success.FAILURES, for counting
    asked: list[dict] = field(default_factory=list)  # every question: when, what, on which belief
    early_plans: dict[str, int] = field(default_factory=dict)  # actions planned in the first EARLY_S, by kind
    user: str = "calibrated"  # the simulated user's profile (sim/users.py)
    yes_withdrawn: int = 0  # "yes" answers withdrawn against the user's opposition (asking.withdraw_yes_s)
    no_withdrawn: int = 0  # times the "no" answers were withdrawn so (asking.withdraw_no_s)
    rule_held: bool | None = None  # on a physics arm: the holding rule's verdict on the close (sim/success.py)
    user_pose: Pose | None = None  # the grasp pose the simulated user drove to (not in the JSON record)

    def metrics(self) -> dict:
        """The JSON record of the trial (without the timeline)."""
        return {
            k: getattr(self, k)
            for k in (
                "scene", "task", "user", "method", "seed", "success", "failure", "failure_kind",
                "completion_time_s", "asked", "early_plans", "mode_changes",
                "joystick_input", "opposing_pct", "correct_prediction", "questions", "final_target_p", "plans",
                "yes_withdrawn", "no_withdrawn",
            )
        } | ({} if self.rule_held is None else {"rule_held": self.rule_held})


EARLY_S = 2.0
"""The opening of a task whose plans ``early_plans`` counts (s): the paper's Table II, HO chosen at the start."""


def question_record(snap: Snapshot, target: str, t: float) -> dict:
    """A question as the trial records it: when (s), about which target, the largest target probability
    then and that over uniform (``1.0``: a uniform belief; issue 16 asks for none below 1.1), the rank
    of the target's object among the objects by probability (1 = the most likely; an object's probability
    is the sum over its grasp types), and the rank of the target itself among the targets (1 = the most
    likely target; ties share the better rank). The two ranks differ where the likeliest target belongs to
    an object whose probability is spread over fewer grasp types than another's. ``charged_s``: the
    question time the planner charged (s, ``Snapshot.question_time_s``: the person's, learned from their
    earlier answers). The trial adds the answer and ``answered_after_s`` (s) once it is answered."""
    tp = snap.goals.target_probabilities(snap.probs)
    objects: dict[str, float] = {}
    for k, v in tp.items():
        obj = parse_target(k)[0]
        objects[obj] = objects.get(obj, 0.0) + v
    ranked = sorted(objects, key=lambda o: -objects[o])
    p_max = max(tp.values())
    return {"t": round(t, 6), "target": target, "p_max": round(p_max, 6),
            "over_uniform": round(p_max * len(tp), 6), "object_rank": ranked.index(parse_target(target)[0]) + 1,
            "target_rank": 1 + sum(v > tp[target] for v in tp.values()), "charged_s": snap.question_time_s}


def desired_pose(goal: Goal, start: Pose, cfg: Config, rng: np.random.Generator, choice: str | None = None,
                 obj: SceneObject | None = None) -> Pose:
    """The pose the user wants (``choice``, default ``sim_user.pose_choice``):

    * ``closest``: the goal's pose closest to the start by the planner's own metric (``k_c``);
    * ``random``: a seeded random pose of the goal;
    * ``other``: a seeded random pose of the goal other than ``k_c`` (``k_c`` if the goal has one pose);
    * ``off_list``: in no list (section VI-E.4): ``k_c`` shifted along its tool x axis (across the closing
      axis and the approach) by up to ``off_list_m`` and turned about its approach by up to
      ``off_list_rad``, both uniform and seeded, redrawn (up to 50 times, then halved) until the
      gripper closed there would still hold ``obj`` (``world/holding.py``).
    """
    choice = choice or cfg.sim_user.pose_choice
    kc = goal.desired_pose(start, cfg.intent.rotation_weight_m_per_rad)
    if choice == "random":
        return goal.poses[int(rng.integers(len(goal.poses)))]
    if choice == "other":
        others = [p for p in goal.poses if p is not kc]
        return others[int(rng.integers(len(others)))] if others else kc
    if choice == "off_list":
        return _off_list(kc, goal, cfg, rng, obj)
    return kc


def _off_list(kc: Pose, goal: Goal, cfg: Config, rng: np.random.Generator, obj: SceneObject | None) -> Pose:
    su = cfg.sim_user
    scale = 1.0
    for attempt in range(200):
        if attempt and attempt % 50 == 0:
            scale /= 2.0
        shift = float(rng.uniform(-1.0, 1.0)) * su.off_list_m * scale
        turn = float(rng.uniform(-1.0, 1.0)) * su.off_list_rad * scale
        r = kc.rotation
        position = kc.position + shift * r[:, 0]
        c, s = np.cos(turn), np.sin(turn)
        about_z = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        pose = Pose.from_matrix(position, r @ about_z)
        if obj is None or holds(obj, pose, goal.grasp_type).held:
            return pose
    return kc


def run_trial(
    scene: Scene,
    task: str,
    method: str,
    seed: int,
    cfg: Config,
    arm_factory: ArmFactory = kinematic_arm,
    record: bool = False,
    pose_choice: str | None = None,
    user_name: str = "calibrated",
    on_plan: Callable[[float, Snapshot, PlanResult], None] | None = None,
    pose_known: bool = False,
) -> TrialResult:
    """Run one trial of ``task`` (``"object:grasp_type"``) with ``method``; deterministic per ``seed``.
    ``on_plan(t, snapshot, result)`` sees every plan, ``t`` the trial's time in s. ``pose_known`` is an
    oracle for measuring, never the product's: the controller's goal for ``task`` holds the user's own
    grasp pose alone, so the low-level target is known (the same seed draws the same user)."""
    rng = np.random.default_rng(seed)
    arm = arm_factory(scene, cfg)
    if arm.kinematics is not None:  # an arm with joints: only the poses it can reach (arm/reach.py)
        scene = reachable_scene(scene, arm.kinematics, cfg.safety.joint_margin_rad)
    goal = scene.goal(task)
    dt = 1.0 / cfg.eval.control_hz
    want = desired_pose(goal, scene.start, cfg, rng, pose_choice, scene_object(scene, goal.object))
    user = SimulatedUser(task, want, cfg.sim_user, cfg.input, rng, dt)
    goals = scene.goals
    if pose_known:
        goals = tuple(g.with_poses((want,)) if g.target == goal.target else g for g in goals)
    ctl = Controller(cfg, goals, method, dt, arm.kinematics)
    solver = Solver(ctl.model)
    plan_every = max(1, round(cfg.planner.period_s / dt))
    n_steps = int(np.ceil(cfg.sim_user.timeout_s / dt))
    axes: list = []
    modes: list[str] = []
    opposed: list[bool] = []
    plans = 0
    asked: list[dict] = []
    early: dict[str, int] = {}
    closed = False
    timeline = Timeline() if record else None
    targets = scene.targets
    for step in range(n_steps):
        t = step * dt
        state = arm.read()
        inp = user.act(state.pose, listening=ctl.question is not None, blocked=ctl.last.refused)
        if inp.close:
            arm.command_gripper(True)
            closed = True
            break
        ctl.set_mode(inp.mode)
        ctl.on_input(inp.axes, t)
        ctl.update_belief(state.pose, t)
        answered = False
        q = ctl.question
        if q is not None and user.answers_by(q.qid, q.asked_at, t):
            value = user.answer(q.target, cfg.asking.third_answer)
            ctl.on_answer(value, t)
            answered = True  # re-plan now, with the answer
            if asked and asked[-1]["target"] == q.target:
                asked[-1].update(answer=answer_word(value), answered_after_s=round(t - q.asked_at, 6))
        if step % plan_every == 0 or answered:
            snap = ctl.snapshot(state.pose, budget_s=None, node_budget=cfg.eval.node_budget)
            if snap is not None:
                result = solver.plan(snap)
                plans += 1
                if on_plan is not None:
                    on_plan(t, snap, result)
                if t < EARLY_S:
                    kind = result.action.kind.value
                    early[kind] = early.get(kind, 0) + 1
                if ctl.accept_plan(snap, result, t) is not None:
                    asked.append(question_record(snap, result.action.target, t))
        tick = ctl.tick(state, t)
        axes.append(inp.axes)
        modes.append(inp.mode.value)
        opposed.append(tick.command.opposed)
        arm.command_twist(tick.safety.twist)
        arm.step(dt)
        if timeline is not None:
            tp = ctl.belief.target_probabilities()
            timeline.t.append(t)
            timeline.belief.append([tp[x] for x in targets])
            timeline.action.append(tick.command.action.label)
            timeline.opposed.append(tick.command.opposed)
            timeline.user_twist.append(ctl.user_twist.tolist())
            timeline.robot_twist.append(tick.command.robot_twist.tolist())
            timeline.command_twist.append(tick.safety.twist.tolist())
            timeline.safety.append(tick.safety.status.value)
            timeline.mode.append(inp.mode.value)
    elapsed = len(axes) * dt
    final_p = ctl.belief.target_probabilities()[task]
    outcome = grasp_outcome(scene, task, arm.read().pose if closed else None, arm)
    arm.close()
    return TrialResult(
        scene=scene.name,
        task=task,
        method=method,
        seed=seed,
        success=outcome.success,
        failure=outcome.reason,
        failure_kind=outcome.kind,
        rule_held=outcome.rule_held,
        asked=asked,
        early_plans=early,
        user=user_name,
        user_pose=want,
        completion_time_s=round(elapsed, 6),
        mode_changes=metrics.mode_changes([Mode.TRANSLATION.value] + modes),
        joystick_input=metrics.joystick_input(axes),
        opposing_pct=metrics.opposing_pct(opposed),
        correct_prediction=metrics.correct_prediction(final_p),
        questions=len(ctl.asked),
        yes_withdrawn=ctl.yes_withdrawn,
        no_withdrawn=ctl.no_withdrawn,
        final_target_p=final_p,
        plans=plans,
        targets=targets,
        timeline=timeline,
    )
