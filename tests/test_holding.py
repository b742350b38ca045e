"""The geometric success rule (``world/holding.py``): would a gripper closed at a pose hold the object?

Checked on every generated grasp of the built-in scenes (they hold; 3 cm back along the approach they
do not; within the paper's closing tolerance almost all still hold), on hand-made objects for each rule,
and through ``sim/success.py``'s ``grasp_outcome``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from sa_daemon.arm.kinematic import KinematicArm
from sa_daemon.geometry import Pose
from sa_daemon.sim.success import TIMEOUT, grasp_outcome, scene_object
from sa_daemon.world.goals import GraspType
from sa_daemon.world.grasps import (
    GRIPPER_MAX_OPENING_M,
    RIM_DEPTH_M,
    RIM_INSET_M,
    grasp_pose,
)
from sa_daemon.world.holding import (
    HOLD_FAILURES,
    HOLD_MARGIN_M,
    OUTSIDE,
    RIM_MISSED,
    SLIPS,
    TOO_WIDE,
    WRONG_TYPE,
    holds,
)
from sa_daemon.world.scene import SceneObject, builtin_scene_names, load_scene

SCENES = builtin_scene_names()
CLOSE_TRANSLATION_M = 0.01  # the paper's closing tolerance (sim_user.close_translation_m) ...
CLOSE_ROTATION_RAD = math.pi / 48  # ... and sim_user.close_rotation_rad
SAMPLES_PER_GRASP = 20
DOWN = np.array([0.0, 0.0, -1.0])


def _grasps(scene_name: str):
    """(object, grasp type, target, index, pose) for every generated grasp pose of the scene."""
    scene = load_scene(scene_name)
    for goal in scene.goals:
        obj = scene_object(scene, goal.object)
        for i, pose in enumerate(goal.poses):
            yield obj, goal.grasp_type, goal.target, i, pose


def _back(pose: Pose, d: float) -> Pose:
    """``pose`` moved ``d`` m back along its approach axis (tool z points into the object)."""
    return Pose(pose.position - d * pose.rotation[:, 2], pose.quat_wxyz)


def _axis_angle(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rotation matrix of ``angle`` rad about unit ``axis`` (Rodrigues)."""
    k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    return np.eye(3) + math.sin(angle) * k + (1.0 - math.cos(angle)) * (k @ k)


def _unit(rng: np.random.Generator) -> np.ndarray:
    v = rng.normal(size=3)
    return v / np.linalg.norm(v)


def _within_tolerance(pose: Pose, rng: np.random.Generator) -> Pose:
    """A pose within the closing tolerance of ``pose``: a translation in a uniform random direction of a
    length uniform in [0, 1 cm], and a rotation about a uniform random axis (through the TCP) by an angle
    uniform in [0, pi/48]."""
    shift = CLOSE_TRANSLATION_M * rng.uniform() * _unit(rng)
    turn = _axis_angle(_unit(rng), CLOSE_ROTATION_RAD * rng.uniform())
    return Pose.from_matrix(pose.position + shift, turn @ pose.rotation)


def _hold_fraction(scene_name: str, seed: int = 0) -> float:
    rng = np.random.default_rng(seed)
    verdicts = [
        holds(obj, _within_tolerance(pose, rng), gt).held
        for obj, gt, _, _, pose in _grasps(scene_name)
        for _ in range(SAMPLES_PER_GRASP)
    ]
    return sum(verdicts) / len(verdicts)


# -- the generated grasps of the built-in scenes --------------------------------------------------------


@pytest.mark.parametrize("scene_name", SCENES)
def test_every_generated_grasp_holds_its_object_with_its_goals_type(scene_name):
    failed = [
        (target, i, v.reason)
        for obj, gt, target, i, pose in _grasps(scene_name)
        if not (v := holds(obj, pose, gt)).held
    ]
    assert failed == []


@pytest.mark.parametrize("scene_name", SCENES)
def test_no_generated_grasp_holds_three_cm_back_along_its_approach(scene_name):
    held = [
        (target, i)
        for obj, gt, target, i, pose in _grasps(scene_name)
        if holds(obj, _back(pose, 0.03), gt).held
    ]
    assert held == []


