"""The Controller in-process: plan adoption across resampling, questions, stale input, late plans, the
arm's refusal as the simulated user sees it, the gripper, reset, rule-based methods and a closed loop
with the real solver, kinematic arm and simulated user (no clock, no sockets, no subprocesses)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sa_daemon.arm.base import ArmState
from sa_daemon.arm.kinematic import KinematicArm
from sa_daemon.config import Config, config_from_dict, load_config
from sa_daemon.control.controller import Controller
from sa_daemon.control.outputs import NoQuestion
from sa_daemon.control.safety import SafetyCode
from sa_daemon.geometry import Pose
from sa_daemon.model.actions import HO_ACTION, NO_ASSIST, Action, ActionKind, Mode
from sa_daemon.planner.snapshot import PlanResult, Snapshot
from sa_daemon.planner.solver import Solver
from sa_daemon.sim.episode import desired_pose
from sa_daemon.sim.user import Phase, SimulatedUser
from sa_daemon.world.scene import load_scene

CFG = load_config(None)
SCENE = load_scene("scene1")
DT = 1.0 / CFG.eval.control_hz  # 0.025 s, the evaluation's control period
START = SCENE.start
W = CFG.intent.rotation_weight_m_per_rad
AMAX = np.array([CFG.safety.linear_accel_mps2] * 3 + [CFG.safety.angular_accel_radps2] * 3)
ZEROING = {SafetyCode.STOPPED, SafetyCode.ARM_FAULT, SafetyCode.NAN, SafetyCode.STALE, SafetyCode.GRIPPER}
TARGET = "chips can:side"  # far from the other targets: joystick input toward it resamples quickly


# -- helpers --------------------------------------------------------------------------------------------


def make_ctl(method: str = "policy", cfg: Config = CFG, kinematics=None) -> Controller:
    return Controller(cfg, SCENE.goals, method, DT, kinematics)


def sharp_cfg(factor: float = 3.0) -> Config:
    """Defaults, but the MaxEnt IOC update's rationality ``factor`` times the default, so a few samples of
    input toward one target concentrate the belief and trigger resampling (``N_eff < |G|/2`` and a new
    allocation) well within one plan's validity."""
    return config_from_dict({"intent": {"rationality": factor * CFG.intent.rationality}})


def result(action: Action) -> PlanResult:
    """A planner result choosing ``action`` (statistics irrelevant to the controller)."""
    return PlanResult(action, 0.0, 0.0, 0, 0, 0.0, True)


def move_to(goals, target: str) -> Action:
    """The move action toward the first goal of ``target`` in ``goals``."""
    i = int(np.flatnonzero(goals.target_mask(target))[0])
    return Action(ActionKind.MOVE, i, target)


def ask(target: str) -> Action:
    return Action(ActionKind.QUESTION, None, target)


def state(pose: Pose = START, closed: bool = False, joints=None) -> ArmState:
    return ArmState(pose, closed, None, joints)


def toward(target: str, pose: Pose = START) -> np.ndarray:
    """Translation axes (max |axis| = 1) from ``pose`` toward ``target``'s closest grasp pose."""
    d = SCENE.goal(target).desired_pose(pose, W).position - pose.position
    return d / np.max(np.abs(d))


def feed(ctl: Controller, axes, t: float, pose: Pose = START) -> bool:
    """One joystick sample and the belief update it drives; ``True`` if the belief was updated."""
    assert ctl.on_input(axes, t)
    return ctl.update_belief(pose, t)


def drive_until_resampled(ctl: Controller, axes, t: float, pose: Pose = START, max_steps: int = 40) -> float:
    """Feed ``axes`` every ``DT`` from ``t`` until resampling replaces the belief's goal set; the time."""
    before = ctl.belief.goals
    for _ in range(max_steps):
        feed(ctl, axes, t, pose)
        if ctl.belief.goals is not before:
            return t
        t += DT
    raise AssertionError(f"no resampling in {max_steps} samples")


def assert_twist_step_within_accel(prev: np.ndarray, cur: np.ndarray) -> None:
    assert np.all(np.abs(cur - prev) <= AMAX * DT + 1e-12), (prev, cur)


# -- 1. plans carried over a resampling -----------------------------------------------------------------


