"""The watch model (``planner.model = "watch"``, the default planner): rollouts and search.

These tests pin its pieces (the predicted user, the rollouts, the batched search against a plain
recursion); ``test_when_to_ask.py`` pins the paper's behaviours.
"""

from __future__ import annotations

import time

import numpy as np
import pytest
from helpers import predicted_input

from sa_daemon.config import config_from_dict
from sa_daemon.geometry import Pose, quat_angle, turn
from sa_daemon.model.actions import HO_ACTION, NO_ASSIST, Action, ActionKind, Mode
from sa_daemon.model.huber import pregrasp_points, q_minus_v_at
from sa_daemon.model.model import SharedAutonomyModel
from sa_daemon.model.reward import approach_return
from sa_daemon.model.twists import (
    ho_angular,
    ho_linear,
    user_angular,
    user_linear,
)
from sa_daemon.planner.node_keys import distinct_rows
from sa_daemon.planner.rollouts import Rollouts
from sa_daemon.planner.snapshot import Snapshot
from sa_daemon.planner.solver import Solver
from sa_daemon.planner.watch import MAX_BATCH, WatchSearch
from sa_daemon.world.scene import load_scene

SCENE = load_scene("scene1")


def _cfg(**planner):
    return config_from_dict({"planner": {"model": "watch", **planner}, "reward": {"question_time_s": 2.0}}, "test")


def _snap(speed=(0.02, 0.0), probs=None, budget_s=None):
    goals = SharedAutonomyModel().initial_belief(SCENE.goals).goals
    p = np.full(len(goals), 1.0 / len(goals)) if probs is None else np.asarray(probs, dtype=float)
    return Snapshot(goals, p, SCENE.start, np.zeros(6), budget_s=budget_s, user_speed=speed)


def test_the_predicted_user_heads_to_the_goal_at_its_speed_and_slows_near_it():
    p, q = SCENE.start.position, SCENE.start.quat_wxyz
    goal = p + np.array([0.3, 0.0, -0.4])
    u = user_linear(p, goal, pregrasp_points(goal, q, 0.0), 0.05, 0.0)
    assert np.linalg.norm(u) == pytest.approx(0.05)
    assert np.allclose(u / 0.05, (goal - p) / 0.5)
    near_goal = p + np.array([0.01, 0.0, 0.0])
    near = user_linear(p, near_goal, pregrasp_points(near_goal, q, 0.0), 0.05, 0.0)
    assert near[0] == pytest.approx(0.01)  # slows within a second of the goal
    assert np.all(user_angular(q, q, 0.2) == 0.0)  # aligned already


def test_the_predicted_user_aims_behind_the_grasp_until_close():
    grasp = SCENE.goal("cup:side").poses[0]
    pre = pregrasp_points(grasp.position, grasp.quat_wxyz, 0.06)
    assert np.allclose(pre, grasp.position - 0.06 * grasp.rotation[:, 2])
    far = grasp.position + np.array([-0.3, 0.0, 0.2])
    u = user_linear(far, grasp.position, pre, 0.05, 0.06)
    assert np.allclose(u / np.linalg.norm(u), (pre - far) / np.linalg.norm(pre - far))
    close = grasp.position - 0.05 * grasp.rotation[:, 2] + np.array([0.0, 0.0, 0.02])  # within 9 cm
    v = user_linear(close, grasp.position, pre, 0.05, 0.06)
    assert np.allclose(v / np.linalg.norm(v), (grasp.position - close) / np.linalg.norm(grasp.position - close))


def test_rollouts_standing_still_earn_the_stay_reward_each_step_and_a_move_gains_on_its_own_goal():
    cfg = _cfg()
    snap = _snap(speed=(0.0, 0.0))
    goals = snap.goals
    kp, kq = goals.desired_poses(snap.pose, cfg.intent.rotation_weight_m_per_rad)
    actions = [Action(ActionKind.MOVE, 0, goals.goals[0].target), HO_ACTION, NO_ASSIST]
    R = Rollouts(cfg, snap.pose.position[None], snap.pose.quat_wxyz[None], snap.probs[None], kp, kq, actions,
                 Mode.TRANSLATION, (0.0, 0.0), steps=8, dt=0.25, watch_steps=4)
    none = R.value[0, :, 2, :]  # an idle user and no assistance: the arm stands, each step earns stay
    assert np.allclose(none, none[:, :1] + np.arange(9)[None] * R.stay[0][:, None])
    assert np.all(R.stay < 0.0)  # far from every goal, standing costs
    assert R.value[0, 0, 0, 8] > R.value[0, 0, 2, 8] + 1.0  # moving to goal 0 beats standing, for goal 0
    assert R.loglik.shape == (1, len(goals), 3, len(goals))