@pytest.mark.parametrize("scene_names", [("scene1", "study-simple"), ("scene2",)], ids=["scene1+study", "scene2"])
def test_poses_within_the_closing_tolerance_almost_always_hold(scene_names):
    # Measured (seed 0, 20 poses per grasp): scene1 1.000, study-simple 1.000, scene2 0.995.
    for name in scene_names:
        assert _hold_fraction(name) >= 0.99, name


def test_within_tolerance_sampling_is_seeded():
    rng_a, rng_b = np.random.default_rng(4), np.random.default_rng(4)
    pose = Pose.from_rpy([0.4, 0.0, 0.3], (math.pi, 0.0, 0.0))
    a, b = _within_tolerance(pose, rng_a), _within_tolerance(pose, rng_b)
    np.testing.assert_array_equal(a.position, b.position)
    d_t, d_r = a.distance(pose)
    assert d_t <= CLOSE_TRANSLATION_M and d_r <= CLOSE_ROTATION_RAD + 1e-12


def test_one_cm_back_along_the_approach_only_pitched_vertical_side_grasps_fail():
    """The paper's closing tolerance (1 cm) back along the approach: every grasp still holds except the
    side_vertical grasps pitched 25 deg down to keep the wrist off the table, whose lower pad then misses
    the bottom face and meets the side face outside the friction cone (``docs/simulated-user.md``)."""
    failed = [
        (target, v.reason)
        for name in SCENES
        for obj, gt, target, i, pose in _grasps(name)
        if not (v := holds(obj, _back(pose, CLOSE_TRANSLATION_M), gt)).held
    ]
    assert failed, "the pitched grasps are expected to fail: the rule would be weaker than documented"
    assert all(t.endswith(":side_vertical") and "friction cone" in r for t, r in failed)


# -- hand-made objects, one rule at a time --------------------------------------------------------------


def _obj(shape: str, size, position, grasp_type: GraspType, rim: bool = False, yaw: float = 0.0) -> SceneObject:
    return SceneObject("thing", shape, tuple(size), tuple(position), yaw, (grasp_type,), rim)


BOX = _obj("box", (0.05, 0.15, 0.05), (0.45, 0.0, 0.025), GraspType.TOP)  # long along base y


def test_a_box_closed_along_its_long_axis_is_wider_than_the_open_fingers():
    assert BOX.size[1] > GRIPPER_MAX_OPENING_M
    tcp = [0.45, 0.0, 0.03]  # 2 cm below the top face, at the centre
    along = holds(BOX, grasp_pose(tcp, DOWN, [0.0, 1.0, 0.0]), GraspType.TOP)
    assert along.held is False
    assert "wider than the open fingers" in along.reason and along.kind == TOO_WIDE
    across = holds(BOX, grasp_pose(tcp, DOWN, [1.0, 0.0, 0.0]), GraspType.TOP)
    assert across.held is True and across.reason == "" and across.kind == ""


def test_a_top_grasp_pose_classified_as_side_fails_on_its_grasp_type():
    side = grasp_pose([0.44, 0.0, 0.025], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])  # approach horizontal
    verdict = holds(BOX, side, GraspType.TOP)
    assert verdict.held is False
    assert verdict.reason.startswith("grasp type") and verdict.kind == WRONG_TYPE
    assert "side" in verdict.reason and "top" in verdict.reason


CAN_R = 0.03
CAN = _obj("cylinder", (CAN_R, 0.12), (0.5, 0.0, 0.06), GraspType.SIDE)


