"""Which ``k_c`` the copies resampling makes of one target are driven to and scored at (``intent.copy_reach``).

``own`` (the default) gives each copy the closest of its own poses (under the tracked reach, the default
since session 43, its tracked pose; the tests at the end), so the copies of one target are goals
the planner can tell apart; ``target`` gives every copy the closest pose over all its target's poses (the
``k_c`` the target had before resampling split it); ``likeliest`` gives every copy the ``k_c`` of the
target's most probable copy. Measured and left off (docs/model.md, Copies that share one k_c).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from sa_daemon.config import ConfigError, IntentConfig, config_from_dict
from sa_daemon.control.controller import Controller
from sa_daemon.geometry import Pose
from sa_daemon.model.actions import Action, ActionKind
from sa_daemon.model.belief import Belief
from sa_daemon.model.huber import tracked_goal_poses
from sa_daemon.model.model import SharedAutonomyModel
from sa_daemon.planner.snapshot import Snapshot
from sa_daemon.planner.solver import Solver
from sa_daemon.planner.watch import WatchSearch
from sa_daemon.world.goals import Goal, GraspType
from sa_daemon.world.goalset import GoalSet

TOP = (math.pi, 0.0, 0.0)
GRIPPER = Pose.from_rpy([0.30, 0.0, 0.20], TOP)
W = IntentConfig().rotation_weight_m_per_rad
# Target "a" has four grasp poses 5, 2, 8 and 11 cm ahead of the gripper: its k_c is the second.
A_DX = (0.05, 0.02, 0.08, 0.11)


def top_goal(obj: str, *positions) -> Goal:
    return Goal(obj, GraspType.TOP, tuple(Pose.from_rpy(p, TOP) for p in positions))


def scene() -> GoalSet:
    x, y, z = GRIPPER.position
    return GoalSet((
        top_goal("a", *([x + dx, y, z] for dx in A_DX)),
        top_goal("b", [x, y + 0.1, z]),
        top_goal("c", [x, y - 0.1, z]),
        top_goal("d", [x, y, z + 0.1]),
    ))


def split() -> Belief:
    """``a:top`` at 0.8, resampled into copies that own disjoint subsets of its poses, at equal shares (so
    a few per cent more makes any copy the likeliest)."""
    cfg = IntentConfig(step_cost="time", rationality=1.0, copy_weights="equal")
    b = Belief.from_probs(scene(), np.array([0.8, 0.1, 0.05, 0.05])).resampled(GRIPPER, cfg)
    assert [g.target for g in b.goals.goals].count("a:top") >= 2, "the fixture must split a:top"
    return b


def model(copy_reach: str) -> SharedAutonomyModel:
    # copy_reach chooses among k_c's: the paper's reach (the default until session 43)
    return SharedAutonomyModel(config_from_dict({"intent": {"copy_reach": copy_reach, "reach_pose": "closest"}}))


def copies(goals: GoalSet) -> np.ndarray:
    return np.flatnonzero(goals.target_mask("a:top"))


def test_own_is_each_copys_closest_pose_as_before():
    b = split()
    kp, kq = model("own").desired_poses(b.goals, GRIPPER, b.probs)
    want = b.goals.desired_poses(GRIPPER, W)
    np.testing.assert_array_equal(kp, want[0])
    np.testing.assert_array_equal(kq, want[1])
    assert len({tuple(kp[i]) for i in copies(b.goals)}) == len(copies(b.goals))  # the copies differ


def test_target_gives_every_copy_the_targets_k_c_before_the_split():
    b = split()
    kp, _ = model("target").desired_poses(b.goals, GRIPPER, b.probs)
    before = scene().desired_poses(GRIPPER, W)[0][0]  # a:top's k_c while it was one goal: 2 cm ahead
    for i in copies(b.goals):
        np.testing.assert_allclose(kp[i], before, atol=1e-12)
    own = b.goals.desired_poses(GRIPPER, W)[0]
    others = ~b.goals.target_mask("a:top")
    np.testing.assert_array_equal(kp[others], own[others])  # single-copy targets keep their own


def test_likeliest_lends_the_most_probable_copys_k_c_and_follows_the_belief():
    b = split()
    own = b.goals.desired_poses(GRIPPER, W)[0]
    idx = copies(b.goals)
    for lender in (idx[-1], idx[0]):
        probs = b.probs.copy()
        probs[lender] += 0.05  # this copy is now the most probable of its target
        probs /= probs.sum()
        kp, _ = model("likeliest").desired_poses(b.goals, GRIPPER, probs)
        for i in idx:
            np.testing.assert_array_equal(kp[i], own[lender])


@pytest.mark.parametrize("copy_reach", ["target", "likeliest"])
def test_the_planner_cannot_tell_shared_copies_apart(copy_reach):
    """Moves to copies that share one pose are worth the same at the root, and the watch search scores
    every copy at that pose; with ``own`` the copies' moves are worth different amounts."""
    b = split()
    snap = Snapshot(b.goals, b.probs, GRIPPER, np.zeros(6), budget_s=None, node_budget=400)
    shared = model(copy_reach)
    search = WatchSearch(shared, snap)
    np.testing.assert_array_equal(search.kp, shared.desired_poses(b.goals, GRIPPER, b.probs)[0])

    def copy_values(m: SharedAutonomyModel) -> list[float]:
        values = Solver(m).plan(snap).root_values
        return [v for a, v in values.items() if a.kind is ActionKind.MOVE and a.target == "a:top"]

    same = copy_values(shared)
    assert len(same) >= 2 and max(same) - min(same) < 1e-9
    apart = copy_values(model("own"))
    assert max(apart) - min(apart) > 1.0


