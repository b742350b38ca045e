"""The planning problem (move rewards by lookahead rollouts, bounds) and the anytime solver.

The solver is checked against a brute-force reference written here: plain recursion over question
sequences, no pruning, no memoisation, taking from :class:`Problem` only the move rewards ``M``, the HO
rewards, the answer likelihoods ``L_yes`` and the question list.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from sa_daemon.config import Config, config_from_dict
from sa_daemon.geometry import (
    Pose,
    integrate_pose,
    quat_angle,
    quat_mul,
    rotvec_to_quat,
    rpy_to_quat,
)
from sa_daemon.model.actions import ActionKind
from sa_daemon.model.huber import goal_gradients
from sa_daemon.model.model import SharedAutonomyModel
from sa_daemon.model.reward import distance_reward, opposes
from sa_daemon.model.twists import blend, ho_twist, move_twist
from sa_daemon.planner.problem import Problem
from sa_daemon.planner.snapshot import Snapshot
from sa_daemon.planner.solver import Solver
from sa_daemon.world.goals import Goal, GraspType
from sa_daemon.world.goalset import GoalSet

TOP = (math.pi, 0.0, 0.0)


def config(H: int = 15, top_goals: int = 3, max_questions: int = 10, every_step: bool = False) -> Config:
    return config_from_dict(
        {
            # The commit model (moves end the search) with the paper's question cost and Javdani's HO.
            "reward": {"lookahead_steps": H, "opposition_every_step": every_step, "question_time_s": 0.0},
            "planner": {"model": "commit", "top_goals": top_goals, "max_questions": max_questions},
            "ho": {"generator": "gradient"},
            # The geometry of these tests was laid out for move limits equal to the joystick's.
            "move": {"linear_max_mps": 0.2, "angular_max_radps": 0.4},
        }
    )


# -- brute-force reference ------------------------------------------------------------------------------


def move_value(prob: Problem, b: np.ndarray) -> float:
    vals = [float(b @ prob.M[:, a]) for a in range(prob.M.shape[1])]
    return max(vals) if vals else -math.inf


def answers(prob: Problem, b: np.ndarray, q: int):
    """``(P(yes), b_yes, b_no)`` after question ``q``."""
    like = prob.L_yes[q]
    p_yes = float(like @ b)
    return p_yes, like * b / p_yes, (1.0 - like) * b / (1.0 - p_yes)


def question_value(prob: Problem, b: np.ndarray, q: int, asked: frozenset[int], depth: int) -> float:
    p_yes, b_yes, b_no = answers(prob, b, q)
    asked = asked | {q}
    return prob.q_reward + prob.cfg.reward.gamma * (
        p_yes * reference_value(prob, b_yes, asked, depth - 1)
        + (1.0 - p_yes) * reference_value(prob, b_no, asked, depth - 1)
    )


def reference_value(prob: Problem, b: np.ndarray, asked: frozenset[int], depth: int) -> float:
    """``V(b)`` with at most ``depth`` more questions, none repeated."""
    best = move_value(prob, b)
    if depth > 0:
        for q in range(len(prob.questions)):
            if q not in asked:
                best = max(best, question_value(prob, b, q, asked, depth))
    return best


def reference_action_value(prob: Problem, action) -> float:
    """Reference value at the root of taking ``action`` first, then playing optimally."""
    b, depth = prob.b0, prob.cfg.planner.max_questions
    if action.kind is ActionKind.QUESTION:
        assert depth > 0
        return question_value(prob, b, prob.questions.index(action), frozenset(), depth)
    assert action in prob.moves
    return float(b @ prob.M[:, prob.moves.index(action)])


def reference_optimum(prob: Problem) -> float:
    return reference_value(prob, prob.b0, frozenset(), prob.cfg.planner.max_questions)


# -- random small problems ------------------------------------------------------------------------------

OBJECTS = ("cup", "bowl", "can", "plate", "box", "jar")
METHODS = ("policy",) * 4 + ("policy+noho", "policy+withoutnoassist", "policy+noqns")


def random_problem(seed: int) -> tuple[Config, Snapshot]:
    rng = np.random.default_rng(seed)
    n = int(rng.integers(3, 7))
    center = np.array([0.4, 0.0, 0.15])
    spread = float(rng.choice([0.03, 0.08, 0.2]))  # near goals make questions worth asking
    goals = []
    for i in range(n):
        poses = tuple(
            Pose(center + rng.normal(size=3) * spread, rpy_to_quat(rng.normal(size=3) * rng.choice([0.2, 1.0, 3.0])))
            for _ in range(int(rng.integers(1, 3)))
        )
        goals.append(Goal(OBJECTS[i], GraspType("top" if i % 2 else "side"), poses))
    if rng.random() < 0.3:  # a resampled target: two copies sharing "cup:side", split grasp poses
        extra = Pose(center + rng.normal(size=3) * spread, goals[0].poses[0].quat_wxyz)
        goals.append(goals[0].with_poses((extra,)))
    probs = rng.dirichlet(np.full(len(goals), float(rng.choice([0.2, 1.0, 10.0])))) + 1e-6
    pose = Pose(center + rng.normal(size=3) * spread, rpy_to_quat(rng.normal(size=3)))
    u = np.zeros(6)
    kind = rng.integers(0, 3)
    if kind == 1:
        u[:3] = rng.normal(size=3) * 0.1
    elif kind == 2:
        u[3:] = rng.normal(size=3) * 0.2
    asked = frozenset({goals[1].target}) if rng.random() < 0.2 else frozenset()
    cfg = config(
        H=int(rng.choice([1, 15])),
        top_goals=int(rng.integers(2, 5)),
        max_questions=int(rng.choice([1, 2, 3, 10])),
    )
    method = str(rng.choice(METHODS))
    return cfg, Snapshot(GoalSet(tuple(goals)), probs, pose, u, asked=asked, method=method, budget_s=None)


SEEDS = range(200)


@pytest.mark.parametrize("seed", SEEDS)
def test_solver_matches_brute_force(seed):
    cfg, snap = random_problem(seed)
    model = SharedAutonomyModel(cfg)
    prob = Problem(model, snap)
    opt = reference_optimum(prob)
    res = Solver(model).plan(snap)
    assert res.complete
    assert res.value == pytest.approx(opt, abs=1e-9)
    assert res.upper_bound == pytest.approx(opt, abs=1e-9)
    assert reference_action_value(prob, res.action) == pytest.approx(opt, abs=1e-9)


def test_random_problems_exercise_both_questions_and_moves():
    kinds = set()
    for seed in range(40):
        cfg, snap = random_problem(seed)
        kinds.add(Solver(SharedAutonomyModel(cfg)).plan(snap).action.kind)
    assert ActionKind.QUESTION in kinds and ActionKind.MOVE in kinds


@pytest.mark.parametrize("seed", range(0, 40, 4))
def test_node_budget_is_deterministic_and_bracketed(seed):
    cfg, snap = random_problem(seed)
    model = SharedAutonomyModel(cfg)
    prob = Problem(model, snap)
    opt = reference_optimum(prob)
    for budget in (1, 3, 8):
        limited = Snapshot(snap.goals, snap.probs, snap.pose, snap.user_twist, asked=snap.asked,
                           method=snap.method, budget_s=None, node_budget=budget)
        a, b = Solver(model).plan(limited), Solver(model).plan(limited)
        assert (a.action, a.value, a.upper_bound, a.depth, a.nodes, a.complete) == (
            b.action, b.value, b.upper_bound, b.depth, b.nodes, b.complete
        )
        assert a.value <= opt + 1e-9 <= a.upper_bound + 2e-9
        # the reported value is achieved by the chosen action
        assert reference_action_value(prob, a.action) >= a.value - 1e-9


def test_tiny_time_budget_still_returns_an_action():
    cfg, snap = random_problem(1)
    model = SharedAutonomyModel(cfg)
    rushed = Snapshot(snap.goals, snap.probs, snap.pose, snap.user_twist, method="policy", budget_s=1e-9)
    res = Solver(model).plan(rushed)
    assert res.action is not None
    assert math.isfinite(res.value)
    assert res.value <= reference_optimum(Problem(model, rushed)) + 1e-9


# -- constructed cases ----------------------------------------------------------------------------------


def turned(q, rotvec):
    return quat_mul(rotvec_to_quat(np.asarray(rotvec, dtype=float)), q)


P = np.array([0.45, 0.0, 0.10])
Q = rpy_to_quat(TOP)


def same_place_goals(angle: float, axes) -> GoalSet:
    """Goals at one position whose orientations are the gripper's (``Q``) turned by ``angle`` about ``axes``."""
    names = ("cup", "bowl", "plate")
    return GoalSet(
        tuple(Goal(n, GraspType.TOP, (Pose(P, turned(Q, angle * np.asarray(ax))),)) for n, ax in zip(names, axes))
    )


