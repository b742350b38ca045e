"""The arm registry and factory: one name per backend, and ``JOINTED_BACKENDS`` agrees with the arms it builds.

``run`` filters the scene's grasp poses by reachability *before* it builds the arm (from the backend's
name, ``JOINTED_BACKENDS``); ``eval`` filters after (from ``arm.kinematics``). Both must mean the
same arms, or the daemon and the evaluation would plan over different goal sets.
"""

from __future__ import annotations

import pytest

from sa_daemon.arm.backends import BACKENDS, JOINTED_BACKENDS, SIMULATED_BACKENDS
from sa_daemon.arm.factory import make_arm
from sa_daemon.cli import build_parser
from sa_daemon.config import ConfigError, config_from_dict
from sa_daemon.world.scene import load_scene


@pytest.mark.parametrize("backend", BACKENDS)
def test_jointed_backends_are_exactly_the_arms_with_kinematics(backend: str) -> None:
    cfg = config_from_dict({"arm": {"xarm": {"sdk": "fake"}}})  # the documented fake SDK: no arm needed
    arm = make_arm(backend, load_scene("scene1"), cfg)
    try:
        assert (arm.kinematics is not None) == (backend in JOINTED_BACKENDS)
    finally:
        arm.close()


def test_unknown_backend_is_refused_naming_the_choices() -> None:
    with pytest.raises(ValueError, match="kinematic, mujoco, xarm"):
        make_arm("ur5", load_scene("scene1"), config_from_dict({}))


def test_every_place_that_names_a_backend_reads_the_registry() -> None:
    """Config validation, ``run --arm`` and ``eval --arm`` take their names from the one registry."""
    for name in BACKENDS:
        assert config_from_dict({"arm": {"backend": name}}).arm.backend == name
    with pytest.raises(ConfigError, match=r"arm.backend.*kinematic, mujoco, xarm"):
        config_from_dict({"arm": {"backend": "ur5"}})
    sub = next(a for a in build_parser()._actions if a.dest == "command").choices
    run_arm = next(a for a in sub["run"]._actions if a.dest == "arm")
    eval_arm = next(a for a in sub["eval"]._actions if a.dest == "arm")
    assert tuple(run_arm.choices) == BACKENDS
    assert tuple(eval_arm.choices) == SIMULATED_BACKENDS == ("kinematic", "mujoco")