def test_move_plan_is_carried_to_the_same_target_after_resampling():
    """A move accepted on goal set A keeps commanding the same target, and the same grasp pose, once
    resampling has replaced A: the tick remaps the goal index into the new set and re-anchors the plan."""
    ctl = make_ctl(cfg=sharp_cfg())
    axes = toward(TARGET)
    feed(ctl, axes, 0.0)
    snap = ctl.snapshot(START, None)
    action = move_to(snap.goals, TARGET)
    assert ctl.accept_plan(snap, result(action), 0.0) is None
    assert ctl.plan.goals is snap.goals and ctl.plan.action == action

    t = drive_until_resampled(ctl, axes, DT)
    assert t <= ctl.plan.until  # still within the plan's validity: the move is the current action
    new = ctl.belief.goals
    assert new is not snap.goals and len(new) > len(snap.goals)
    assert ctl.plan.goals is snap.goals  # nothing remaps before the tick

    tick = ctl.tick(state(), t)
    assert tick.error is None
    assert ctl.plan.goals is ctl.belief.goals
    carried = ctl.plan.action
    assert carried.kind is ActionKind.MOVE and carried.target == action.target
    assert tick.command.action == carried
    assert new.goals[carried.goal].target == TARGET
    # The new copy owns the grasp pose the old goal was heading to (redistribution keeps the objects).
    kc = snap.goals.goals[action.goal].desired_pose(START, W)
    assert any(p is kc for p in new.goals[carried.goal].poses)
    assert ctl.model.remap_action(action, snap.goals, new, START) == carried
    want = ctl.model.command(carried, new, ctl.belief.probs, START, ctl.user_twist, "policy")
    np.testing.assert_allclose(tick.command.robot_twist, want.robot_twist, atol=1e-12)
    np.testing.assert_allclose(tick.command.total_twist, want.total_twist, atol=1e-12)
    # ... and the arm is sent exactly where the plan sent it on goal set A.
    old = ctl.model.robot_twist(action, snap.goals, snap.probs, START, ctl.user_twist)
    np.testing.assert_allclose(tick.command.robot_twist, old, atol=1e-12)
    assert np.any(tick.command.robot_twist)

    # Adopted once: the next tick on the same goal set keeps the action as it is.
    again = ctl.tick(state(), t + DT)
    assert ctl.plan.action == carried and again.command.action == carried


def test_plan_on_a_stale_goal_set_is_adopted_and_carried_over():
    """A plan computed on a goal set that resampling replaced before it arrived is still adopted (on
    its own goal set) and mapped to the current set at the next tick, even when its target's index moved
    (here: the copies of another target were inserted before it)."""
    ctl = make_ctl(cfg=sharp_cfg())
    axes = toward(TARGET)
    feed(ctl, axes, 0.0)
    snap = ctl.snapshot(START, None)
    t = drive_until_resampled(ctl, axes, DT)
    assert ctl.belief.goals is not snap.goals

    other = "bowl:top"  # after TARGET in the scene's order: its index grows with TARGET's copies
    action = move_to(snap.goals, other)
    assert ctl.accept_plan(snap, result(action), t) is None
    assert ctl.plan.action == action and ctl.plan.goals is snap.goals
    assert ctl.plan.until == pytest.approx(t + 2 * CFG.planner.period_s)

    tick = ctl.tick(state(), t)
    assert tick.error is None
    assert ctl.plan.goals is ctl.belief.goals
    carried = ctl.plan.action
    assert carried.kind is ActionKind.MOVE and carried.target == other
    assert carried.goal != action.goal
    assert ctl.belief.goals.goals[carried.goal].target == other
    want = ctl.model.command(carried, ctl.belief.goals, ctl.belief.probs, START, ctl.user_twist, "policy")
    np.testing.assert_allclose(tick.command.robot_twist, want.robot_twist, atol=1e-12)


def test_the_snapshot_carries_where_the_user_last_translated():
    """The belief's anchor (the gripper's position at the user's last translating input, from which a
    turn's charge is measured) reaches the planner; input that does not translate leaves it where it was,
    and it survives the plain form the snapshot can be written in. A snapshot refuses a non-finite one."""
    ctl = make_ctl()
    feed(ctl, toward(TARGET), 0.0)
    elsewhere = Pose(START.position + np.array([0.05, -0.02, 0.0]), START.quat_wxyz)
    feed(ctl, np.zeros(3), DT, elsewhere)  # the robot moved the gripper; the user let go
    snap = ctl.snapshot(elsewhere, None)
    np.testing.assert_array_equal(snap.anchor, START.position)
    np.testing.assert_array_equal(Snapshot.from_dict(snap.to_dict()).anchor, START.position)
    feed(ctl, toward(TARGET, elsewhere), 2 * DT, elsewhere)
    np.testing.assert_array_equal(ctl.snapshot(elsewhere, None).anchor, elsewhere.position)
    with pytest.raises(ValueError, match="anchor"):
        Snapshot(snap.goals, snap.probs, snap.pose, snap.user_twist, anchor=[0.1, np.nan, 0.2])


# -- 2. questions ---------------------------------------------------------------------------------------


def pending_question(target: str = "cup:top", t: float = 1.0) -> tuple[Controller, Snapshot]:
    """A controller with fresh input toward ``target``, a move toward it adopted, then a question about
    it asked at ``t``."""
    ctl = make_ctl()
    feed(ctl, toward(target), t)
    snap = ctl.snapshot(START, None)
    ctl.accept_plan(snap, result(move_to(snap.goals, target)), t - DT)  # a move was being applied
    q = ctl.accept_plan(snap, result(ask(target)), t)
    assert q is not None and ctl.plan.action.kind is ActionKind.MOVE
    return ctl, snap