@pytest.mark.parametrize(
    "half_angle, margin",
    [
        (0.12, 10.0),  # committing reaches either goal (+100) within the 1.5 s lookahead: guessing is a coin flip
        (math.pi / 4, 0.05),  # 90 deg apart: only the rotation reward is at stake, still worth a question
    ],
)
def test_question_is_optimal_when_two_goals_differ_only_in_orientation(half_angle, margin):
    # Gripper at the common position, its orientation halfway between the two goals', belief 50/50.
    goals = same_place_goals(half_angle, ([1, 0, 0], [-1, 0, 0]))
    model = SharedAutonomyModel(config(H=15, top_goals=10))
    snap = Snapshot(goals, np.array([0.5, 0.5]), Pose(P, Q), np.zeros(6), budget_s=None)
    prob = Problem(model, snap)
    res = Solver(model).plan(snap)
    assert res.is_question and res.complete
    assert res.value == pytest.approx(reference_optimum(prob), abs=1e-9)
    assert res.value > move_value(prob, prob.b0) + margin


def test_move_is_optimal_when_the_belief_is_concentrated():
    goals = same_place_goals(0.12, ([1, 0, 0], [-1, 0, 0]))
    model = SharedAutonomyModel(config(H=15, top_goals=10))
    snap = Snapshot(goals, np.array([0.98, 0.02]), Pose(P, Q), np.zeros(6), budget_s=None)
    res = Solver(model).plan(snap)
    assert res.action.kind is ActionKind.MOVE and res.action.target == "cup:top"
    assert res.complete
    assert res.value == pytest.approx(reference_optimum(Problem(model, snap)), abs=1e-9)