def _standing_rollouts(terminal: str, speed: tuple[float, float]):
    """No-assist from Scene 1's start in rotation mode, 3 steps of 0.5 s, under ``planner.terminal``; with
    the distances of the start to every goal's ``k_c``."""
    goals = _snap().goals
    kp, kq = goals.desired_poses(SCENE.start, 0.05)
    p, q = SCENE.start.position, SCENE.start.quat_wxyz
    cfg = _cfg(terminal=terminal)
    R = Rollouts(cfg, p[None], q[None], np.full((1, len(goals)), 1.0 / len(goals)), kp, kq, [NO_ASSIST],
                 Mode.ROTATION, speed, steps=3, dt=0.5)
    return cfg, R, np.linalg.norm(kp - p, axis=1), quat_angle(kq, q)


@pytest.mark.parametrize("speed", [(0.0, 0.0), (0.0, 0.2)])
def test_a_rollout_that_has_not_arrived_is_worth_the_approach_still_to_go(speed):
    """``planner.terminal = "approach"``: standing still for ``s`` steps is worth ``s`` stays plus the
    return of finishing the approach from the start pose, at ``alpha`` x the move's top speed plus
    ``1 - alpha`` x the user's in each part; a user turning too makes what is still to go cheaper."""
    cfg, R, d_t, d_r = _standing_rollouts("approach", speed)
    a = cfg.blend.alpha
    end = approach_return(d_t, d_r, a * cfg.move.linear_max_mps + (1 - a) * speed[0],
                          a * cfg.move.angular_max_radps + (1 - a) * speed[1], cfg.reward)
    assert np.allclose(R.value[0, :, 0, 0], end)
    if speed == (0.0, 0.0):  # nothing moves: each step earns the stay
        assert np.allclose(R.value[0, :, 0, :], end[:, None] + np.arange(4)[None] * R.stay[0][:, None])
    else:
        robot_alone = approach_return(d_t, d_r, a * cfg.move.linear_max_mps, a * cfg.move.angular_max_radps,
                                      cfg.reward)
        assert np.all(end >= robot_alone - 1e-9) and np.any(end > robot_alone + 1.0)


def test_the_fixed_terminal_charges_the_last_pose_for_terminal_s():
    """``planner.terminal = "fixed"`` (default): the pose at the horizon is charged ``R_d`` for
    ``terminal_s`` more; standing still, that is the stay scaled from one rollout step to ``terminal_s``."""
    cfg, R, _, _ = _standing_rollouts("fixed", (0.0, 0.0))
    end = R.stay[0] / (0.5 / cfg.reward.step_s) * (cfg.planner.terminal_s / cfg.reward.step_s)
    assert np.all(end < 0.0)
    assert np.allclose(R.value[0, :, 0, :], end[:, None] + np.arange(4)[None] * R.stay[0][:, None])


def test_watch_search_values_every_root_action_and_picks_the_best():
    model = SharedAutonomyModel(_cfg())
    r = Solver(model).plan(_snap())
    assert r.complete and r.value == max(r.root_values.values())
    kinds = {a.kind for a in r.root_values}
    assert {ActionKind.MOVE, ActionKind.HO, ActionKind.NONE, ActionKind.QUESTION} <= kinds
    assert Solver(model).plan(_snap()).action == r.action  # deterministic


