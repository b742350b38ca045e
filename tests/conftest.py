"""Small shared fixtures: a hand-built 4-goal scene and a goal factory (no dependency on scene.py)."""

from __future__ import annotations

import math

import pytest

from sa_daemon.config import Config
from sa_daemon.geometry import Pose
from sa_daemon.world.goals import Goal, GraspType
from sa_daemon.world.goalset import GoalSet

TOP_RPY = (math.pi, 0.0, 0.0)
SIDE_RPY = (math.pi, -math.pi / 2, 0.0)


def _goal(obj: str, kind: str, *positions, rpy=None) -> Goal:
    """Goal ``obj:kind`` with one grasp pose per position, all in the grasp type's orientation."""
    gt = GraspType(kind)
    if rpy is None:
        rpy = TOP_RPY if gt.is_top else SIDE_RPY
    return Goal(obj, gt, tuple(Pose.from_rpy(p, rpy) for p in positions))


@pytest.fixture
def make_goal():
    """Factory: ``make_goal("cup", "top", [x, y, z], ..., rpy=None)``."""
    return _goal


@pytest.fixture
def scene_goals() -> tuple[Goal, ...]:
    """Cup top, cup side, chips can side, bowl top: one grasp pose each."""
    return (
        _goal("cup", "top", [0.45, 0.15, 0.09]),
        _goal("cup", "side", [0.45, 0.15, 0.05]),
        _goal("chips_can", "side", [0.50, -0.10, 0.12]),
        _goal("bowl", "top", [0.35, -0.25, 0.06]),
    )


@pytest.fixture
def scene(scene_goals) -> GoalSet:
    return GoalSet(scene_goals)


@pytest.fixture
def start_pose() -> Pose:
    """Gripper start pose of the scene."""
    return Pose.from_rpy([0.25, 0.0, 0.35], [math.pi, -math.pi / 4, 0.0])


@pytest.fixture
def cfg() -> Config:
    return Config()
