"""The arm factory: one name per backend, and ``JOINTED_BACKENDS`` agrees with the arms it builds.

``run`` filters the scene's grasp poses by reachability *before* it builds the arm (from the backend's
name, ``JOINTED_BACKENDS``); ``eval`` filters after (from ``arm.kinematics``). Both must mean the
same arms, or the daemon and the evaluation would plan over different goal sets.
"""

from __future__ import annotations

import pytest

from sa_daemon.arm.factory import BACKENDS, JOINTED_BACKENDS, make_arm
from sa_daemon.config import config_from_dict
from sa_daemon.planner.scene import load_scene


@pytest.mark.parametrize("backend", BACKENDS)
def test_jointed_backends_are_exactly_the_arms_with_kinematics(backend: str) -> None:
    cfg = config_from_dict({"arm": {"xarm": {"ip": "fake"}}})  # the documented fake SDK: no arm needed
    arm = make_arm(backend, load_scene("scene1"), cfg)
    try:
        assert (arm.kinematics is not None) == (backend in JOINTED_BACKENDS)
    finally:
        arm.close()


def test_unknown_backend_is_refused_naming_the_choices() -> None:
    with pytest.raises(ValueError, match="kinematic, mujoco, xarm"):
        make_arm("ur5", load_scene("scene1"), config_from_dict({}))