def test_watching_a_user_heading_to_a_goal_moves_the_branch_belief_toward_that_goal():
    """The predicted joystick input of a user heading to ``g`` is evidence for ``g``: in every branch of
    every watched motion the belief in the branch's goal grows from the uniform prior."""
    model = SharedAutonomyModel(_cfg())
    s = WatchSearch(model, _snap(speed=(0.05, 0.0)))
    pose = s.snap.pose
    R = s.rollouts(pose.position[None], pose.quat_wxyz[None], s.b0[None], s.n, s.n_w)
    for w in s.watched:
        B = s.child_beliefs(R, [w])
        assert np.allclose(B.sum(axis=1), 1.0)
        assert np.all(B[np.arange(len(s.branches)), s.branches] > s.b0[s.branches]), s.moves[w].label


def test_without_watch_levels_only_commits_and_questions_are_valued():
    model = SharedAutonomyModel(_cfg(watch_levels=0))
    values, watched, complete = WatchSearch(model, _snap()).run()
    assert complete and watched == {}
    assert any(a.kind is ActionKind.QUESTION for a in values)


def test_a_node_budget_stops_before_the_watched_motions():
    model = SharedAutonomyModel(_cfg())
    snap = _snap()
    snap = Snapshot(snap.goals, snap.probs, snap.pose, snap.user_twist, budget_s=None, node_budget=1,
                    user_speed=snap.user_speed)
    solver = Solver(model)
    r = solver.plan(snap)
    assert not r.complete and r.upper_bound >= r.value
    # the watched motions' rollouts, started beside the root's questions, were dropped: the rollout threads
    # are free and the next plan is the one a fresh solver makes
    full = Snapshot(snap.goals, snap.probs, snap.pose, snap.user_twist, budget_s=None, user_speed=snap.user_speed)
    again, fresh = solver.plan(full), Solver(SharedAutonomyModel(_cfg())).plan(full)
    assert again.complete and (again.action, again.value) == (fresh.action, fresh.value)


# -- the search against a plain recursion ---------------------------------------------------------------


