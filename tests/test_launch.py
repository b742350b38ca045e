"""The composition root builds the daemon from a config and plain options (no argparse), as ``run``,
``bench loop`` and ``bench soak`` do."""

from __future__ import annotations

import pytest

from sa_daemon.config import ConfigError, config_from_dict
from sa_daemon.runtime.launch import DEFAULT_TASK, Launch, build_daemon

KINEMATIC = config_from_dict({"arm": {"backend": "kinematic"}, "speech": {"enabled": False}})


def test_defaults_are_the_paper_task_on_scene1_and_exit_when_done():
    d = build_daemon(KINEMATIC, Launch())
    assert d.opts.scene.name == "scene1" and d.opts.tasks == [DEFAULT_TASK]
    assert d.opts.exit_when_done is True and d.opts.duration_s is None and d.opts.arm == "kinematic"


def test_a_duration_runs_tasks_back_to_back_unless_told_otherwise():
    assert build_daemon(KINEMATIC, Launch(duration_s=5.0)).opts.exit_when_done is False
    d = build_daemon(KINEMATIC, Launch(tasks=("bowl:top", "cup:side"), duration_s=5.0, exit_when_done=True))
    assert d.opts.tasks == ["bowl:top", "cup:side"] and d.opts.exit_when_done is True


def test_a_scene_without_the_default_task_starts_with_its_first_target():
    d = build_daemon(KINEMATIC, Launch(scene="scene2"))
    assert d.opts.tasks == [d.opts.scene.targets[0]] and DEFAULT_TASK not in d.opts.scene.targets


def test_unknown_tasks_scenes_and_exposed_endpoints_are_refused_before_anything_starts():
    with pytest.raises(KeyError, match="teapot:top"):
        build_daemon(KINEMATIC, Launch(tasks=("teapot:top",)))
    with pytest.raises(Exception, match="scene"):
        build_daemon(KINEMATIC, Launch(scene="no-such-scene"))
    exposed = config_from_dict({"arm": {"backend": "kinematic"}, "zmq": {"cmd": "tcp://0.0.0.0:5556"}})
    with pytest.raises(ConfigError, match=r"zmq\.cmd"):
        build_daemon(exposed, Launch())