def test_the_move_drives_every_copy_to_the_shared_pose():
    b = split()
    m = model("target")
    twists = [m.robot_twist(Action(ActionKind.MOVE, int(i), "a:top"), b.goals, b.probs, GRIPPER, np.zeros(6))
              for i in copies(b.goals)]
    for t in twists[1:]:
        np.testing.assert_array_equal(t, twists[0])
    assert twists[0][0] > 0 and abs(twists[0][1]) < 1e-12  # straight ahead, toward the pose 2 cm ahead


def test_an_unknown_copy_reach_is_refused_by_name():
    with pytest.raises(ConfigError, match=r"intent\.copy_reach"):
        config_from_dict({"intent": {"copy_reach": "nearest"}})


# -- under the tracked reach (intent.reach_pose = "tracked_moves", the default since session 43) ----------

def tracked_model(copy_reach: str) -> SharedAutonomyModel:
    return SharedAutonomyModel(config_from_dict({"intent": {"copy_reach": copy_reach}}))


def pointed(copy_probs: tuple[float, float, float]) -> Belief:
    """:func:`split`'s copies of ``a:top`` (owning the poses 2 cm / 5 cm / 8 and 11 cm ahead) at
    ``copy_probs``, the input having pointed the third copy at its 11 cm pose, not its 8 cm one."""
    b = split()
    probs = np.array([*copy_probs, 0.1, 0.05, 0.05])
    log_w = np.array(b.pose_log_w)
    log_w[2] = [-20.0, 0.0]
    return Belief(b.goals, np.log(probs / probs.sum()), pose_log_w=log_w)


def reach_dx(m: SharedAutonomyModel, b: Belief) -> list[float]:
    """Where the moves drive each copy of ``a:top``: cm ahead of the gripper."""
    kp, _ = m.reach_poses(b.goals, GRIPPER, b.pose_log_w, b.probs)
    return [round(100 * (kp[i][0] - GRIPPER.position[0]), 6) for i in copies(b.goals)]


def test_tracked_own_drives_each_copy_to_the_pose_its_input_points_at():
    b = pointed((0.25, 0.25, 0.3))
    assert reach_dx(tracked_model("own"), b) == [2.0, 5.0, 11.0]
    kp, kq = tracked_model("own").reach_poses(b.goals, GRIPPER, b.pose_log_w, b.probs)
    want = tracked_goal_poses(GRIPPER.position, GRIPPER.quat_wxyz, b.goals.positions, b.goals.quats_wxyz,
                              b.pose_log_w, IntentConfig())
    np.testing.assert_array_equal(kp, want[0])
    np.testing.assert_array_equal(kq, want[1])


def test_tracked_target_drives_every_copy_to_the_likeliest_copy_and_pose():
    """``target``: all copies take the pose of highest ``P(g) P(k | g, input) w_k``; as the input moves
    probability between the copies, all of them follow, while single-copy targets keep their own."""
    m = tracked_model("target")
    assert reach_dx(m, pointed((0.05, 0.05, 0.7))) == [11.0, 11.0, 11.0]  # the pointed pose, not the 8 cm one
    assert reach_dx(m, pointed((0.7, 0.05, 0.05))) == [2.0, 2.0, 2.0]
    b = pointed((0.05, 0.7, 0.05))
    assert reach_dx(m, b) == [5.0, 5.0, 5.0]
    kp, _ = m.reach_poses(b.goals, GRIPPER, b.pose_log_w, b.probs)
    own, _ = tracked_model("own").reach_poses(b.goals, GRIPPER, b.pose_log_w, b.probs)
    others = ~b.goals.target_mask("a:top")
    np.testing.assert_array_equal(kp[others], own[others])