def test_question_result_asks_and_holds_the_arm():
    """A QUESTION plan poses the question: it is pending and recorded, every tick commands exactly zero
    (robot and blended) although the user pushes, no plan is wanted, and a plan arriving meanwhile is moot."""
    ctl = make_ctl()
    feed(ctl, toward("cup:top"), 1.0)
    snap = ctl.snapshot(START, None)
    plan_before = ctl.plan
    q = ctl.accept_plan(snap, result(ask("cup:top")), 1.0)
    assert q is not None and q.target == "cup:top" and q.asked_at == 1.0
    assert ctl.question == q and "cup:top" in ctl.asked and ctl.questions_asked == 1
    assert ctl.current_action(1.0) == ask("cup:top")

    for k in range(5):
        t = 1.0 + k * DT
        feed(ctl, toward("cup:top"), t)
        tick = ctl.tick(state(), t)
        assert tick.fresh and np.any(ctl.user_twist)
        assert tick.command.action.kind is ActionKind.QUESTION
        assert not np.any(tick.command.robot_twist) and not np.any(tick.command.total_twist)
        assert not np.any(tick.safety.twist)
    assert ctl.snapshot(START, None) is None

    late = ctl.accept_plan(snap, result(move_to(snap.goals, "bowl:top")), 1.1)
    assert late is None and ctl.plan is plan_before and ctl.question == q
    assert ctl.accept_plan(snap, result(ask("bowl:top")), 1.1) is None
    assert ctl.question == q and ctl.asked == frozenset({"cup:top"}) and ctl.questions_asked == 1


@pytest.mark.parametrize("yes", [True, False])
def test_answer_updates_the_belief_and_drops_plan_and_question(yes):
    """``on_answer`` applies the model's answer update (yes: the target's probability near 1; no: near 0),
    clears the question and leaves no-assist until the next plan."""
    ctl, _ = pending_question("cup:top")
    before = ctl.belief
    q = ctl.on_answer(yes, 2.0)
    assert q.target == "cup:top" and ctl.question is None
    want = ctl.model.update_answer(before, "cup:top", yes)
    np.testing.assert_allclose(ctl.belief.probs, want.probs, atol=1e-12)
    p = ctl.belief.target_probabilities()["cup:top"]
    if yes:
        assert p > 0.98 and ctl.belief.confirmed == "cup:top"
    else:
        assert p < 0.01 and "cup:top" in ctl.belief.ruled_out
    assert ctl.plan.action == NO_ASSIST and ctl.current_action(2.0) == NO_ASSIST
    assert ctl.asked == frozenset({"cup:top"})  # still asked in this task
    assert ctl.snapshot(START, None) is not None  # a new plan is wanted


def test_answer_without_question_raises_and_changes_nothing():
    """An answer with no question pending is ``NoQuestion`` (a ``ValueError``); belief and plan stay."""
    ctl = make_ctl()
    feed(ctl, toward("cup:top"), 0.0)
    snap = ctl.snapshot(START, None)
    ctl.accept_plan(snap, result(move_to(snap.goals, "cup:top")), 0.0)
    belief, plan = ctl.belief, ctl.plan
    with pytest.raises(NoQuestion):
        ctl.on_answer(True, 0.05)
    assert issubclass(NoQuestion, ValueError)
    assert ctl.belief is belief and ctl.plan is plan and ctl.question is None and not ctl.asked


def test_question_expires_only_after_the_timeout():
    """``expire_question`` keeps a question up to ``runtime.question_timeout_s`` and drops it (with the
    plan) after that, returning it."""
    ctl, _ = pending_question(t=1.0)
    q = ctl.question
    timeout = CFG.runtime.question_timeout_s
    assert ctl.expire_question(1.0 + timeout / 2) is None and ctl.question == q
    assert ctl.expire_question(1.0 + timeout) is None and ctl.question == q
    assert ctl.expire_question(1.0 + timeout + 1e-6) == q
    assert ctl.question is None and ctl.plan.action == NO_ASSIST
    assert ctl.expire_question(1.0 + 2 * timeout) is None  # nothing left to expire


# -- 3. stale and refused input -------------------------------------------------------------------------


def test_input_older_than_the_stale_limit_commands_zero():
    """Input is fresh up to ``safety.stale_command_s`` after the sample; after that the tick is zero with
    code ``stale_input`` and ``fresh`` False."""
    ctl = make_ctl("manual")
    ctl.adopt_fixed()
    t0 = 1.0
    assert ctl.on_input([1.0, 0.0, 0.0], t0)
    for k in range(4):  # moving, from rest
        tick = ctl.tick(state(), t0 + k * CFG.safety.stale_command_s / 4)
        assert tick.fresh and np.any(tick.safety.twist)
    stale = t0 + CFG.safety.stale_command_s + 1e-3
    assert not ctl.input_fresh(stale)
    tick = ctl.tick(state(), stale)
    assert not tick.fresh and tick.safety.status is SafetyCode.STALE
    assert not np.any(tick.safety.twist) and not np.any(tick.command.total_twist)