@pytest.mark.parametrize("off, held", [(0.0, True), (0.3, True), (0.6, True), (0.65, False), (0.8, False)])
def test_a_cylinder_side_grasp_closing_off_its_axis_slips_beyond_the_friction_cone(off, held):
    """Approach along +x, closing along y: the closing line passes ``off * r`` from the axis. The rule's
    bound is sin(atan(0.8)) r = 0.62 r."""
    pose = grasp_pose([0.5 - off * CAN_R, 0.0, 0.06], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    verdict = holds(CAN, pose, GraspType.SIDE)
    assert verdict.held is held
    if not held:
        assert "friction cone" in verdict.reason and verdict.kind == SLIPS


CUP = _obj("cylinder", (0.04, 0.10), (0.45, 0.0, 0.05), GraspType.TOP, rim=True)
RIM_Z = 0.10


@pytest.mark.parametrize("angle", [0.0, 1.0, 2.5])
def test_a_rim_grasp_holds_below_the_rim_inside_the_wall_and_not_above_it(angle):
    u = np.array([math.cos(angle), math.sin(angle), 0.0])
    wall = np.array([0.45, 0.0, 0.0]) + (CUP.size[0] - RIM_INSET_M) * u
    below = grasp_pose([wall[0], wall[1], RIM_Z - RIM_DEPTH_M], DOWN, u)  # 1.5 cm below the rim
    assert holds(CUP, below, GraspType.TOP).held is True
    above = grasp_pose([wall[0], wall[1], RIM_Z + 0.01], DOWN, u)  # 1 cm above the rim
    verdict = holds(CUP, above, GraspType.TOP)
    assert verdict.held is False
    assert "rim" in verdict.reason and verdict.kind == RIM_MISSED


def test_a_rim_grasp_closing_along_the_wall_slips():
    u = np.array([1.0, 0.0, 0.0])
    wall = np.array([0.45, 0.0, 0.0]) + (CUP.size[0] - RIM_INSET_M) * u
    tangential = grasp_pose([wall[0], wall[1], RIM_Z - RIM_DEPTH_M], DOWN, [0.0, 1.0, 0.0])
    verdict = holds(CUP, tangential, GraspType.TOP)
    assert verdict.held is False and "friction cone" in verdict.reason and verdict.kind == SLIPS


def test_a_tcp_just_above_the_top_face_holds_within_the_pad_margin():
    small = _obj("box", (0.05, 0.05, 0.05), (0.45, 0.0, 0.025), GraspType.TOP)
    above = grasp_pose([0.45, 0.0, 0.05 + 0.6 * HOLD_MARGIN_M], DOWN, [0.0, 1.0, 0.0])  # 3 mm above
    assert holds(small, above, GraspType.TOP).held is True


def test_a_tcp_beyond_the_pad_margin_above_a_box_does_not_hold():
    small = _obj("box", (0.05, 0.05, 0.05), (0.45, 0.0, 0.025), GraspType.TOP)
    above = grasp_pose([0.45, 0.0, 0.05 + 2.0 * HOLD_MARGIN_M], DOWN, [0.0, 1.0, 0.0])
    verdict = holds(small, above, GraspType.TOP)
    assert verdict.held is False and "outside the object" in verdict.reason and verdict.kind == OUTSIDE


# -- grasp_outcome ---------------------------------------------------------------------------------------


def test_grasp_outcome_without_a_close_is_a_timeout():
    scene = load_scene("scene1")
    outcome = grasp_outcome(scene, "cup:top", None)
    assert outcome.success is False and outcome.reason == "timeout" and outcome.kind == TIMEOUT


@pytest.mark.parametrize("task", ["cup:top", "cup:side", "chips can:side", "bowl:top"])
def test_grasp_outcome_of_a_held_pose_succeeds_on_a_kinematic_arm(task):
    scene = load_scene("scene1")
    pose = scene.goal(task).poses[0]
    arm = KinematicArm(scene.start)
    assert not callable(getattr(arm, "lift_test", None))
    for a in (arm, None):
        outcome = grasp_outcome(scene, task, pose, a)
        assert outcome.success is True and outcome.reason == "" and outcome.rule_held is None  # the rule decided
    missed = grasp_outcome(scene, task, _back(pose, 0.03), arm)
    assert missed.success is False and missed.reason not in ("", "timeout") and missed.kind in HOLD_FAILURES
    assert missed.rule_held is None


def test_grasp_outcome_refuses_a_held_pose_of_another_grasp_type():
    scene = load_scene("scene1")
    side_pose = scene.goal("cup:side").poses[0]
    outcome = grasp_outcome(scene, "cup:top", side_pose, KinematicArm(scene.start))
    assert outcome.success is False and outcome.reason.startswith("grasp type") and outcome.kind == WRONG_TYPE