def test_tracked_likeliest_lends_the_most_probable_copys_tracked_pose():
    m = tracked_model("likeliest")
    assert reach_dx(m, pointed((0.2, 0.2, 0.3))) == [11.0, 11.0, 11.0]
    assert reach_dx(m, pointed((0.2, 0.3, 0.2))) == [5.0, 5.0, 5.0]


def test_tracked_target_moves_and_rollouts_share_the_pose():
    """The watch search scores every copy at the shared pose, and the copies' moves are one twist."""
    b = pointed((0.1, 0.1, 0.5))
    m = tracked_model("target")
    snap = Snapshot(b.goals, b.probs, GRIPPER, np.zeros(6), budget_s=None, node_budget=400, pose_log_w=b.pose_log_w)
    search = WatchSearch(m, snap)
    np.testing.assert_array_equal(search.kp, m.reach_poses(b.goals, GRIPPER, b.pose_log_w, b.probs)[0])
    reach = m.reach_poses(b.goals, GRIPPER, b.pose_log_w, b.probs)
    twists = [m.robot_twist(Action(ActionKind.MOVE, int(i), "a:top"), b.goals, b.probs, GRIPPER, np.zeros(6), reach)
              for i in copies(b.goals)]
    for t in twists[1:]:
        np.testing.assert_array_equal(t, twists[0])
    assert twists[0][0] > 0  # ahead, toward the 11 cm pose


# -- pooled: the target's posterior over its poses, kept across its copies ---------------------------------

A_DY = (-0.05, -0.02, 0.02, 0.05)  # m: the fan's four poses of a:top, 10 cm ahead, across the path


def fan() -> GoalSet:
    """:func:`scene` with ``a:top``'s four poses fanned across the path, 10 cm ahead."""
    x, y, z = GRIPPER.position
    return GoalSet((top_goal("a", *([x + 0.1, y + dy, z] for dy in A_DY)), *scene().goals[1:]))


POOLED = config_from_dict({"intent": {"copy_reach": "pooled"}}).intent
OWN = config_from_dict({"intent": {"copy_reach": "own"}}).intent
# m/s: toward the fan's +5 cm pose, wavering; rad/s: none (translation mode)
INPUTS = [np.array([0.1, 0.05 + 0.01 * math.sin(i), 0.0, 0.0, 0.0, 0.0]) for i in range(30)]


def driven_with_resampling(cfg: IntentConfig, resample: bool = True) -> list[Belief]:
    """The belief along :data:`INPUTS` from ``a:top`` at 0.8, resampled after every sample (``resample``)."""
    b = Belief.from_probs(fan(), np.array([0.8, 0.1, 0.05, 0.05]))
    out = []
    for u in INPUTS:
        b = b.after_input(GRIPPER, u, cfg)
        if resample:
            b = b.resampled(GRIPPER, cfg)
        out.append(b)
    return out


def aside_cm(p: Pose) -> float:
    return round(100 * (p.position[1] - GRIPPER.position[1]), 6)


def joint_by_pose(b: Belief) -> dict[float, float]:
    """``a:top``'s pooled log posterior by pose (cm aside of the gripper)."""
    out = {}
    for i in copies(b.goals):
        for k, p in enumerate(b.goals.goals[i].poses):
            out[aside_cm(p)] = float(b.pose_joint_log_w[i, k])
    return out


def reach_aside(m: SharedAutonomyModel, b: Belief) -> list[float]:
    """Where the moves drive each copy of ``a:top``: cm aside of the gripper."""
    kp, kq = m.reach_poses(b.goals, GRIPPER, m.reach_log_w(b), b.probs)
    return [aside_cm(Pose(kp[i], kq[i])) for i in copies(b.goals)]


def test_pooled_keeps_the_unsplit_targets_posterior_over_its_poses():
    """Across resamplings that split ``a:top`` into copies, the pooled posterior over its four poses equals
    the posterior the unsplit target (no resampling) keeps over them: the same Bayes, never split."""
    split_run = driven_with_resampling(POOLED)
    whole_run = driven_with_resampling(POOLED, resample=False)
    assert any(len(copies(b.goals)) > 1 for b in split_run), "the run must split a:top"
    assert all(len(copies(b.goals)) == 1 for b in whole_run)
    for split_b, whole_b in zip(split_run, whole_run):
        whole = dict(zip((aside_cm(p) for p in whole_b.goals.goals[0].poses), whole_b.pose_log_w[0]))
        got = joint_by_pose(split_b)
        assert got.keys() == whole.keys()
        for dx, lw in whole.items():
            assert got[dx] == pytest.approx(lw, abs=1e-9)


