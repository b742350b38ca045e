"""The shared-autonomy controller: the one place where an arm command is computed.

It owns the belief over goals, the adopted plan, the pending question, the joystick's axes and mode, and the
safety pipeline. It does no I/O and keeps no clock: every call that depends on time takes ``t`` (s, any
monotonic clock the caller chooses), so the daemon drives it at real time and the evaluation at simulated
time, and tests drive it in-process. Per control period the caller does, in order::

    ctl.on_input(axes, t); ctl.update_belief(pose, t)     # joystick sample, MaxEnt IOC update
    snap = ctl.snapshot(pose, budget_s)                   # when a plan is due (None: none is wanted)
    ctl.accept_plan(snap, planner.plan(snap), t)          # possibly later, in another process
    tick = ctl.tick(arm.read(), t)                        # blended, safety-filtered command
    arm.command_twist(tick.safety.twist)

A plan carries the goal set it was computed on (``Snapshot.goals``); the belief's resampling may replace
that goal set at any input, and the move is carried over to the new set in :meth:`tick`, the only place
an action meets a goal set.
"""

from __future__ import annotations

import math
import weakref

import numpy as np

from ..arm.base import ArmState, Kinematics
from ..config import Config
from ..geometry import FloatArray, Pose
from ..model.actions import NO_ASSIST, Action, ActionKind, Mode
from ..model.belief import Belief
from ..model.methods import method_spec
from ..model.model import Command, SharedAutonomyModel
from ..planner.snapshot import PlanResult, Snapshot
from ..world.goalset import GoalSet
from .answer_time import AnswerTime
from .outputs import IDLE_TICK, ZERO6, NoQuestion, Plan, Question, Tick
from .safety import SafetyPipeline
from .stick import Stick
from .user_speed import UserSpeed
from .withdrawal import AnswerWithdrawal
from .yielding import Yielding