def _outcomes(cfg, goals, question_target: str, b: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """The answers to a question about ``question_target`` at belief ``b``, computed one goal at a time:
    ``(P(answer | g) for every g, the tracker's belief after it)``. Yes and no by Bayes with the
    two-answer likelihood; with ``asking.third_answer`` also "that object, another grasp", where the
    asked target's probability goes to its object's other targets."""
    p = cfg.intent.answer_p_correct
    G = len(goals)
    tgt = [goals.goals[g].target for g in range(G)]
    obj = [goals.goals[g].object for g in range(G)]
    qobj = question_target.split(":", 1)[0]
    in_t = np.array([t == question_target for t in tgt])
    lb = np.where(in_t, p, 1 - p)
    yes_b, no_b = b * lb / (b @ lb), b * (1 - lb) / (b @ (1 - lb))
    if not cfg.asking.third_answer:
        return [(lb, yes_b), (1 - lb, no_b)]
    sib = np.array([o == qobj and not t for o, t in zip(obj, in_t)])
    if not sib.any():
        return [(lb, yes_b), (1 - lb, no_b)]
    correct = ["yes" if in_t[g] else ("other" if sib[g] else "no") for g in range(G)]
    P = {a: np.array([p if correct[g] == a else (1 - p) / 2 for g in range(G)]) for a in ("yes", "no", "other")}
    other_b = b.copy()
    m_asked = b[in_t].sum()
    sib_targets = sorted({tgt[g] for g in range(G) if sib[g]})
    m_sib = b[sib].sum()
    for g in range(G):
        if sib[g]:
            if m_sib > 0:
                other_b[g] = b[g] * (1 + m_asked / m_sib)
            else:
                other_b[g] = b[g] + m_asked / len(sib_targets) / sum(t == tgt[g] for t in tgt)
    other_b[in_t] = 0.0
    return [(P["yes"], yes_b), (P["no"], no_b), (P["other"], other_b)]


def _watched_belief(cfg, target_index, b0, ll, mode: Mode = Mode.TRANSLATION) -> np.ndarray:
    """A watched branch's belief, goal by goal: each target's mass by Bayes on ``watch_evidence`` (in
    rotation mode ``watch_evidence_rotation`` where set) x the log-likelihood, its copies split by
    ``watch_copy_evidence`` of that."""
    pc = cfg.planner
    lam, kappa = pc.watch_evidence, pc.watch_copy_evidence
    if mode is Mode.ROTATION and pc.watch_evidence_rotation is not None:
        lam = pc.watch_evidence_rotation
    full = b0 * np.exp(lam * (ll - ll.max()))
    part = b0 * np.exp(kappa * lam * (ll - ll.max()))
    out = np.zeros_like(b0)
    for g in range(len(b0)):
        same = target_index == target_index[g]
        out[g] = full[same].sum() / full.sum() * part[g] / part[same].sum()
    return out


def _reference_values(model: SharedAutonomyModel, snap: Snapshot) -> dict:
    """Every root action's value by a plain recursion over the tree of ``planner/watch.py``'s module doc:
    one node at a time, no batching, no deduplication, one rollout per start pose."""
    s = WatchSearch(model, snap)
    cfg, b0, pose = model.cfg, s.b0, snap.pose
    r_q, n_q = cfg.reward.question, s.n_q

    def roll(position, quat, weights, steps, watch_steps=0):  # the watch read as planner.watch_likelihood says
        return Rollouts(cfg, position[None], quat[None], weights[None], s.kp, s.kq, s.moves, snap.mode,
                        snap.user_speed, steps, s.dt, watch_steps, poses=s.poses)

    def decide(R, b, asked: frozenset, steps: int, depth: int, cont=None) -> np.ndarray:
        best_e, best_v = -np.inf, None
        for a in range(len(s.moves)):
            v = R.value[0, :, a, steps]
            if b @ v > best_e:
                best_e, best_v = float(b @ v), v
        if cont is not None and cont[1] > best_e:  # the watch continued (planner.watch_levels = 2)
            best_e, best_v = cont[1], cont[0]
        if depth < s.max_q and steps >= n_q:
            for q in range(len(s.questions)):
                if q in asked:
                    continue
                v = ask(R, b, asked, q, steps, depth)
                if v is not None and b @ v > best_e:
                    best_e, best_v = float(b @ v), v
        return best_v

    def ask(R, b, asked: frozenset, q: int, steps: int, depth: int) -> np.ndarray | None:
        """Question ``q``'s vector, or None where planner.question_gate = "information" closes it: its
        answers' worth over standing still as long and deciding without them is not above -r_q."""
        informed = sum(like * decide(R, after, asked | {q}, steps - n_q, depth + 1)
                       for like, after in _outcomes(cfg, snap.goals, s.questions[q].target, b))
        if cfg.planner.question_gate == "information" and (
                steps == n_q or b @ (informed - decide(R, b, asked, steps - n_q, depth + 1)) <= -r_q):
            return None
        return r_q + n_q * R.stay[0] + informed

    def continued(kid, bc, w):
        """The child's watch of ``w`` continued: a grandchild per branch ``h``, then ask or commit; weighed
        by ``bc`` over the branches, each branch credited its own return."""
        ret = {}
        for h in s.branches:
            bg = _watched_belief(cfg, snap.goals.target_index, bc, kid.loglik[0, h, w], snap.mode)
            grand = roll(kid.watch_positions[0, h, w], kid.watch_quats[0, h, w], bg, s.n - 2 * s.n_w)
            ret[h] = kid.watch_return[0, h, w] + decide(grand, bg, frozenset(), s.n - 2 * s.n_w, 0)[h]
        value = sum(bc[h] * r for h, r in ret.items()) / sum(bc[h] for h in ret)
        vec = np.full(len(b0), value)
        for h, r in ret.items():
            vec[h] = r
        return vec, value

    R = roll(pose.position, pose.quat_wxyz, b0, s.n, s.n_w)
    root = b0.copy()  # the root's average: every goal, or (root_goals = "top") the branches renormalised
    if cfg.planner.root_goals == "top":
        outside = np.ones(len(b0), dtype=bool)
        outside[s.branches] = False
        root[outside] = 0.0
        root /= root.sum()
    out = {a: float(root @ R.value[0, :, i, s.n]) for i, a in enumerate(s.moves)}
    for q, a in enumerate(s.questions):
        v = ask(R, b0, frozenset(), q, s.n, 0) if s.n >= n_q and s.max_q > 0 else None
        if v is not None:
            out[a] = float(root @ v)
    watched = {}
    branches = [int(g) for g in s.branches]
    # "mapped": every goal the belief holds, each outside the branches read through the child of the branch
    # its predicted input is likeliest for; otherwise ("top", "all") the branches' own goals
    over = [h for h in range(len(b0)) if b0[h] > 0] if cfg.planner.watch_branches == "mapped" else branches
    for w in s.watched:
        total = 0.0
        for h in over:
            g = h if h in branches else max(branches, key=lambda b: (R.loglik[0, h, w, b], -branches.index(b)))
            bc = _watched_belief(cfg, snap.goals.target_index, b0, R.loglik[0, g, w], snap.mode)
            kid = roll(R.watch_positions[0, g, w], R.watch_quats[0, g, w], bc, s.n - s.n_w, s.n_w * s.continues)
            cont = continued(kid, bc, w) if s.continues else None
            total += b0[h] * (R.watch_return[0, h, w] + decide(kid, bc, frozenset(), s.n - s.n_w, 0, cont)[h])
        watched[s.moves[w]] = total / sum(b0[h] for h in over)
    return out, watched


def _assert_the_reference_values(model, snap, values, watched, complete) -> None:
    """The search's ``run()`` (``values``, ``watched``, ``complete``) gives every root action the plain
    recursion's value."""
    ref_values, ref_watched = _reference_values(model, snap)
    assert complete
    assert values.keys() == ref_values.keys() and watched.keys() == ref_watched.keys()
    for a, v in ref_values.items():
        assert values[a] == pytest.approx(v, rel=1e-9, abs=1e-6), a.label
    for a, v in ref_watched.items():
        assert watched[a] == pytest.approx(v, rel=1e-9, abs=1e-6), a.label


@pytest.mark.parametrize("third", [False, True])
@pytest.mark.parametrize("seed", range(12))
def test_the_batched_search_equals_a_plain_recursion_on_random_problems(seed, third):
    """With fewer top goals than goals in half the problems (``top_goals = 2`` of Scene 1's four), so that
    ``planner.watch_branches`` has goals outside the branches to average over or map."""
    rng = np.random.default_rng(seed)
    cfg = _cfg(horizon_s=4.0, rollout_step_s=0.5, watch_s=1.0, max_questions=2,
               watch_moves=int(rng.integers(0, 3)), watch_likelihood=("kc", "marginal")[seed % 2],
               watch_evidence=(1.0, 0.5, 0.0)[seed % 3], top_goals=(10, 2)[seed // 6],
               watch_branches=("top", "mapped", "all")[seed % 3 if third else (seed + 1) % 3],
               root_goals=("all", "top")[(seed // 3) % 2], question_gate=("none", "information")[(seed // 2) % 2])
    reward = cfg.reward.model_copy(update={"question_time_s": float(rng.choice([0.5, 1.5]))})
    asking = cfg.asking.model_copy(update={"third_answer": third})
    cfg = cfg.model_copy(update={"reward": reward, "asking": asking})
    model = SharedAutonomyModel(cfg)
    goals = model.initial_belief(SCENE.goals).goals
    probs = rng.dirichlet(np.full(len(goals), 0.7)) + 1e-6
    pose = SCENE.start
    start = Pose(pose.position + rng.normal(0.0, 0.05, 3), pose.quat_wxyz)
    mode = Mode.TRANSLATION if seed % 3 else Mode.ROTATION
    snap = Snapshot(goals, probs, start, np.zeros(6), mode, budget_s=None,
                    user_speed=(float(rng.uniform(0, 0.1)), float(rng.uniform(0, 0.3))))
    values, watched, complete = WatchSearch(model, snap).run()
    _assert_the_reference_values(model, snap, values, watched, complete)


@pytest.mark.parametrize("seed", range(8))
def test_a_continued_watch_equals_the_plain_recursion_on_random_problems(seed):
    """``planner.watch_levels = 2``: each child may keep its motion for another watch, then ask or commit
    (``planner/continued_watch.py``); the batched search, its children one per motion and its grandchildren
    deduplicated, gives the plain recursion's values, with Scene 2's shared orientations in half the
    problems."""
    rng = np.random.default_rng(100 + seed)
    scene = load_scene(("scene1", "scene2")[seed % 2])
    cfg = _cfg(horizon_s=4.0, rollout_step_s=0.5, watch_s=1.0 if seed % 4 < 2 else 0.5, max_questions=1,
               watch_levels=2, watch_moves=int(rng.integers(0, 3)), top_goals=(10, 3)[(seed // 2) % 2],
               watch_branches=("top", "all")[(seed // 4) % 2], question_gate=("none", "information")[seed % 2])
    model = SharedAutonomyModel(cfg)
    goals = model.initial_belief(scene.goals).goals
    probs = rng.dirichlet(np.full(len(goals), 0.7)) + 1e-6
    start = Pose(scene.start.position + rng.normal(0.0, 0.05, 3), scene.start.quat_wxyz)
    mode = Mode.TRANSLATION if seed % 3 else Mode.ROTATION
    snap = Snapshot(goals, probs, start, np.zeros(6), mode, budget_s=None,
                    user_speed=(float(rng.uniform(0.01, 0.1)), float(rng.uniform(0.05, 0.3))))
    search = WatchSearch(model, snap)
    assert search.continues
    values, watched, complete = search.run()
    _assert_the_reference_values(model, snap, values, watched, complete)
    one = WatchSearch(SharedAutonomyModel(_cfg(**{**cfg.planner.model_dump(), "watch_levels": 1})), snap).run()
    assert one[0] == values  # commits and questions: the root is not changed by its children's option


def test_a_continued_watch_keeps_every_grandchild_s_questions_in_a_large_batch():
    """Every goal a branch on Scene 2 (``watch_branches = "all"``), three answers: more grandchildren than
    one question level of ``MAX_BATCH`` beliefs holds. They are decided in batches, so each may still ask,
    as the plain recursion lets it (found by review: one batch cut their questions, session 41)."""
    rng = np.random.default_rng(1005)
    cfg = _cfg(horizon_s=4.0, rollout_step_s=0.5, watch_levels=2, max_questions=1, question_gate="none",
               watch_s=1.5, watch_moves=2, top_goals=10, watch_branches="all", root_goals="top",
               watch_evidence=0.3, watch_evidence_rotation=0.8, watch_copy_evidence=0.5)
    reward = cfg.reward.model_copy(update={"question_time_s": float(rng.choice([0.5, 1.0]))})
    cfg = cfg.model_copy(update={"reward": reward, "asking": cfg.asking.model_copy(update={"third_answer": True})})
    model = SharedAutonomyModel(cfg)
    scene = load_scene("scene2")
    goals = model.initial_belief(scene.goals).goals
    probs = rng.dirichlet(np.full(len(goals), 0.7)) + 1e-6
    start = Pose(scene.start.position + rng.normal(0.0, 0.05, 3), scene.start.quat_wxyz)
    snap = Snapshot(goals, probs, start, np.zeros(6), Mode.TRANSLATION, budget_s=None,
                    user_speed=(float(rng.uniform(0.01, 0.1)), float(rng.uniform(0.05, 0.3))))
    search = WatchSearch(model, snap)
    values, watched, complete = search.run()
    assert search.grandchildren * search.answers * len(search.questions) > MAX_BATCH  # the case under test
    _assert_the_reference_values(model, snap, values, watched, complete)


def test_a_continued_watch_past_the_deadline_leaves_the_watches_out():
    """The continued watch is the search's largest stage: past the deadline it is not started, and the plan
    is the commits' and the questions' (incomplete), as when the children's stage is dropped."""
    model = SharedAutonomyModel(_cfg(watch_levels=2))
    search = WatchSearch(model, _snap(), deadline=time.perf_counter() - 1.0)
    search._out_of_budget = lambda: False  # the deadline passes between the children's stage and this one
    values, watched, complete = search.run()
    assert watched == {} and not complete and values
    assert search.children > 0 and search.grandchildren == 0
    on_time = WatchSearch(model, _snap())
    assert on_time.run()[1] and on_time.grandchildren > 0


@pytest.mark.parametrize("seed", range(3))
def test_branches_turning_alike_are_searched_once_with_the_values_of_the_plain_recursion(seed):
    """Turning, a user heading to a goal and one heading to a goal with its orientation (Scene 2's side
    grasps share one) drive the same turn and the tracker reads it alike: their children are the same
    and are searched once. The values stay those of the plain recursion, which searches every branch."""
    scene = load_scene("scene2")
    rng = np.random.default_rng(seed)
    cfg = _cfg(max_questions=1, watch_moves=1)
    model = SharedAutonomyModel(cfg)
    goals = model.initial_belief(scene.goals).goals
    probs = rng.dirichlet(np.full(len(goals), 0.7)) + 1e-3
    start = Pose(scene.start.position + rng.normal(0.0, 0.05, 3), scene.start.quat_wxyz)
    snap = Snapshot(goals, probs, start, np.zeros(6), Mode.ROTATION, budget_s=None,
                    user_speed=(0.02, float(rng.uniform(0.05, 0.3))))
    search = WatchSearch(model, snap)
    values, watched, complete = search.run()
    twins = len(search.branches) - len({tuple(search.kq[g]) for g in search.branches})
    assert twins > 0  # the case under test: branches whose goals share an orientation
    assert search.children == len(search.watched) * (len(search.branches) - twins)
    _assert_the_reference_values(model, snap, values, watched, complete)


def test_watching_no_assist_with_an_idle_user_is_standing_then_the_best_commitment():
    """With an idle user nothing moves while no-assist is watched, so the watch is worth standing for
    ``n_w`` steps and then the best commitment over what is left of the horizon, from the same pose. The
    terminal charge counts once, at the end of the horizon (not also at the end of the watch)."""
    model = SharedAutonomyModel(_cfg(watch_moves=0, max_questions=0))
    s = WatchSearch(model, _snap(speed=(0.0, 0.0)))
    values, watched, _ = s.run()
    pose = s.snap.pose
    R = s.rollouts(pose.position[None], pose.quat_wxyz[None], s.b0[None], s.n, s.n_w)
    stand_then = s.n_w * R.stay[0][:, None] + R.value[0, :, :, s.n - s.n_w]  # (G, A)
    best = max(float(s.b0 @ stand_then[:, a]) for a in range(len(s.moves)))
    assert watched[NO_ASSIST] == pytest.approx(best, rel=1e-3)
    assert watched[NO_ASSIST] > values[NO_ASSIST]  # standing all along is worse: an idle arm gains nothing


# -- HO in a rollout follows the tracked belief -----------------------------------------------------------


def _ho_rollout_by_hand(cfg, kp, kq, b0, position, quat, g, mode, speed, steps, dt):
    """One HO rollout for a user heading to goal ``g``, one step at a time: HO's belief starts at ``b0``
    and after every step takes the tracker's MaxEnt IOC update for that step's predicted input
    (``belief_hz x dt`` samples, rationality ``beta``, the rotation part's ``rotation_rationality``).
    Returns the pose after ``steps`` and the belief."""
    log_b = np.log(b0)
    p, q = np.array(position, dtype=float), np.array(quat, dtype=float)
    alpha, T = cfg.blend.alpha, cfg.intent.action_apply_time_s
    for _ in range(steps):
        u = predicted_input(cfg, p, q, kp, kq, g, mode, speed)
        b = np.exp(log_b - log_b.max())
        robot = np.concatenate((ho_linear(p + u[:3] * T, kp, b, cfg), ho_angular(turn(q, u[3:], T), kq, b, cfg)))
        log_b = log_b - cfg.runtime.belief_hz * dt * cfg.intent.rationality * q_minus_v_at(
            p, q, u, kp, kq, cfg.intent, cfg.intent.rotation_rationality / cfg.intent.rationality)
        twist = (1.0 - alpha) * u + alpha * robot
        p, q = p + twist[:3] * dt, turn(q, twist[3:], dt)
    b = np.exp(log_b - log_b.max())
    return p, q, b / b.sum()


@pytest.mark.parametrize("intent", [{}, {"rotation_rationality": 200.0},
                                    {"rotation_rationality": 200.0, "step_cost": "time"}],
                         ids=["defaults", "beta_r", "beta_r-time"])
@pytest.mark.parametrize("mode, speed", [(Mode.TRANSLATION, (0.05, 0.0)), (Mode.ROTATION, (0.0, 0.3))])
def test_ho_in_a_rollout_follows_the_belief_the_predicted_input_gives(mode, speed, intent):
    """``planner.ho_belief = "tracked"`` (default): the batched rollouts move HO exactly as a plain loop
    that updates HO's belief after every step, for every goal the user may head to; and that belief
    grows on the user's goal, so HO ends nearer it than HO under the plan's fixed belief does. Also with
    the rotation part of the evidence weighed apart (``intent.rotation_rationality``), in either step-cost form."""
    cfg = _cfg()
    cfg = cfg.model_copy(update={"intent": cfg.intent.model_copy(update=intent)})
    snap = _snap()
    goals, pose, steps, dt = snap.goals, snap.pose, 4, 0.5
    kp, kq = goals.desired_poses(pose, cfg.intent.rotation_weight_m_per_rad)
    actions = [HO_ACTION, NO_ASSIST]

    def ho_poses(c):
        R = Rollouts(c, pose.position[None], pose.quat_wxyz[None], snap.probs[None], kp, kq, actions, mode, speed,
                     steps=steps, dt=dt, watch_steps=steps)
        n = len(goals)
        return (np.broadcast_to(R.watch_positions[0, :, 0], (n, 3)), np.broadcast_to(R.watch_quats[0, :, 0], (n, 4)))

    P, Q = ho_poses(cfg)
    fixed = cfg.model_copy(update={"planner": cfg.planner.model_copy(update={"ho_belief": "fixed"})})
    P_fixed, Q_fixed = ho_poses(fixed)
    for g in range(len(goals)):
        p, q, b = _ho_rollout_by_hand(cfg, kp, kq, snap.probs, pose.position, pose.quat_wxyz, g, mode, speed,
                                      steps, dt)
        assert np.allclose(P[g], p, atol=1e-12) and np.allclose(Q[g], q, atol=1e-12), g
        assert b[g] > snap.probs[g]
        if mode is Mode.TRANSLATION:
            assert np.linalg.norm(P[g] - kp[g]) < np.linalg.norm(P_fixed[g] - kp[g]), g
        else:
            assert quat_angle(Q[g], kq[g]) < quat_angle(Q_fixed[g], kq[g]), g


def test_with_an_idle_user_tracked_and_fixed_ho_are_the_same_rollouts():
    """No input, no evidence (path step cost): HO's tracked belief stays the plan's."""
    cfg = _cfg()
    fixed = cfg.model_copy(update={"planner": cfg.planner.model_copy(update={"ho_belief": "fixed"})})
    snap = _snap(speed=(0.0, 0.0))
    kp, kq = snap.goals.desired_poses(snap.pose, cfg.intent.rotation_weight_m_per_rad)
    values = [Rollouts(c, snap.pose.position[None], snap.pose.quat_wxyz[None], snap.probs[None], kp, kq,
                       [HO_ACTION, NO_ASSIST], Mode.TRANSLATION, (0.0, 0.0), steps=5, dt=1.0).value
              for c in (cfg, fixed)]
    assert np.allclose(values[0], values[1], rtol=0, atol=1e-9)


def test_distinct_rows_are_numpys_unique_rows_in_order_of_appearance():
    """The children are deduplicated by their (pose, belief) rows; ``-0.0`` and ``0.0`` are one number."""
    rng = np.random.default_rng(2)
    rows = rng.integers(0, 3, (60, 4)).astype(float)
    rows[5] = -0.0 * rows[5]  # the same as row 5 was, with negative zeros where it had zeros
    rows[7] = rows[5] * 0.0
    first, kid = distinct_rows(rows)
    values, inverse = np.unique(rows, axis=0, return_inverse=True)
    assert len(first) == len(values)
    assert np.array_equal(rows[first][kid], rows)  # every row is its child's row
    assert list(first) == sorted(first) and kid[first].tolist() == list(range(len(first)))
    assert np.array_equal(np.unique(inverse.ravel()[first]), np.arange(len(values)))