def test_pooled_changes_the_reach_only():
    """The belief's probabilities and each copy's own pose posterior are those of ``own``."""
    for a, b in zip(driven_with_resampling(POOLED), driven_with_resampling(OWN)):
        np.testing.assert_array_equal(a.log_p, b.log_p)
        np.testing.assert_array_equal(a.pose_log_w, b.pose_log_w)
        assert b.pose_joint_log_w is None


def test_pooled_drives_every_copy_to_the_pose_the_input_points_at():
    b = driven_with_resampling(POOLED)[-1]
    assert len(copies(b.goals)) > 1
    joint = joint_by_pose(b)
    assert max(joint, key=joint.get) == 5.0  # the input headed to the +5 cm pose
    assert reach_aside(SharedAutonomyModel(config_from_dict({"intent": {"copy_reach": "pooled"}})), b) == \
        [5.0] * len(copies(b.goals))
    own = reach_aside(SharedAutonomyModel(config_from_dict({"intent": {"copy_reach": "own"}})), b)
    assert len(set(own)) == len(own)  # each copy its own pose


def test_the_pooled_reach_with_no_input_is_the_targets_pose_of_least_value():
    """No input yet: the pooled reach is the pose of least ``V`` over all the target's poses, for every copy
    (the 2 cm one ahead in :func:`split`, where each copy's own is another)."""
    b = split()
    assert b.pose_joint_log_w is None
    m = SharedAutonomyModel(config_from_dict({"intent": {"copy_reach": "pooled"}}))
    assert reach_dx(m, b) == [2.0, 2.0, 2.0]


# -- ranked: each copy its own pose, the planner weighing the copies by the pooled posterior --------------

RANKED = config_from_dict({"intent": {"copy_reach": "ranked"}})


def test_ranked_deals_each_target_to_its_copies_by_what_the_input_says_of_the_pose():
    """After input toward the fan's +5 cm pose the belief (pose-weighted copies) favours another copy of
    ``a:top``; the planner's probabilities make the copy that owns +5 cm the likeliest, and keep every
    target's total."""
    b = driven_with_resampling(RANKED.intent)[-1]
    idx = copies(b.goals)
    assert len(idx) > 1
    owner = next(i for i in idx if 5.0 in [aside_cm(p) for p in b.goals.goals[i].poses])
    assert idx[np.argmax(b.probs[idx])] != owner  # the belief's likeliest copy is another one
    planned = SharedAutonomyModel(RANKED).planning_probs(b, GRIPPER)
    assert idx[np.argmax(planned[idx])] == owner
    assert planned[owner] / planned[idx].sum() > 1.15 * b.probs[owner] / b.probs[idx].sum()
    np.testing.assert_allclose(b.goals.target_sums(planned), b.goals.target_sums(b.probs), atol=1e-12)
    # each copy is still driven to its own tracked pose
    m = SharedAutonomyModel(RANKED)
    assert m.reach_log_w(b) is b.pose_log_w
    assert len(set(reach_aside(m, b))) == len(idx)


def test_other_copy_reaches_plan_with_the_beliefs_probabilities():
    for reach in ("own", "pooled"):
        cfg = config_from_dict({"intent": {"copy_reach": reach}})
        b = driven_with_resampling(cfg.intent)[-1]
        assert SharedAutonomyModel(cfg).planning_probs(b, GRIPPER) is b.probs


def test_the_controller_plans_with_the_ranked_probabilities():
    """The controller's own input (toward the fan's +5 cm pose) splits ``a:top``; its snapshot then carries
    the ranked probabilities, not the belief's."""
    ctl = Controller(RANKED, fan(), "policy", 0.01)
    for i in range(60):
        t = 0.01 * i
        assert ctl.on_input(np.array([1.0, 0.5, 0.0]), t)  # +x, +y: toward the +5 cm pose, 10 cm ahead
        ctl.update_belief(GRIPPER, t)
    b = ctl.belief
    assert len(copies(b.goals)) > 1 and b.pose_joint_log_w is not None
    snap = ctl.snapshot(GRIPPER, budget_s=None, node_budget=50)
    np.testing.assert_allclose(snap.probs, SharedAutonomyModel(RANKED).planning_probs(b, GRIPPER), atol=1e-12)
    assert not np.allclose(snap.probs, b.probs)