class Controller:
    """Belief, plan, question, mode and safety for one arm (see the module doc). Not thread-safe: one
    caller, the daemon's event loop or the evaluation's step loop."""

    def __init__(self, cfg: Config, goals: GoalSet | tuple, method: str, control_dt: float,
                 kinematics: Kinematics | None = None) -> None:
        """``goals``: the scene's goals; ``control_dt``: the control period (s), for the acceleration
        limit; ``kinematics``: the arm's joints, for the joint stages (``None``: an arm without joints)."""
        method_spec(method)  # raises on an unknown name
        self._cfg = cfg
        self._model = SharedAutonomyModel(cfg)
        self._safety = SafetyPipeline(cfg.safety, cfg.limits, control_dt, kinematics)
        self._scene_goals = goals
        self._method = method
        self._belief = self._model.initial_belief(goals)
        self._plan = Plan(NO_ASSIST, self._belief.goals, 0.0)
        self._question: Question | None = None
        self._questions = 0
        self._asked: set[str] = set()
        self._stick = Stick(cfg.input)  # axes, mode, freshness, the tremor filter
        self._yielding = Yielding(cfg.blend)  # why the robot does not assist now (blend.*), or None
        self._withdrawal = AnswerWithdrawal(cfg)  # asking.withdraw_yes_s, asking.withdraw_no_s
        self._answer_time = AnswerTime(cfg)  # this person's answer times, across tasks
        pc = cfg.planner
        self._speed = UserSpeed(pc.user_speed_tau_s, pc.user_speed_idle, pc.user_speed_unused,
                                (cfg.input.linear_scale_mps, cfg.input.angular_scale_radps))
        self._assist = True
        self._gripper_closed = False
        self._last = IDLE_TICK
        self._task = 0  # counts resets
        self._issued: weakref.WeakKeyDictionary[Snapshot, int] = weakref.WeakKeyDictionary()  # -> task

    # -- read-only state ---------------------------------------------------------------------------------

    @property
    def model(self) -> SharedAutonomyModel:
        return self._model

    @property
    def belief(self) -> Belief:
        return self._belief

    @property
    def plan(self) -> Plan:
        return self._plan

    @property
    def question(self) -> Question | None:
        return self._question

    @property
    def asked(self) -> frozenset[str]:
        """The targets asked about in this task."""
        return frozenset(self._asked)

    @property
    def answer_time(self) -> AnswerTime:
        """This person's answer times and what the planner charges a question (``asking.learn_answer_time``)."""
        return self._answer_time

    @property
    def questions_asked(self) -> int:
        """Questions asked since the controller was made (every task)."""
        return self._questions

    @property
    def mode(self) -> Mode:
        """The joystick's mode."""
        return self._stick.mode

    @property
    def axes(self) -> FloatArray:
        """The last joystick sample, normalised to [-1, 1]."""
        return self._stick.axes

    @property
    def t_input(self) -> float:
        """When the last input sample arrived (s; ``-inf``: none, or the input was lost)."""
        return self._stick.t_input

    @property
    def input_seq(self) -> int:
        """Counts the input samples taken."""
        return self._stick.seq

    @property
    def assist(self) -> bool:
        return self._assist

    @property
    def method(self) -> str:
        return self._method

    @property
    def gripper_closed(self) -> bool:
        """The gripper was last commanded closed (it may not be closed yet)."""
        return self._gripper_closed

    @property
    def stopped(self) -> bool:
        """The safety pipeline's stop is latched."""
        return self._safety.stopped

    @property
    def stop_tested(self) -> bool:
        """The start-up stop self-test has passed, or none is required (``safety.stop_self_test``)."""
        return self._safety.stop_tested

    @property
    def last(self) -> Tick:
        """The last :meth:`tick`'s output."""
        return self._last

    @property
    def user_twist(self) -> FloatArray:
        """The user's twist (m/s, rad/s) of the last sample in the current mode, after the tremor filter if
        any."""
        return self._stick.twist

    @property
    def user_speed(self) -> tuple[float, float]:
        """The user's smoothed speed ``(linear m/s, angular rad/s)``: each an exponential average, time
        constant ``planner.user_speed_tau_s``, of the twist's norm over the belief ticks in its mode
        (:mod:`.user_speed`)."""
        return self._speed.value

    def input_fresh(self, t: float) -> bool:
        """An input sample arrived within ``safety.stale_command_s`` of ``t``."""
        return self._stick.fresh(t, self._cfg.safety.stale_command_s)

    # -- input -------------------------------------------------------------------------------------------

    def on_input(self, axes: FloatArray, t: float) -> bool:
        """A joystick sample at ``t``; ``False`` (and nothing changes) unless it is 3 finite numbers.
        Axes are clipped to [-1, 1]."""
        return self._stick.sample(axes, t)

    def hold_input(self, t: float) -> None:
        """The input device reports changes only and is connected: its held axes are current at ``t``."""
        self._stick.hold(t)

    def lose_input(self) -> None:
        """The input device is gone: axes zero and stale at once, so the next tick commands zero (the
        pipeline's stale stage) instead of waiting for ``stale_command_s``."""
        self._stick.lose()

    def set_mode(self, mode: Mode) -> bool:
        """Switch the joystick mode; ``True`` if it changed."""
        return self._stick.set_mode(mode)

    def toggle_mode(self) -> Mode:
        """Switch to the other joystick mode; returns it."""
        self.set_mode(Mode.ROTATION if self.mode is Mode.TRANSLATION else Mode.TRANSLATION)
        return self.mode

    def set_assist(self, on: bool) -> None:
        """Assistance on or off (off: the user's twist alone, still filtered)."""
        self._assist = bool(on)

    def set_gripper(self, closed: bool) -> None:
        """The gripper has been commanded closed or open: while closed or closing no motion is commanded
        (pipeline stage ``gripper_closed``) and no plan is wanted."""
        self._gripper_closed = bool(closed)

    def set_method(self, method: str) -> None:
        """Change the assistance method; raises ``ValueError`` on an unknown name. The plan and any
        pending question are dropped."""
        method_spec(method)
        self._method = method
        self.drop_plan()
        self._question = None

    # -- belief ------------------------------------------------------------------------------------------

    def update_belief(self, pose: Pose, t: float) -> bool:
        """The MaxEnt IOC update with the user's twist at ``pose``, if the input is fresh at ``t``;
        ``True`` if the belief was updated. Resampling may replace the goal set (see :meth:`tick`)."""
        if not self.input_fresh(t):
            return False
        u = self.user_twist
        self._belief = self._model.update_input(self._belief, pose, u)
        self._speed.update(u, 0 if self.mode is Mode.TRANSLATION else 1, t)
        return True

    # -- questions ---------------------------------------------------------------------------------------

    def ask(self, target: str, t: float) -> Question:
        """Pose the question about ``target`` at ``t``; the arm holds still until it is answered."""
        self._questions += 1
        self._question = Question(target, t, self._questions)
        self._asked.add(target)
        return self._question

    def on_answer(self, answer: bool | str, t: float) -> Question:
        """Apply an answer to the pending question (final, ``docs/model.md``) and return it: yes/no
        (``True``/``False`` or ``"yes"``/``"no"``) or ``"other"`` (that object, another grasp; only with
        ``asking.third_answer``, and only where the object has another grasp type: ``ValueError``
        otherwise, nothing changed). The plan is dropped so that the next one uses the new belief.
        :class:`NoQuestion` if none is pending."""
        q = self._question
        if q is None:
            raise NoQuestion("no question is pending")
        if answer == "other" and not self._cfg.asking.third_answer:
            raise ValueError("the third answer is off (asking.third_answer)")
        self._belief = self._model.update_answer(self._belief, q.target, answer if answer == "other" else
                                                 answer in (True, "yes"))
        self._withdrawal.answered()
        self._answer_time.record(t - q.asked_at)
        self._question = None
        self.drop_plan()
        return q

    def expire_question(self, t: float) -> Question | None:
        """Drop the pending question if it has waited longer than ``runtime.question_timeout_s``; return it
        if it was dropped."""
        q = self._question
        if q is None or t - q.asked_at <= self._cfg.runtime.question_timeout_s:
            return None
        self._question = None
        self.drop_plan()
        return q

    # -- plans -------------------------------------------------------------------------------------------

    def snapshot(self, pose: Pose, budget_s: float | None, node_budget: int | None = None) -> Snapshot | None:
        """What the planner needs now, or ``None`` when no plan is wanted (a question is pending, the
        gripper is closed, or the stop self-test is pending). A rule-based method's snapshot is planned by
        the solver without search; the daemon spares the worker that round trip with :meth:`adopt_fixed`."""
        if self._question is not None or self._gripper_closed or not self._safety.stop_tested:
            return None
        b = self._belief
        cap = self._cfg.asking.max_per_task
        snap = Snapshot(b.goals, self._model.planning_probs(b, pose), pose, self.user_twist, self.mode,
                        frozenset(self._asked), self._method, budget_s=budget_s, node_budget=node_budget,
                        user_speed=self.user_speed, questions_left=max(0, cap - len(self._asked)) if cap else None,
                        anchor=b.anchor, pose_log_w=self._model.reach_log_w(b),
                        question_time_s=self._answer_time.charged_s)
        self._issued[snap] = self._task
        return snap

    def accept_plan(self, snap: Snapshot, result: PlanResult, t: float) -> Question | None:
        """Adopt the planner's choice for ``snap`` at ``t``. A question is asked (and returned); a move, HO
        or no-assist becomes the plan until ``t + 2 planner.period_s`` (the next plan is due in one
        period; one more of grace). A plan is moot, and ignored, when a question arrived meanwhile, the
        method changed, the gripper was closed, or its snapshot was taken before the last :meth:`reset`."""
        stale_task = self._issued.get(snap, self._task) != self._task
        if (self._question is not None or snap.method != self._method or self._gripper_closed or stale_task
                or not self._safety.stop_tested):
            return None
        action = result.action
        if action.kind is ActionKind.QUESTION:
            return self.ask(str(action.target), t)
        action = self._held(snap, result, action, t)
        self._plan = Plan(action, snap.goals, t + 2 * self._cfg.planner.period_s)
        return None

    def _held(self, snap: Snapshot, result: PlanResult, action: Action, t: float) -> Action:
        """``action``, or the adopted motion when it is still valid, was planned on the same goals and
        the new plan values ``action`` less than ``planner.switch_margin`` above it."""
        margin = self._cfg.planner.switch_margin
        held, values = self._plan.action, result.root_values
        if (margin <= 0.0 or held == action or t > self._plan.until or self._plan.goals is not snap.goals
                or held not in values or action not in values):  # a plan without both values holds nothing
            return action
        return held if values[action] - values[held] < margin else action

    def adopt_fixed(self) -> None:
        """A rule-based method's action for the current belief (``manual``, ``ho``, ``blend``, ...), valid
        until the next call."""
        b = self._belief
        self._plan = Plan(self._model.fixed_action(self._method, b.goals, b.probs), b.goals, math.inf)

    def drop_plan(self) -> None:
        """No-assist until the next plan."""
        self._plan = Plan(NO_ASSIST, self._belief.goals, 0.0)

    def current_action(self, t: float) -> Action:
        """The action applied at ``t``: a pending question holds the arm; assistance off or an expired plan
        (a late or dead planner) gives no-assist."""
        if self._question is not None:
            return Action(ActionKind.QUESTION, None, self._question.target)
        if not self._assist or t > self._plan.until or not self._safety.stop_tested:
            return NO_ASSIST
        return self._plan.action

    # -- the task ----------------------------------------------------------------------------------------

    def use_arm(self, kinematics: Kinematics | None) -> None:
        """The arm's joint model for the pipeline's joint stages (``None``: an arm without joints); call it
        whenever the arm is (re)built."""
        self._safety.kinematics = kinematics

    def reset(self) -> None:
        """A new task from the start: uniform belief over the scene's goals, nothing asked, translation
        mode, gripper open, the stop released and the arm restarting from rest. Plans for snapshots of
        the previous task are moot from now on."""
        self._task += 1
        self._belief = self._model.initial_belief(self._scene_goals)
        self._asked.clear()
        self._question = None
        self.drop_plan()
        self._speed.reset()
        self._stick.set_mode(Mode.TRANSLATION)
        self._gripper_closed = False
        self._yielding.reset()
        self._withdrawal.reset()
        self._safety.restart()

    # -- stop --------------------------------------------------------------------------------------------

    def stop(self) -> None:
        """Latch the stop: every tick commands zero until :meth:`resume`."""
        self._safety.stop()

    def resume(self) -> bool:
        """Release the stop; the arm restarts from rest (acceleration-limited). Returns ``True`` when this
        resume passed the stop self-test (a stop was latched and the test was pending)."""
        pending = not self._safety.stop_tested
        self._safety.resume()
        return pending and self._safety.stop_tested

    def new_goals(self, goals: GoalSet | tuple) -> None:
        """A new scene's goals (``set_scene``): uniform belief over them, nothing asked, no plan; plans
        for snapshots of the old scene are moot. The stop, the mode and the gripper stay as they are."""
        self._task += 1
        self._scene_goals = goals
        self._belief = self._model.initial_belief(goals)
        self._asked.clear()
        self._question = None
        self._withdrawal.reset()
        self.drop_plan()

    def reconfigure(self, cfg: Config) -> None:
        """Take a person's new settings (a profile switched between tasks: the assistance level, the tremor
        filter, the questions they want); the task, belief and plan go on."""
        self._cfg = cfg
        self._model = SharedAutonomyModel(cfg)
        self._stick.reconfigure(cfg.input)  # a new tremor filter starts at rest
        self._yielding.reconfigure(cfg.blend)
        self._withdrawal.reconfigure(cfg)
        self._answer_time.reconfigure(cfg)  # another person: their answer times count afresh

    def require_stop_test(self) -> None:
        """No assistance, no plans and no motion until a stop has been latched and resumed once."""
        self._safety.require_stop_test()

    # -- control -----------------------------------------------------------------------------------------

    def tick(self, state: ArmState, t: float) -> Tick:
        """The command for this control period at the arm's ``state``: the current action's twist blended
        with the user's (zero when the input is stale), then the safety pipeline."""
        fresh = self.input_fresh(t)
        self._stick.filter(t)  # the tremor filter runs at the control rate on the held axes
        u = self.user_twist if fresh else ZERO6.copy()
        action = self._carried_action(t, state.pose)
        error = None
        b = self._belief
        try:
            reach = self._model.reach_poses(b.goals, state.pose, self._model.reach_log_w(b), b.probs)
            cmd = self._model.command(action, b.goals, b.probs, state.pose, u, self._method, reach)
            has_input = fresh and bool(np.any(u))
            self._withdraw_answers_if_opposed(t, cmd, has_input)
            # (the belief after any withdrawal: near_object reads the one the next plan will)
            yielding = self._yielding.step(t, self.mode, has_input, bool(cmd.opposed), self._belief, state.pose)
            if yielding is not None and action.kind in (ActionKind.MOVE, ActionKind.HO):
                cmd = self._model.command(NO_ASSIST, b.goals, b.probs, state.pose, u, self._method)
        except (ValueError, FloatingPointError) as e:
            cmd, error = Command(NO_ASSIST, ZERO6.copy(), u, False), str(e)
        result = self._safety.filter(
            cmd.total_twist, state.pose, input_fresh=fresh, fault=state.fault is not None, joints=state.joints,
            gripper_closed=state.gripper_closed or self._gripper_closed,  # closed, or closing (not yet reported)
        )
        self._last = Tick(cmd, result, fresh, error)
        return self._last

    @property
    def yielding(self) -> str | None:
        """Why the robot is not assisting now although its plan would: ``"near_object"`` (within
        ``blend.yield_near_m`` of the object the belief settles on: the person fine-tunes alone) or
        ``"user_opposes"`` (the person has kept opposing the assistance over ``blend.opposition_window_s``:
        they want a pose of their own) or ``"mode_churn"`` (the person keeps switching mode,
        ``blend.churn_window_s``: the assistance undoes in one mode what they do in the other); ``None``
        otherwise."""
        return self._yielding.reason

    @property
    def yes_withdrawn(self) -> int:
        """How many "yes" answers this task were withdrawn because the user kept opposing the assistance
        (``asking.withdraw_yes_s``)."""
        return self._withdrawal.yes_withdrawn

    @property
    def no_withdrawn(self) -> int:
        """How many times this task the "no" answers were withdrawn so (``asking.withdraw_no_s``)."""
        return self._withdrawal.no_withdrawn

    def _withdraw_answers_if_opposed(self, t: float, cmd: Command, has_input: bool) -> None:
        """A standing answer withdrawn once the user has kept opposing the assistance (``control/withdrawal.py``);
        the plan is then dropped, so the next one uses the belief without it."""
        assisting = has_input and cmd.action.kind in (ActionKind.MOVE, ActionKind.HO)
        if (b := self._withdrawal.step(self._belief, t, assisting, bool(cmd.opposed))) is not None:
            self._belief = b
            self.drop_plan()

    def _carried_action(self, t: float, pose: Pose) -> Action:
        """:meth:`current_action`, its goal index carried over to the belief's goal set when resampling
        replaced the one the plan was computed on."""
        action = self.current_action(t)
        plan = self._plan
        if action.kind is ActionKind.MOVE and plan.goals is not self._belief.goals:
            action = self._model.remap_action(action, plan.goals, self._belief.goals, pose)
            self._plan = Plan(action, self._belief.goals, plan.until)
        return action