def test_lost_input_is_stale_at_once():
    """``lose_input`` zeroes the axes and makes the very next tick stale, with no waiting."""
    ctl = make_ctl("manual")
    ctl.adopt_fixed()
    ctl.on_input([0.0, 1.0, 0.0], 1.0)
    assert ctl.tick(state(), 1.0).fresh
    ctl.lose_input()
    assert not np.any(ctl.axes) and ctl.t_input == -math.inf
    tick = ctl.tick(state(), 1.0)
    assert not tick.fresh and tick.safety.status is SafetyCode.STALE and not np.any(tick.safety.twist)


def test_stale_input_does_not_update_the_belief():
    """``update_belief`` with stale input returns False and leaves the belief object as it is."""
    ctl = make_ctl()
    assert feed(ctl, toward(TARGET), 0.0)
    updated = ctl.belief
    assert ctl.belief.probs[2] > 0.25  # the fresh sample moved it
    assert not ctl.update_belief(START, CFG.safety.stale_command_s + 1e-3)
    assert ctl.belief is updated
    ctl.lose_input()
    assert not ctl.update_belief(START, 0.0) and ctl.belief is updated


@pytest.mark.parametrize("bad", [
    [np.nan, 0.0, 0.0], [0.0, np.inf, 0.0], [0.0, 0.0, -np.inf], [0.1, 0.2], [0.1, 0.2, 0.3, 0.4],
    [[0.1, 0.2, 0.3]], 0.5,
])
def test_non_finite_or_misshapen_axes_are_refused(bad):
    """NaN/inf or a wrong shape: ``on_input`` returns False and axes, time and sequence stay."""
    ctl = make_ctl()
    assert ctl.on_input([0.2, -0.3, 0.4], 1.0)
    axes, t_in, seq = ctl.axes, ctl.t_input, ctl.input_seq
    assert ctl.on_input(bad, 2.0) is False
    np.testing.assert_array_equal(ctl.axes, axes)
    assert ctl.t_input == t_in and ctl.input_seq == seq


def test_axes_are_clipped_and_counted():
    """Accepted axes are clipped to [-1, 1] and counted in ``input_seq``."""
    ctl = make_ctl()
    assert ctl.on_input([2.0, -3.0, 0.5], 0.0) and ctl.input_seq == 1
    np.testing.assert_array_equal(ctl.axes, [1.0, -1.0, 0.5])


# -- 4. late plans and moot plans -----------------------------------------------------------------------


def test_move_expires_two_planner_periods_after_acceptance():
    """A move applies until ``t + 2 planner.period_s``; after that the tick is no-assist: no robot twist,
    the user's twist alone (through the pipeline)."""
    ctl = make_ctl()
    t = 3.0
    feed(ctl, toward(TARGET), t)
    snap = ctl.snapshot(START, None)
    action = move_to(snap.goals, TARGET)
    ctl.accept_plan(snap, result(action), t)
    until = t + 2 * CFG.planner.period_s
    assert ctl.plan.until == pytest.approx(until)
    assert ctl.current_action(until - 1e-6) == action
    tick = ctl.tick(state(), until - 1e-6)
    assert tick.command.action == action and np.any(tick.command.robot_twist)

    late = until + 1e-6
    feed(ctl, toward(TARGET), late)
    assert ctl.current_action(late) == NO_ASSIST
    tick = ctl.tick(state(), late)
    assert tick.command.action == NO_ASSIST and not tick.command.opposed
    assert not np.any(tick.command.robot_twist)
    np.testing.assert_array_equal(tick.command.total_twist, ctl.user_twist)


@pytest.mark.parametrize("margin", [0.0, 20.0])
def test_switch_margin_keeps_the_motion_on_near_ties_only(margin):
    """With ``planner.switch_margin`` the adopted motion stays while the new plan's motion beats it by less
    than the margin (in the new plan's own values); a larger lead, a question or an expired plan are not
    held back. With 0 (the paper) every plan is adopted as it comes."""
    ctl = make_ctl(cfg=config_from_dict({"planner": {"switch_margin": margin}}))
    t = 1.0
    feed(ctl, toward(TARGET), t)
    snap = ctl.snapshot(START, None)
    move = move_to(snap.goals, TARGET)

    def plan(best: Action, lead: float, at: float) -> PlanResult:
        values = {best: -100.0, move: -100.0 - lead, NO_ASSIST: -500.0}
        return PlanResult(best, -100.0, -100.0, 1, 1, 0.0, True, values)

    ctl.accept_plan(snap, plan(move, 0.0, t), t)
    ctl.accept_plan(snap, plan(HO_ACTION, 15.0, t + 0.1), t + 0.1)
    assert ctl.plan.action == (move if margin else HO_ACTION)
    ctl.accept_plan(snap, plan(HO_ACTION, 25.0, t + 0.2), t + 0.2)
    assert ctl.plan.action == HO_ACTION  # a lead above the margin switches

    ctl.accept_plan(snap, plan(move, 0.0, t + 0.3), t + 0.3)
    late = t + 0.3 + 2 * CFG.planner.period_s + 0.01  # the move expired: nothing to hold
    ctl.accept_plan(snap, plan(HO_ACTION, 1.0, late), late)
    assert ctl.plan.action == HO_ACTION

    ctl.accept_plan(snap, plan(move, 0.0, late + 0.1), late + 0.1)
    ctl.accept_plan(snap, PlanResult(HO_ACTION, -99.0, -99.0, 1, 1, 0.0, True, {move: -100.0}), late + 0.15)
    assert ctl.plan.action == HO_ACTION  # a plan that does not value both motions holds nothing
    ctl.accept_plan(snap, plan(move, 0.0, late + 0.17), late + 0.17)
    q = ctl.accept_plan(snap, PlanResult(ask(TARGET), -99.0, -99.0, 1, 1, 0.0, True,
                                         {ask(TARGET): -99.0, move: -100.0}), late + 0.2)
    assert q is not None and q.target == TARGET  # a question is never held back


