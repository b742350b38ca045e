"""Reachable goals for arms with joints (``arm/reach.py``): IK against the xArm-6's bounds."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sa_daemon import cli
from sa_daemon.arm.kinematics import ArmKinematics, start_configuration
from sa_daemon.arm.reach import reachable_scene, reaches
from sa_daemon.cli import verbs
from sa_daemon.geometry import Pose
from sa_daemon.world.goals import Goal, GraspType
from sa_daemon.world.scene import load_scene

MARGIN = 0.1


@pytest.fixture(scope="module")
def kin() -> ArmKinematics:
    return ArmKinematics()


@pytest.fixture(scope="module")
def scene2_filtered(kin):
    scene = load_scene("scene2")
    return scene, reachable_scene(scene, kin, MARGIN)


def test_kept_poses_have_an_in_bounds_ik_solution_and_some_side_grasps_go(kin, scene2_filtered):
    scene, kept = scene2_filtered
    assert [g.target for g in kept.goals] == scene.targets  # every goal stays, in order
    dropped = sum(len(a.poses) - len(b.poses) for a, b in zip(scene.goals, kept.goals))
    assert dropped > 0
    q0 = start_configuration(kin, scene.start)
    for a, b in zip(scene.goals, kept.goals):
        assert set(map(id, b.poses)) <= set(map(id, a.poses))  # a subset, same objects, same order
        for pose in b.poses:
            assert reaches(kin, pose, q0, MARGIN)
        for pose in a.poses:
            if all(pose is not p for p in b.poses):
                assert not reaches(kin, pose, q0, MARGIN)
                assert a.grasp_type.is_top is False  # only side grasps are out of reach on scene2


def test_scene1_loses_only_the_head_on_side_grasp_of_the_cup(kin):
    """Head-on, the cup's side grasp needs the other wrist branch: from the start's branch joint 5 would
    pass its -1.69 rad bound."""
    scene = load_scene("scene1")
    kept = reachable_scene(scene, kin, MARGIN)
    assert [len(g.poses) for g in kept.goals] == [16, 9, 12, 16]
    (lost,) = [p for p in scene.goal("cup:side").poses if all(p is not k for k in kept.goal("cup:side").poses)]
    bearing = np.array([1.0, 0.0, 0.0])  # the cup stands straight ahead
    assert float(np.dot(lost.rotation[:, 2], bearing)) > 0.99


def test_a_goal_with_no_reachable_pose_is_refused_naming_it(kin):
    scene = load_scene("scene1")
    behind = Pose.from_rpy([-0.6, 0.0, 0.25], (math.pi / 2, 0.0, 0.0))  # behind the base, out of reach
    far = Goal("ghost", GraspType.SIDE, (behind,))
    bad = type(scene)(scene.name, scene.start, scene.objects, (*scene.goals, far), scene.table_z)
    with pytest.raises(ValueError, match=r"no grasp pose of ghost:side is reachable"):
        reachable_scene(bad, kin, MARGIN)


@pytest.mark.parametrize("arm, filtered", [("mujoco", True), ("xarm", True), ("kinematic", False)])
def test_the_daemon_plans_over_the_goals_its_arm_reaches(arm, filtered):
    args = cli.build_parser().parse_args(["run", "--arm", arm, "--scene", "scene2", "--task", "drill:side_horizontal",
                                          "--no-speech"])
    daemon = verbs.build_daemon(args)
    poses = len(daemon.opts.scene.goal("drill:side_horizontal").poses)
    assert poses == (2 if filtered else 4)
    assert np.isclose(sum(daemon.ctl.belief.probs), 1.0)