def test_two_questions_worth_asking_when_one_alone_is_not():
    # Three goals in one place, 0.12 rad from the gripper's orientation each; cup 0.85 likely.
    # Asking one question never beats moving to the cup, but asking "cup?" and, after a "no", "bowl?" does:
    # a depth-1 search must not prune its way to a false proof of optimality.
    goals = same_place_goals(0.12, ([1, 0, 0], [0, 1, 0], [-1, 0, 0]))
    model = SharedAutonomyModel(config(H=15, top_goals=3, max_questions=3))
    snap = Snapshot(goals, np.array([0.85, 0.075, 0.075]), Pose(P, Q), np.zeros(6), budget_s=None)
    prob = Problem(model, snap)
    m = move_value(prob, prob.b0)
    assert reference_value(prob, prob.b0, frozenset(), 1) == pytest.approx(m, abs=1e-12)
    opt = reference_optimum(prob)
    assert opt > m + 1.0
    res = Solver(model).plan(snap)
    assert res.complete and res.is_question
    assert res.value == pytest.approx(opt, abs=1e-9)


def test_no_questions_for_policy_noqns():
    goals = same_place_goals(0.12, ([1, 0, 0], [-1, 0, 0]))
    model = SharedAutonomyModel(config(H=15, top_goals=10))
    snap = Snapshot(goals, np.array([0.5, 0.5]), Pose(P, Q), np.zeros(6), method="policy+noqns", budget_s=None)
    res = Solver(model).plan(snap)
    assert res.action.kind is not ActionKind.QUESTION and res.complete