def test_plan_for_another_method_is_moot():
    """After ``set_method`` a plan computed for the old method is ignored (move or question)."""
    ctl = make_ctl("policy")
    feed(ctl, toward(TARGET), 0.0)
    snap = ctl.snapshot(START, None)
    ctl.set_method("policy+noqns")
    plan = ctl.plan
    assert ctl.accept_plan(snap, result(move_to(snap.goals, TARGET)), 0.0) is None
    assert ctl.plan is plan and ctl.plan.action == NO_ASSIST
    assert ctl.accept_plan(snap, result(ask(TARGET)), 0.0) is None
    assert ctl.question is None and not ctl.asked


def test_set_method_drops_plan_and_question_and_refuses_unknown_names():
    """An unknown method name raises and changes nothing; a known one drops the plan and the question."""
    ctl, _ = pending_question()
    with pytest.raises(ValueError):
        ctl.set_method("nonsense")
    assert ctl.method == "policy" and ctl.question is not None
    ctl.set_method("policy+noho")
    assert ctl.question is None and ctl.plan.action == NO_ASSIST and ctl.method == "policy+noho"


def test_assist_off_gives_no_assist_and_back_on_the_plan():
    """Assistance off applies no-assist over an adopted move; back on, the move applies again."""
    ctl = make_ctl()
    feed(ctl, toward(TARGET), 0.0)
    snap = ctl.snapshot(START, None)
    action = move_to(snap.goals, TARGET)
    ctl.accept_plan(snap, result(action), 0.0)
    ctl.set_assist(False)
    assert ctl.current_action(0.0) == NO_ASSIST
    assert not np.any(ctl.tick(state(), 0.0).command.robot_twist)
    ctl.set_assist(True)
    assert ctl.current_action(0.0) == action


# -- 5. the arm's refusal reaches the simulated user ----------------------------------------------------


class _StuckJoints:
    """A 6-joint arm double (``Kinematics`` protocol) whose every joint sits within the pipeline's
    ``joint_margin_rad`` of both bounds: any motion is halted by the ``joint_bound`` stage. Its Jacobian
    is well conditioned (no singularity stage)."""

    def __init__(self, q: np.ndarray):
        m = CFG.safety.joint_margin_rad / 2
        self.lower, self.upper = q - m, q + m
        self.velocity_limit = np.full(6, 2.0)

    def jacobian(self, q):
        return np.diag([CFG.safety.characteristic_length_m] * 3 + [1.0] * 3)

    def joint_velocities(self, q, twist):
        return np.linalg.solve(self.jacobian(q), np.asarray(twist, dtype=float))

    def fk(self, q):  # pragma: no cover - unused by the pipeline
        return START


def _stuck_user_run(feedback: bool, seconds: float = 4.0):
    """Manual method, an arm whose joints refuse every motion, a seeded simulated user for ``cup:top``.
    ``feedback``: the user is told ``blocked=ctl.last.refused`` (as the daemon does), else False.
    Returns (user, per-step inputs, per-step ``tick.refused``, arm)."""
    q = np.zeros(6)
    kin = _StuckJoints(q)
    ctl = make_ctl("manual", kinematics=kin)
    rng = np.random.default_rng(7)
    goal = SCENE.goal("cup:top")
    user = SimulatedUser("cup:top", desired_pose(goal, START, CFG, rng, "closest"), CFG.sim_user, CFG.input, rng, DT)
    arm = KinematicArm(START, CFG.limits)
    inputs, refused = [], []
    for step in range(round(seconds / DT)):
        t = step * DT
        pose = arm.read().pose
        inp = user.act(pose, blocked=ctl.last.refused if feedback else False)
        ctl.set_mode(inp.mode)
        ctl.on_input(inp.axes, t)
        ctl.update_belief(pose, t)
        ctl.adopt_fixed()
        tick = ctl.tick(ArmState(pose, False, None, q), t)
        arm.command_twist(tick.safety.twist)
        arm.step(DT)
        inputs.append(inp)
        refused.append(tick.refused)
    return user, inputs, refused, arm


