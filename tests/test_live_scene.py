"""Scenes at run time (issue 19, part 1): ``set_scene`` validated like a scene file, applied with the arm
stopped or at the simulated user's next task, ``sa-daemon scene push`` and the detector bridge example,
against real daemons."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from helpers import CLI, DaemonProc
from hypothesis import example, given, settings
from hypothesis import strategies as st

from sa_daemon.io.protocol import RequestError, parse_request
from sa_daemon.world.live import MAX_OBJECTS, scene_from_request
from sa_daemon.world.scene import SceneError, load_scene

REPO = Path(__file__).resolve().parents[1]
SCENE1 = load_scene("scene1")

#: Two objects the way a detector reports them: a mug with raw untyped grasps (here the poses Scene 1's
#: generator gives its cup, as a detector would report them), a box with none (generated).
_CUP = next(o for o in SCENE1.objects if o.name == "cup")
MUG_GRASPS = [{"position": p.position.tolist(), "quat_wxyz": p.quat_wxyz.tolist()} for p in SCENE1.goal("cup:top").poses]
DETECTED = {"name": "detected", "table_z": SCENE1.table_z, "objects": [
    {"name": "mug", "shape": _CUP.shape, "size": list(_CUP.size), "position": list(_CUP.position), "rim": _CUP.rim,
     "grasp_types": ["top"], "grasps": MUG_GRASPS},
    {"name": "box", "shape": "box", "size": [0.05, 0.05, 0.12], "position": [0.40, -0.15, SCENE1.table_z + 0.06],
     "grasp_types": ["side_horizontal"]},
]}


def test_a_detected_scene_is_built_with_the_scene_files_rules():
    s = scene_from_request({"scene": DETECTED}, SCENE1)
    assert list(s.targets) == ["mug:top", "box:side_horizontal"]
    assert len(s.goal("mug:top").poses) == len(MUG_GRASPS)  # the raw grasps, sorted into their type
    assert np.allclose(s.start.position, SCENE1.start.position)  # no start given: the running one's


def test_a_marker_frame_is_mapped_to_the_base_frame():
    yaw = math.pi / 2
    t = {"position": [0.1, 0.0, 0.0], "quat_wxyz": [math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)]}
    marker = {"name": "m", "table_z": SCENE1.table_z,
              "objects": [{**DETECTED["objects"][1], "position": [-0.15, -0.40, SCENE1.table_z + 0.06]}]}
    s = scene_from_request({"scene": marker, "marker_to_base": t}, SCENE1)
    o = s.objects[0]
    assert np.allclose(o.position, [0.1 + 0.40, -0.15, SCENE1.table_z + 0.06]) and o.yaw == pytest.approx(yaw)
    tilted = {"position": [0, 0, 0], "quat_wxyz": [math.cos(0.1), math.sin(0.1), 0.0, 0.0]}
    with pytest.raises(SceneError, match="about the vertical"):
        scene_from_request({"scene": marker, "marker_to_base": tilted}, SCENE1)


@pytest.mark.parametrize("scene, where", [
    ({"objects": [{**DETECTED["objects"][1], "size": [0.05, -0.05, 0.1]}]}, "objects[0] 'box': size"),
    ({"objects": [{**DETECTED["objects"][1], "shape": "torus"}]}, "objects[0] 'box': shape"),
    ({"objects": [{**DETECTED["objects"][0], "grasps": [{"position": [0.4, 0.1], "quat_wxyz": [0, 1, 0, 0]}]}]},
     "objects[0] 'mug'"),
    ({"objects": []}, "objects"),
    ({"objects": [DETECTED["objects"][1]] * (MAX_OBJECTS + 1)}, "more than"),
    ({"objects": [DETECTED["objects"][1]], "colour": "red"}, "colour"),
])
def test_a_bad_scene_is_refused_naming_the_object_and_field(scene, where):
    with pytest.raises(SceneError, match=where.replace("[", r"\[").replace("]", r"\]")):
        scene_from_request({"scene": scene}, SCENE1)


def test_the_protocol_refuses_malformed_set_scene_requests():
    for body, why in (({"cmd": "set_scene"}, '"scene" must be an object'),
                      ({"cmd": "set_scene", "scene": {}, "when": "later"}, '"when" must be'),
                      ({"cmd": "set_scene", "scene": {}, "marker_to_base": [1]}, '"marker_to_base" must be')):
        with pytest.raises(RequestError, match=why):
            parse_request(json.dumps(body).encode())
    with pytest.raises(RequestError, match="not JSON"):
        parse_request(b'{"cmd": "set_scene", "scene": {"objects": [{"size": [NaN]}]}}')


@settings(max_examples=200, deadline=None)
@given(st.recursive(st.none() | st.booleans() | st.floats(allow_nan=False) | st.text(max_size=12),
                    lambda c: st.lists(c, max_size=4) | st.dictionaries(
                        st.sampled_from(["name", "shape", "size", "position", "yaw", "objects", "grasps",
                                         "grasp_types", "rim", "start", "type", "quat_wxyz"]), c, max_size=5),
                    max_leaves=25))
@example({"objects": [{"grasps": 1.0}]})  # found by this test: the grasp count took len() of a number
def test_fuzzed_scenes_are_a_scene_or_refused_with_a_reason(data):
    try:
        scene_from_request({"scene": data}, SCENE1)
    except SceneError as e:
        assert str(e)


# -- against running daemons ---------------------------------------------------------------------------------

JOYSTICK_RUN = ("--arm", "kinematic", "--input", "evdev", "--scene", "scene1")


@pytest.fixture(scope="module")
def joystick_daemon(tmp_path_factory):
    """A daemon waiting for a joystick that is not there: its stop latches (the stop button is missing)."""
    d = DaemonProc(tmp_path_factory.mktemp("live"), "--method", "ho", "--duration", "600", "--no-speech",
                   run=JOYSTICK_RUN)
    try:
        d.wait_ready()
        yield d
    finally:
        d.close()


def test_set_scene_applies_now_with_the_arm_stopped_and_is_refused_otherwise(joystick_daemon):
    d = joystick_daemon
    c = d.collector
    c.state(lambda s: s["stopped"], timeout_s=30, what="the stop latched (no joystick)")
    i = len(c)
    r = d.request({"cmd": "set_scene", "scene": DETECTED})
    assert r["ok"] and r["targets"] == ["mug:top", "box:side_horizontal"] and r["when"] == "now"
    _, e = c.event("scene", timeout_s=10, start=i)
    assert e["name"] == "detected" and e["objects"] == ["mug", "box"] and e["dropped"] == []
    _, s = c.state(lambda s: {b["goal"] for b in s["belief"]} == {"mug:top", "box:side_horizontal"},
                   timeout_s=10, start=i, what="the belief over the new targets")
    assert all(b["p"] == pytest.approx(0.5) for b in s["belief"]) and s["stopped"]
    assert d.request({"cmd": "scene"})["name"] == "detected"
    bad = d.request({"cmd": "set_scene", "scene": {"objects": [{"name": "x:y"}]}})
    assert not bad["ok"] and "objects[0] 'x:y'" in bad["error"]
    assert d.request({"cmd": "scene"})["name"] == "detected"  # nothing half-applied
    assert d.request({"cmd": "resume"})["ok"]
    c.state(lambda s: not s["stopped"], timeout_s=10, start=len(c))
    r = d.request({"cmd": "set_scene", "scene": DETECTED})
    assert not r["ok"] and "stop the arm first" in r["error"]
    assert d.request({"cmd": "stop"})["ok"]


def test_scene_push_and_the_detector_bridge_send_scenes(joystick_daemon, tmp_path):
    d = joystick_daemon
    assert d.request({"cmd": "stop"})["ok"]
    f = tmp_path / "s.json"
    f.write_text(json.dumps({**DETECTED, "name": "pushed"}))
    r = subprocess.run([*CLI, "scene", "push", str(f), "--cmd", d.cmd], capture_output=True, text=True,
                       timeout=60, check=False)
    assert r.returncode == 0 and json.loads(r.stdout)["scene"] == "pushed", r.stderr
    det = {"marker_to_base": {"position": [0.0, 0.0, 0.0], "quat_wxyz": [1.0, 0.0, 0.0, 0.0]},
           "table_z": SCENE1.table_z, "detections": [{**DETECTED["objects"][0], "name": "cup"}]}
    g = tmp_path / "det.json"
    g.write_text(json.dumps(det))
    r = subprocess.run([sys.executable, str(REPO / "examples" / "detector_bridge.py"), str(g), "--cmd", d.cmd,
                        "--name", "from-camera"], capture_output=True, text=True, timeout=60, check=False)
    assert r.returncode == 0, r.stdout + r.stderr
    assert json.loads(r.stdout)["targets"] == ["cup:top"]
    assert d.request({"cmd": "scene"})["name"] == "from-camera"
    r = subprocess.run([*CLI, "scene", "push", str(f), "--cmd", d.cmd, "--when", "next_task"], capture_output=True,
                       text=True, timeout=60, check=False)
    assert r.returncode == 1 and "for the simulated user" in r.stdout


def test_with_the_simulated_user_a_scene_waits_for_the_next_task(tmp_path):
    scene = {"name": "next", "objects": [
        {"name": "cup", "shape": "cylinder", "size": [0.04, 0.10], "position": [0.42, 0.2, 0.05], "rim": True,
         "grasp_types": ["top"]},
        {"name": "box", "shape": "box", "size": [0.05, 0.05, 0.12], "position": [0.40, -0.15, 0.06],
         "grasp_types": ["side_horizontal"]}]}
    d = DaemonProc(tmp_path / "d", "--method", "ho", "--duration", "600", "--no-speech")
    try:
        d.wait_ready()
        c = d.collector
        r = d.request({"cmd": "set_scene", "scene": scene})
        assert not r["ok"] and "between tasks" in r["error"]
        r = d.request({"cmd": "set_scene", "scene": {"objects": scene["objects"][1:]}, "when": "next_task"})
        assert not r["ok"] and "cup:top" in r["error"]  # the user's task must be in it
        i = len(c)
        r = d.request({"cmd": "set_scene", "scene": scene, "when": "next_task"})
        assert r["ok"] and r["when"] == "next_task", r
        done_i, _ = c.event("task_done", timeout_s=120, start=i)
        _, e = c.event("scene", timeout_s=10, start=done_i)
        assert e["name"] == "next"
        c.state(lambda s: {b["goal"] for b in s["belief"]} == {"cup:top", "box:side_horizontal"}, timeout_s=10,
                start=done_i, what="the next task on the new scene")
    finally:
        d.close()