def test_max_questions_zero_plans_the_best_move():
    goals = same_place_goals(0.12, ([1, 0, 0], [-1, 0, 0]))
    model = SharedAutonomyModel(config(H=15, top_goals=10, max_questions=0))
    snap = Snapshot(goals, np.array([0.5, 0.5]), Pose(P, Q), np.zeros(6), budget_s=None)
    prob = Problem(model, snap)
    res = Solver(model).plan(snap)
    assert res.complete and not res.is_question
    assert res.value == pytest.approx(move_value(prob, prob.b0), abs=1e-12)


def test_asked_targets_are_not_asked_again():
    goals = same_place_goals(0.12, ([1, 0, 0], [-1, 0, 0]))
    model = SharedAutonomyModel(config(H=15, top_goals=10))
    snap = Snapshot(goals, np.array([0.5, 0.5]), Pose(P, Q), np.zeros(6), asked=frozenset({"cup:top"}), budget_s=None)
    res = Solver(model).plan(snap)
    assert res.complete
    assert res.action.target != "cup:top" or res.action.kind is not ActionKind.QUESTION
    assert res.value == pytest.approx(reference_optimum(Problem(model, snap)), abs=1e-9)


def test_snapshot_refuses_non_finite_input(scene, start_pose):
    with pytest.raises(ValueError):
        Snapshot(scene, np.full(4, 0.25), start_pose, np.array([0, 0, np.nan, 0, 0, 0]))
    with pytest.raises(ValueError):
        Snapshot(scene, np.array([0.5, np.inf, 0.0, 0.0]), start_pose, np.zeros(6))


def test_rule_based_methods_answer_without_search(scene, start_pose):
    model = SharedAutonomyModel(Config())
    snap = Snapshot(scene, np.full(4, 0.25), start_pose, np.zeros(6), method="ho", budget_s=None)
    res = Solver(model).plan(snap)
    assert res.action.kind is ActionKind.HO and res.nodes == 0


# -- Problem: move rewards by hand rollout --------------------------------------------------------------


def hand_desired_poses(goals: GoalSet, pose: Pose, w: float = 0.05):
    """``k_c`` of each goal: the grasp pose minimising ``d_trans + w d_rot`` to the gripper."""
    kp, kq = [], []
    for g in goals.goals:
        best = min(g.poses, key=lambda k: math.dist(k.position, pose.position) + w * float(quat_angle(k.quat_wxyz, pose.quat_wxyz)))
        kp.append(best.position)
        kq.append(best.quat_wxyz)
    return np.array(kp), np.array(kq)


def hand_rollout(cfg: Config, action, pose: Pose, u: np.ndarray, kp, kq, b0) -> np.ndarray:
    """Reward vector over goals of one move action: H steps, then distance reward; the opposition penalty
    at step 0, or at every step it is predicted with ``opposition_every_step``."""
    pos, quat = pose.position.copy(), pose.quat_wxyz.copy()
    penalty = 0.0
    for step in range(cfg.reward.lookahead_steps):
        if action.kind is ActionKind.MOVE:
            r = move_twist(pos, quat, kp[action.goal], kq[action.goal], cfg.move)
        elif action.kind is ActionKind.HO:
            r = ho_twist(b0, goal_gradients(pos, quat, u, kp, kq, cfg.intent, cfg.ho))
        else:
            r = np.zeros(6)
        total = u if action.kind is ActionKind.NONE else blend(u, r, cfg.blend)
        if (step == 0 or cfg.reward.opposition_every_step) and opposes(u, r, cfg.reward.opposition_threshold):
            penalty += cfg.reward.opposition_penalty
        pos, quat = integrate_pose(pos, quat, total, cfg.reward.step_s)
    out = []
    for g in range(len(kp)):
        d_t = math.dist(pos, kp[g])
        d_r = float(quat_angle(quat, kq[g]))
        out.append(float(distance_reward(d_t, d_r, cfg.reward)) + penalty)
    return np.array(out)