def test_joint_refusal_is_reported_and_turns_the_simulated_user_to_rotation():
    """A joint stage halting the user's push makes ``ctl.last.refused`` True; the user told so switches
    to aligning the gripper after ``sim_user.blocked_rotate_s``, one told nothing keeps translating."""
    told, told_inputs, told_refused, arm = _stuck_user_run(feedback=True)
    blind, blind_inputs, blind_refused, _ = _stuck_user_run(feedback=False)
    np.testing.assert_array_equal(arm.read().pose.position, START.position)  # the arm never moved
    assert all(blind_refused)  # every push is refused by the joint stage

    told_modes = [i.mode for i in told_inputs]
    switch = told_modes.index(Mode.ROTATION)
    # The first tick's refusal reaches the user at the second sample; it turns once blocked that long.
    blocked_s = CFG.sim_user.blocked_rotate_s
    assert blocked_s <= (switch - 1) * DT + 1e-9 <= blocked_s + DT
    assert all(told_refused[:switch])
    for a, b in zip(told_inputs[:switch], blind_inputs[:switch]):  # identical until the rule fires
        assert a.mode is b.mode and np.array_equal(a.axes, b.axes)
    assert told.phase is Phase.ALIGN and told.mode_changes == 1
    assert blind.phase is Phase.APPROACH and blind.mode_changes == 0
    assert all(i.mode is Mode.TRANSLATION for i in blind_inputs)


def test_workspace_limit_and_stop_zero_the_motion_but_are_not_refusals():
    """At the workspace box's edge the outward push is clipped (``workspace_limited``) and a latched stop
    zeroes everything (``stopped``); by definition (``SafetyResult.refuses``, docs/simulated-user.md
    item 5) only joint stages count as the arm refusing, so ``last.refused`` stays False for both."""
    hi = np.asarray(CFG.safety.workspace_max_m)
    edge = Pose(np.array([0.4, 0.0, hi[2]]), START.quat_wxyz)
    arm = KinematicArm(edge, CFG.limits)
    ctl = make_ctl("manual")
    ctl.adopt_fixed()
    for k in range(10):
        ctl.on_input([0.0, 0.0, 1.0], k * DT)  # straight up, out of the box
        tick = ctl.tick(arm.read(), k * DT)
        arm.command_twist(tick.safety.twist)
        arm.step(DT)
        assert SafetyCode.WORKSPACE in tick.safety.codes and tick.safety.twist[2] <= 0.0
        assert not ctl.last.refused
    assert arm.read().pose.position[2] <= hi[2] + 1e-12

    ctl.stop()
    assert ctl.stopped
    ctl.on_input([1.0, 0.0, 0.0], 1.0)
    tick = ctl.tick(arm.read(), 1.0)
    assert tick.safety.status is SafetyCode.STOPPED and not np.any(tick.safety.twist)
    assert np.any(tick.command.total_twist) and not ctl.last.refused
    ctl.resume()
    tick = ctl.tick(arm.read(), 1.0)
    assert not ctl.stopped and tick.safety.status is not SafetyCode.STOPPED
    assert_twist_step_within_accel(np.zeros(6), tick.safety.twist)  # restarts from rest


# -- 6. gripper -----------------------------------------------------------------------------------------


def test_gripper_closed_commands_zero_and_reopening_restarts_from_rest():
    """Closing (commanded) zeroes the tick with ``gripper_closed`` and wants no plan; on reopening the
    command restarts from zero and never changes by more than the acceleration limit per tick."""
    ctl = make_ctl("manual")
    ctl.adopt_fixed()
    axes = [0.5, -0.5, 0.5]  # 0.17 m/s: within every speed limit
    t = 0.0
    prev = np.zeros(6)
    for _ in range(20):  # up to speed
        ctl.on_input(axes, t)
        out = ctl.tick(state(), t).safety.twist
        assert_twist_step_within_accel(prev, out)
        prev, t = out, t + DT
    np.testing.assert_allclose(prev, ctl.user_twist)  # at full speed now

    ctl.set_gripper(True)
    assert ctl.gripper_closed and ctl.snapshot(START, None) is None
    ctl.on_input(axes, t)
    tick = ctl.tick(state(), t)
    assert tick.safety.status is SafetyCode.GRIPPER and not np.any(tick.safety.twist)
    # The arm reporting a closed gripper holds it too, whatever was commanded.
    ctl.set_gripper(False)
    assert ctl.tick(state(closed=True), t).safety.status is SafetyCode.GRIPPER

    prev = np.zeros(6)
    for k in range(20):
        t += DT
        ctl.on_input(axes, t)
        tick = ctl.tick(state(), t)
        assert SafetyCode.GRIPPER not in tick.safety.codes
        assert_twist_step_within_accel(prev, tick.safety.twist)
        if k == 0:
            assert np.any(tick.safety.twist)
        prev = tick.safety.twist
    np.testing.assert_allclose(prev, ctl.user_twist)


def test_gripper_closed_wants_no_plan_for_a_planned_method():
    """No snapshot while the gripper is commanded closed; one again once it is opened."""
    ctl = make_ctl("policy")
    assert ctl.snapshot(START, None) is not None
    ctl.set_gripper(True)
    assert ctl.snapshot(START, None) is None
    ctl.set_gripper(False)
    assert ctl.snapshot(START, None) is not None


# -- 7. reset -------------------------------------------------------------------------------------------


def test_reset_restores_a_fresh_task():
    """``reset``: uniform belief over the scene's goals, nothing asked or pending, no plan, translation
    mode, gripper open and the stop released."""
    ctl = make_ctl(cfg=sharp_cfg())
    drive_until_resampled(ctl, toward(TARGET), 0.0)
    assert len(ctl.belief.goals) != len(SCENE.goals)
    snap = ctl.snapshot(START, None)
    ctl.accept_plan(snap, result(move_to(snap.goals, TARGET)), 1.0)
    ctl.accept_plan(snap, result(ask(TARGET)), 1.0)
    ctl.set_mode(Mode.ROTATION)
    ctl.set_gripper(True)
    ctl.stop()
    assert ctl.question is not None and ctl.asked and ctl.stopped

    ctl.reset()
    assert ctl.belief.goals.goals == tuple(SCENE.goals)
    np.testing.assert_allclose(ctl.belief.probs, np.full(len(SCENE.goals), 1 / len(SCENE.goals)))
    assert ctl.belief.confirmed is None and not ctl.belief.ruled_out
    assert ctl.asked == frozenset() and ctl.question is None
    assert ctl.plan.action == NO_ASSIST and ctl.plan.goals is ctl.belief.goals
    assert ctl.mode is Mode.TRANSLATION and not ctl.gripper_closed and not ctl.stopped
    assert ctl.questions_asked == 1  # counted over the controller's life
    ctl.on_input([1.0, 0.0, 0.0], 2.0)
    tick = ctl.tick(state(), 2.0)
    assert tick.safety.status not in ZEROING and np.any(tick.safety.twist)
    assert ctl.snapshot(START, None) is not None



def test_reset_keeps_the_arms_joint_model():
    """``reset`` starts a task; it does not forget the arm's joints (the joint stages keep acting), and
    ``use_arm`` replaces them when the arm is rebuilt."""
    q = np.zeros(6)
    ctl = make_ctl(kinematics=_StuckJoints(q))
    push = [1.0, 0.0, 0.0]

    def codes_after_push(t: float) -> tuple:
        ctl.on_input(push, t)
        return ctl.tick(state(joints=q), t).safety.codes

    assert SafetyCode.JOINT_BOUND in codes_after_push(0.0)
    ctl.reset()
    assert SafetyCode.JOINT_BOUND in codes_after_push(1.0)
    ctl.use_arm(None)
    assert SafetyCode.JOINT_BOUND not in codes_after_push(2.0)


def test_plans_of_the_previous_task_or_after_the_grasp_are_moot():
    """A plan whose snapshot was taken before ``reset`` is ignored (the next task must not inherit the
    last one's question or move), and so is a question chosen before the gripper closed."""
    ctl = make_ctl()
    old = ctl.snapshot(START, None)
    ctl.reset()
    assert ctl.accept_plan(old, result(ask("cup:top")), 1.0) is None
    assert ctl.question is None and ctl.asked == frozenset()
    assert ctl.accept_plan(old, result(move_to(old.goals, "cup:top")), 1.0) is None
    assert ctl.plan.action == NO_ASSIST
    fresh = ctl.snapshot(START, None)
    ctl.set_gripper(True)
    assert ctl.accept_plan(fresh, result(ask("cup:top")), 1.0) is None
    assert ctl.question is None
    ctl.set_gripper(False)
    assert ctl.accept_plan(fresh, result(ask("cup:top")), 1.0) is not None  # same task, gripper open

# -- 8. rule-based methods ------------------------------------------------------------------------------


@pytest.mark.parametrize("method, action", [("manual", NO_ASSIST), ("ho", HO_ACTION)])
def test_rule_based_methods_adopt_their_fixed_action(method, action):
    """``adopt_fixed`` gives ``manual`` no-assist and ``ho`` the HO action, with no expiry, and the tick
    blends it as the model does. (Their snapshot, if the caller asks for one, is answered by the solver
    with the same fixed action at once: ``Controller.snapshot``'s doc.)"""
    ctl = make_ctl(method)
    feed(ctl, toward(TARGET), 0.0)
    ctl.adopt_fixed()
    assert ctl.plan.action == action and ctl.plan.until == math.inf
    assert ctl.plan.goals is ctl.belief.goals
    assert ctl.current_action(1e6) == action
    tick = ctl.tick(state(), 0.0)
    assert tick.command.action == action
    want = ctl.model.command(action, ctl.belief.goals, ctl.belief.probs, START, ctl.user_twist, method)
    np.testing.assert_allclose(tick.command.robot_twist, want.robot_twist, atol=1e-12)
    np.testing.assert_allclose(tick.command.total_twist, want.total_twist, atol=1e-12)
    assert np.any(tick.command.robot_twist) == (method == "ho")

    snap = ctl.snapshot(START, None)
    if snap is not None:  # the current contract: planned without search, to the same action
        res = Solver(ctl.model).plan(snap)
        assert res.action == action and res.nodes == 0
        assert ctl.accept_plan(snap, res, 1.0) is None and ctl.current_action(1.0) == action
        assert ctl.question is None