@pytest.mark.parametrize("every_step", [False, True], ids=["oppose-first", "oppose-every"])
@pytest.mark.parametrize("H", [1, 15])
@pytest.mark.parametrize(
    "user", [[0, 0, 0, 0, 0, 0], [-0.15, 0.05, 0, 0, 0, 0], [0, 0, 0, 0.3, 0, -0.2]], ids=["still", "lin", "rot"]
)
def test_move_rewards_equal_a_hand_rollout(make_goal, start_pose, H, user, every_step):
    p = start_pose.position
    goals = GoalSet(
        (
            make_goal("cup", "top", [0.45, 0.15, 0.09], [0.30, 0.02, 0.30]),  # two poses: k_c is the second
            make_goal("cup", "side", [0.45, 0.15, 0.05]),
            make_goal("can", "side", [0.50, -0.10, 0.12]),
            make_goal("bowl", "top", p + [0.005, 0.0, -0.005], rpy=[math.pi, -math.pi / 4 + 0.02, 0.0]),
        )
    )
    cfg = config(H=H, top_goals=10, every_step=every_step)
    probs = np.array([0.4, 0.3, 0.2, 0.1])
    u = np.asarray(user, dtype=float)
    snap = Snapshot(goals, probs, start_pose, u, budget_s=None)
    prob = Problem(SharedAutonomyModel(cfg), snap)
    kp, kq = hand_desired_poses(goals, start_pose)
    np.testing.assert_allclose(kp[0], [0.30, 0.02, 0.30])
    assert prob.M.shape == (4, len(prob.moves))
    for a, action in enumerate(prob.moves):
        want = hand_rollout(cfg, action, start_pose, u, kp, kq, probs)
        np.testing.assert_allclose(prob.M[:, a], want, atol=1e-9, err_msg=action.label)


def test_reaching_the_goal_in_the_lookahead_earns_the_bonus(make_goal, start_pose):
    near = make_goal("bowl", "top", start_pose.position + [0.005, 0.0, 0.0], rpy=[math.pi, -math.pi / 4, 0.0])
    far = make_goal("cup", "top", [0.45, 0.15, 0.09])
    goals = GoalSet((near, far))
    prob = Problem(SharedAutonomyModel(config(H=15)), Snapshot(goals, np.array([0.5, 0.5]), start_pose, np.zeros(6)))
    move_near = next(i for i, a in enumerate(prob.moves) if a.kind is ActionKind.MOVE and a.goal == 0)
    assert prob.M[0, move_near] > 90.0  # without the +100 bonus every reward is <= 0


def test_opposition_penalty_judged_on_the_first_step(make_goal, start_pose):
    goal = make_goal("cup", "top", start_pose.position + [0.2, 0.0, 0.0], rpy=[math.pi, -math.pi / 4, 0.0])
    goals = GoalSet((goal, make_goal("bowl", "top", start_pose.position + [0.0, 0.2, 0.0])))
    u = np.array([-0.2, 0.0, 0.0, 0.0, 0.0, 0.0])  # away from the cup
    cfg = config(H=1)
    prob = Problem(SharedAutonomyModel(cfg), Snapshot(goals, np.array([0.5, 0.5]), start_pose, u))
    kp, kq = hand_desired_poses(goals, start_pose)
    cup = next(i for i, a in enumerate(prob.moves) if a.kind is ActionKind.MOVE and a.goal == 0)
    none = next(i for i, a in enumerate(prob.moves) if a.kind is ActionKind.NONE)
    # after one step the blended twist is 0.5 * (-0.2) + 0.5 * 0.2 = 0 along x: the gripper stays put
    d_t = float(np.linalg.norm(kp[0] - start_pose.position))
    d_r = float(quat_angle(kq[0], start_pose.quat_wxyz))
    assert prob.M[0, cup] == pytest.approx(float(distance_reward(d_t, d_r, cfg.reward)) - 5.0, abs=1e-9)
    assert prob.M[0, none] > prob.M[0, cup] - 5.0  # no-assist never opposes