# -- 9. closed loop -------------------------------------------------------------------------------------


def test_closed_loop_policy_reaches_cup_top_within_limits():
    """Kinematic arm, seeded simulated user, real solver (``eval.node_budget``), method ``policy`` on
    scene1 ``cup:top`` at 40 Hz: the user closes the gripper at its goal within 40 s; every command is
    within the speed limits and changes by at most the acceleration limit per tick unless a zeroing stage
    acted."""
    cfg = CFG
    rng = np.random.default_rng(3)
    goal = SCENE.goal("cup:top")
    user = SimulatedUser("cup:top", desired_pose(goal, START, cfg, rng, "closest"), cfg.sim_user, cfg.input, rng, DT)
    arm = KinematicArm(START, cfg.limits)
    ctl = make_ctl("policy")
    solver = Solver(ctl.model)
    plan_every = max(1, round(cfg.planner.period_s / DT))
    lo, hi = np.asarray(cfg.safety.workspace_min_m), np.asarray(cfg.safety.workspace_max_m)
    prev = np.zeros(6)
    kinds: set[ActionKind] = set()
    closed = False
    for step in range(round(40.0 / DT)):
        t = step * DT
        pose = arm.read().pose
        inp = user.act(pose, listening=ctl.question is not None, blocked=ctl.last.refused)
        if inp.close:
            arm.command_gripper(True)
            ctl.set_gripper(True)
            closed = True
            break
        ctl.set_mode(inp.mode)
        assert ctl.on_input(inp.axes, t)
        assert ctl.update_belief(pose, t)
        answered = False
        q = ctl.question
        if q is not None and t - q.asked_at >= cfg.sim_user.answer_delay_s - 1e-9:
            ctl.on_answer(user.answer(q.target), t)
            answered = True
        if step % plan_every == 0 or answered:
            snap = ctl.snapshot(pose, budget_s=None, node_budget=cfg.eval.node_budget)
            if snap is not None:
                ctl.accept_plan(snap, solver.plan(snap), t)
        tick = ctl.tick(arm.read(), t)
        out = tick.safety.twist
        assert tick.error is None and tick.fresh
        kinds.add(tick.command.action.kind)
        assert np.all(np.abs(out[:3]) <= cfg.limits.linear_mps + 1e-12)
        assert np.all(np.abs(out[3:]) <= cfg.limits.angular_radps + 1e-12)
        if not set(tick.safety.codes) & ZEROING:
            assert_twist_step_within_accel(prev, out)
        prev = out
        arm.command_twist(out)
        arm.step(DT)
        p = arm.read().pose.position
        assert np.all(p >= lo - 1e-9) and np.all(p <= hi + 1e-9)
    assert closed, "the user never closed the gripper within 40 s"
    assert user.at_goal(arm.read().pose)
    assert ActionKind.MOVE in kinds  # the planner's assistance took part
    assert ctl.belief.target_probabilities()["cup:top"] > 0.5
    assert ctl.snapshot(arm.read().pose, None) is None  # gripper closed: no plan wanted


@pytest.mark.parametrize("idle", ["decay", "hold"])
def test_the_predicted_user_speed_over_a_pause_decays_or_holds(idle):
    """``planner.user_speed_idle``: 2 s of full deflection, then 2 s of a released stick (zero input, still
    fresh). ``decay`` averages the zeros in (time constant ``user_speed_tau_s`` = 1 s: e^-2 of the speed
    left); ``hold`` keeps the speed the user moved at. The other mode's speed is untouched either way (a mode
    not yet entered predicted still, ``user_speed_unused = "zero"``; the deflection: ``test_user_speed.py``)."""
    cfg = config_from_dict({"planner": {"user_speed_idle": idle, "user_speed_unused": "zero"}})
    ctl = make_ctl(cfg=cfg)
    t = 0.0
    for _ in range(80):
        t += DT
        feed(ctl, [1.0, 0.0, 0.0], t)
    moving = ctl.user_speed[0]
    assert moving > 0.5 * cfg.input.linear_scale_mps and ctl.user_speed[1] == 0.0
    for _ in range(80):
        t += DT
        feed(ctl, [0.0, 0.0, 0.0], t)
    if idle == "hold":
        assert ctl.user_speed[0] == moving
    else:
        assert ctl.user_speed[0] == pytest.approx(moving * math.exp(-2.0), rel=0.05)
    assert ctl.user_speed[1] == 0.0