@pytest.mark.parametrize("every_step, steps_charged", [(False, 1), (True, 15)])
def test_a_move_that_keeps_opposing_pays_at_every_lookahead_step(make_goal, start_pose, every_step, steps_charged):
    # The user turns the gripper about z; the cup's grasp wants the opposite turn for the whole window.
    goal = make_goal("cup", "top", start_pose.position, rpy=[math.pi, -math.pi / 4, -1.0])
    goals = GoalSet((goal, make_goal("bowl", "top", start_pose.position + [0.0, 0.3, 0.0])))
    u = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.3])
    both = [Problem(SharedAutonomyModel(config(H=15, every_step=e)), Snapshot(goals, np.array([0.5, 0.5]), start_pose, u))
            for e in (False, every_step)]
    cup = next(i for i, a in enumerate(both[0].moves) if a.kind is ActionKind.MOVE and a.goal == 0)
    extra = (steps_charged - 1) * -5.0
    np.testing.assert_allclose(both[1].M[:, cup], both[0].M[:, cup] + extra, atol=1e-9)


# -- Problem: upper bounds ------------------------------------------------------------------------------


@pytest.mark.parametrize("seed", range(0, 40, 5))
def test_upper_bounds_dominate_every_achievable_reward(seed):
    cfg, snap = random_problem(seed)
    prob = Problem(SharedAutonomyModel(cfg), snap)
    rng = np.random.default_rng(1000 + seed)
    assert np.all(prob.U[:, None] >= prob.M - 1e-12)
    floor = cfg.reward.question / (1.0 - cfg.reward.gamma)
    assert np.all(prob.U >= floor - 1e-12)
    for _ in range(20):
        b = rng.dirichlet(np.full(len(snap.goals), float(rng.choice([0.1, 1.0]))))
        # the linear bound dominates the optimal value of any belief
        assert float(b @ prob.U) >= reference_value(prob, b, frozenset(), cfg.planner.max_questions) - 1e-9


@pytest.mark.parametrize("seed", range(40))
def test_question_time_cost_is_the_forgone_share_of_the_best_moves_gain(seed):
    cfg, snap = random_problem(seed)
    base = Problem(SharedAutonomyModel(cfg), snap)
    timed_cfg = config_from_dict({**cfg.model_dump(mode="json"), "reward": {
        **cfg.model_dump(mode="json")["reward"], "question_time_s": 0.75}})
    timed = Problem(SharedAutonomyModel(timed_cfg), snap)
    assert base.q_reward == cfg.reward.question  # 0 s: the paper's fixed question reward
    if not base.moves:
        assert timed.q_reward == base.q_reward
        return
    stay = base._rewards_at(snap.pose.position[None], snap.pose.quat_wxyz[None])[0]
    gain = max(0.0, float(base.move_values(snap.probs)[0] - snap.probs @ stay))
    assert timed.q_reward == pytest.approx(cfg.reward.question - gain * 0.75 / (base.H * base.dt))
    # The solver stays exact with the extra (constant) cost.
    assert Solver(SharedAutonomyModel(timed_cfg)).plan(snap).value == pytest.approx(reference_optimum(timed), abs=1e-6)
