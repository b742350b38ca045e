"""Scene loading: built-in scenes, the TOML format, explicit grasps and error messages."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from sa_daemon.world.goals import GraspType as G
from sa_daemon.world.grasps import classify_grasp, grasp_pose, is_reachable
from sa_daemon.world.scene import (
    Scene,
    SceneError,
    SceneObject,
    builtin_scene_names,
    load_scene,
    scene_from_dict,
)

EXPECTED_TARGETS = {
    "scene1": ["cup:top", "cup:side", "chips can:side", "bowl:top"],
    "scene2": [
        "cup:top_horizontal", "cup:side_horizontal", "chips can:side_horizontal", "meat can:side_horizontal",
        "scissors:top_vertical", "scissors:side_vertical", "drill:top_vertical", "drill:side_vertical",
        "drill:side_horizontal", "bleach cleanser:side_horizontal", "spoon:top_vertical", "spoon:side_vertical",
        "spoon:side_horizontal", "bowl:top_vertical", "bowl:top_horizontal", "banana:top_horizontal",
        "sugar box:top_horizontal", "sugar box:side_horizontal",
    ],
    "study-simple": ["cup:top", "cup:side", "bottle:side", "bowl:top", "spoon:top", "spoon:side"],
}

EXAMPLE = """\
name = "my-scene"
[start]                      # gripper start pose, base frame
position = [0.25, 0.0, 0.35]
rpy = [3.14159, 0.0, 0.0]    # or quat_wxyz = [...]
[[objects]]
name = "cup"
shape = "cylinder"
size = [0.04, 0.10]
position = [0.42, 0.20, 0.05]
yaw = 0.0
rim = false
grasp_types = ["top_vertical", "side_horizontal"]
"""


def write(tmp_path: Path, text: str, name: str = "bad.toml") -> str:
    path = tmp_path / name
    path.write_text(text)
    return str(path)


def test_builtin_names() -> None:
    assert builtin_scene_names() == ["scene1", "scene2", "study-complex", "study-simple"]


@pytest.mark.parametrize("name", sorted(EXPECTED_TARGETS))
def test_builtin_scene_goals(name: str) -> None:
    scene = load_scene(name)
    assert scene.name == name
    assert scene.targets == EXPECTED_TARGETS[name]
    assert [g.target for g in scene.goals] == scene.targets
    for goal in scene.goals:
        assert 2 <= len(goal.poses) <= 16, goal
        fine = goal.grasp_type not in (G.TOP, G.SIDE)
        for pose in goal.poses:
            assert is_reachable(pose, scene.table_z)
            assert classify_grasp(pose, fine) == goal.grasp_type
    # the same mount and start pose everywhere: table top 0.2 m above the base, TCP 0.35 m above the table,
    # tool z forward and down at 45 deg
    assert scene.table_z == pytest.approx(0.2)
    np.testing.assert_allclose(scene.start.position, [0.25, 0.0, 0.55])
    np.testing.assert_allclose(scene.start.rotation[:, 2], [math.sqrt(0.5), 0.0, -math.sqrt(0.5)], atol=1e-6)


POSE_COUNTS = {  # documented in docs/scenes.md; update both together
    "scene1": [16, 10, 12, 16],
    "scene2": [8, 10, 12, 4, 6, 10, 6, 10, 4, 4, 6, 10, 4, 8, 8, 6, 2, 4],
    "study-simple": [16, 10, 12, 16, 6, 14],
}


@pytest.mark.parametrize("name", sorted(POSE_COUNTS))
def test_builtin_pose_counts_match_the_docs(name: str) -> None:
    assert [len(g.poses) for g in load_scene(name).goals] == POSE_COUNTS[name]


def footprint(obj: SceneObject, xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
    """Boolean mask of the table cells under ``obj``."""
    dx, dy = xs - obj.position[0], ys - obj.position[1]
    if obj.shape == "box":
        c, s = math.cos(obj.yaw), math.sin(obj.yaw)
        u, v = c * dx + s * dy, -s * dx + c * dy
        return (np.abs(u) <= obj.size[0] / 2) & (np.abs(v) <= obj.size[1] / 2)
    return np.hypot(dx, dy) <= obj.size[0]


@pytest.mark.parametrize("name", sorted(EXPECTED_TARGETS))
def test_builtin_objects_on_the_table_in_front_without_overlap(name: str) -> None:
    scene = load_scene(name)
    xs, ys = np.meshgrid(np.arange(0.1, 0.8, 0.002), np.arange(-0.6, 0.6, 0.002), indexing="ij")
    cover = np.zeros(xs.shape, dtype=int)
    for obj in scene.objects:
        assert 0.3 <= obj.position[0] <= 0.6, obj.name
        assert obj.bottom_z == pytest.approx(scene.table_z, abs=1e-9), obj.name
        cover += footprint(obj, xs, ys)
    assert cover.max() == 1, "objects overlap"


def test_scene1_cup_top_and_side_are_equally_far() -> None:
    """From the start pose, cup:top and cup:side need similar rotation and translation."""
    scene = load_scene("scene1")
    start = scene.start
    best = {}
    for target in ("cup:top", "cup:side"):
        pose = scene.goal(target).desired_pose(start, 0.05)
        best[target] = start.distance(pose)
    (t_top, r_top), (t_side, r_side) = best["cup:top"], best["cup:side"]
    for r in (r_top, r_side):
        assert math.radians(40) <= r <= math.radians(55)
    assert abs(r_top - r_side) < math.radians(10)
    assert abs(t_top - t_side) < 0.05


def test_goal_lookup() -> None:
    scene = load_scene("scene1")
    assert scene.goal("cup:top").grasp_type is G.TOP
    assert scene.goal("chips can:side").object == "chips can"
    with pytest.raises(KeyError, match="cup:top, cup:side, chips can:side, bowl:top"):
        scene.goal("cup:top_vertical")


def test_example_toml_loads(tmp_path: Path) -> None:
    scene = load_scene(write(tmp_path, EXAMPLE, "my.toml"))
    assert isinstance(scene, Scene)
    assert scene.name == "my-scene"
    assert scene.targets == ["cup:top_vertical", "cup:side_horizontal"]
    cup = scene.objects[0]
    assert cup == SceneObject("cup", "cylinder", (0.04, 0.10), (0.42, 0.20, 0.05), 0.0,
                              (G.TOP_VERTICAL, G.SIDE_HORIZONTAL), False)
    np.testing.assert_allclose(scene.start.rotation[:, 2], [0, 0, -1], atol=1e-5)


def test_quat_start_and_defaults(tmp_path: Path) -> None:
    text = EXAMPLE.replace("rpy = [3.14159, 0.0, 0.0]", "quat_wxyz = [0.0, 1.0, 0.0, 0.0]")
    text = text.replace('name = "my-scene"\n', "").replace("yaw = 0.0\n", "").replace("rim = false\n", "")
    scene = load_scene(write(tmp_path, text, "plain.toml"))
    assert scene.name == "plain"
    assert scene.objects[0].yaw == 0.0 and scene.objects[0].rim is False
    np.testing.assert_allclose(scene.start.quat_wxyz, [0.0, 1.0, 0.0, 0.0])


def explicit_scene(grasps: list[dict], types: list[str]) -> dict:
    return {
        "start": {"position": [0.25, 0.0, 0.35], "rpy": [math.pi, 0.0, 0.0]},
        "objects": [{"name": "mug", "shape": "cylinder", "size": [0.04, 0.1], "position": [0.45, 0.0, 0.05],
                     "grasp_types": types, "grasps": grasps}],
    }


def grasp_entry(theta_deg: float, closing: tuple[float, float, float], type_: str | None = None) -> dict:
    t = math.radians(theta_deg)
    pose = grasp_pose([0.45, 0.0, 0.08], np.array([math.sin(t), 0.0, -math.cos(t)]), np.array(closing))
    entry = {"position": pose.position.tolist(), "quat_wxyz": pose.quat_wxyz.tolist()}
    if type_ is not None:
        entry["type"] = type_
    return entry


def test_explicit_grasps_with_and_without_type() -> None:
    grasps = [
        grasp_entry(0.0, (1.0, 0.0, 0.0), "top_vertical"),  # typed
        grasp_entry(45.0, (0.0, 1.0, 0.0), "top_vertical"),  # typed: the label wins over the rule
        grasp_entry(10.0, (1.0, 0.0, 0.0)),  # untyped: top_vertical by the rule
        grasp_entry(90.0, (0.0, 1.0, 0.0)),  # untyped: side_horizontal
        grasp_entry(45.0, (0.0, 1.0, 0.0)),  # untyped, fits no type: dropped
        grasp_entry(0.0, (0.0, 1.0, 0.0)),  # untyped top_horizontal: not listed, dropped
    ]
    scene = scene_from_dict(explicit_scene(grasps, ["top_vertical", "side_horizontal"]), "x.toml")
    assert scene.targets == ["mug:top_vertical", "mug:side_horizontal"]
    assert len(scene.goal("mug:top_vertical").poses) == 3
    side = scene.goal("mug:side_horizontal").poses
    assert len(side) == 1 and classify_grasp(side[0], True) is G.SIDE_HORIZONTAL
    np.testing.assert_allclose(scene.goal("mug:top_vertical").poses[0].position, [0.45, 0.0, 0.08])


def test_explicit_grasp_errors() -> None:
    with pytest.raises(SceneError, match=r"x.toml: objects\[0\] 'mug': grasps\[0\].type: 'side'"):
        scene_from_dict(explicit_scene([grasp_entry(0.0, (1, 0, 0), "side")], ["top"]), "x.toml")
    with pytest.raises(SceneError, match=r"objects\[0\] 'mug': grasps: no reachable grasp pose of type side"):
        scene_from_dict(explicit_scene([grasp_entry(0.0, (1, 0, 0))], ["top", "side"]), "x.toml")
    both = grasp_entry(0.0, (1, 0, 0)) | {"rpy": [0.0, 0.0, 0.0]}
    with pytest.raises(SceneError, match=r"objects\[0\] 'mug': grasps\[0\].rpy: give exactly one"):
        scene_from_dict(explicit_scene([both], ["top"]), "x.toml")
    with pytest.raises(SceneError, match=r"grasps\[0\].color: unknown key"):
        scene_from_dict(explicit_scene([grasp_entry(0.0, (1, 0, 0)) | {"color": 1}], ["top"]), "x.toml")


SECOND = """
[[objects]]
name = "cup"
shape = "box"
size = [0.05, 0.05, 0.05]
position = [0.45, -0.2, 0.025]
grasp_types = ["top"]
"""

CUP = "objects[0] 'cup'"
TYPES = "\"side_horizontal\"]"
POS = "position = [0.42, 0.20, 0.05]"
BAD_FILES = [
    # (edit of the example, substrings the message must contain)
    (("rim = false", "rim = false\ncolour = 'red'"), [CUP, "colour: unknown key"]),
    (("name = \"my-scene\"", "name = \"my-scene\"\nlights = 2"), ["lights: unknown key"]),
    (("size = [0.04, 0.10]", "size = [0.04, nan]"), [CUP, "size[1]", "finite"]),
    ((POS, "position = [0.42, inf, 0.05]"), [CUP, "position[1]"]),
    (("size = [0.04, 0.10]", "size = [0.04, -0.10]"), [CUP, "size:", "positive"]),
    (("size = [0.04, 0.10]", "size = [0.04]"), [CUP + ": size: cylinder needs [radius, height]"]),
    (("shape = \"cylinder\"", "shape = \"cone\""), [CUP + ": shape: unknown shape 'cone'"]),
    ((TYPES, "\"sideways\"]"), [CUP + ": grasp_types: unknown grasp type 'sideways'"]),
    ((TYPES, "\"top_vertical\"]"), [CUP + ": grasp_types: duplicate"]),
    ((TYPES, "\"side_vertical\"]"), [CUP + ": grasp_types: cannot generate side_vertical"]),
    (("grasp_types = [\"top_vertical\", \"side_horizontal\"]", "grasp_types = []"), [CUP + ": grasp_types"]),
    (("rpy = [3.14159, 0.0, 0.0]", "rpy = [3.14159, 0.0, 0.0]\nquat_wxyz = [1.0, 0.0, 0.0, 0.0]"),
     ["start: rpy: give exactly one of rpy"]),
    (("rpy = [3.14159, 0.0, 0.0]", "quat_wxyz = [0.0, 0.0, 0.0, 0.0]"), ["start: quat_wxyz"]),
    ((POS, "position = [1.20, 0.20, 0.05]"), [CUP + ": position: no reachable"]),
    ((POS, "position = [0.42, 0.20, 0.0]"), [CUP + ": position: ", "table"]),
    (("rim = false", "rim = 1"), [CUP, "rim: Input should be a valid boolean"]),
    (("name = \"cup\"", "name = \"cup:big\""), ["objects[0] 'cup:big': name: "]),
    (("name = \"cup\"\n", ""), ["objects[0]: name: required key missing"]),
    ((TYPES + "\n", TYPES + "\n" + SECOND), ["objects[1] 'cup': name: duplicate of objects[0]"]),
    (("name = \"my-scene\"", "name = \"my-scene"), ["invalid TOML"]),
    (("name = \"my-scene\"", "name = \"my-scene\"\ntable_z = 0.1"), [CUP + ": position: ", "table_z = 0.1"]),
    (("name = \"my-scene\"", "name = \"my-scene\"\ntable_z = 0.9"), ["table_z: 0.9 m is outside"]),
    (("name = \"my-scene\"", "name = \"my-scene\"\ntable_z = nan"), ["table_z"]),
]


@pytest.mark.parametrize("edit, expected", BAD_FILES, ids=[e[1][-1][:40] for e in BAD_FILES])
def test_bad_files_name_object_and_field(tmp_path: Path, edit: tuple[str, str], expected: list[str]) -> None:
    old, new = edit
    assert old in EXAMPLE
    path = write(tmp_path, EXAMPLE.replace(old, new, 1))
    with pytest.raises(SceneError) as info:
        load_scene(path)
    message = str(info.value)
    assert message.startswith(path + ":")
    for part in expected:
        assert part in message, message
    assert isinstance(info.value, ValueError)


def test_rim_on_a_box_is_refused() -> None:
    data = explicit_scene([], ["top"])
    obj = data["objects"][0]
    del obj["grasps"]
    obj.update(shape="box", size=[0.05, 0.05, 0.05], position=[0.45, 0.0, 0.025], rim=True)
    with pytest.raises(SceneError, match=r"^scene: objects\[0\] 'mug': rim: only cylinders"):
        scene_from_dict(data)


def test_unknown_scene_name() -> None:
    with pytest.raises(SceneError, match="scene1, scene2, study-complex, study-simple"):
        load_scene("scene9")


def _lifted(text: str, dz: float) -> str:
    """``text`` with every ``position`` raised by ``dz`` m and ``table_z = dz``."""
    import re

    def up(m: re.Match[str]) -> str:
        x, y, z = (float(v) for v in m.group(1).split(","))
        return f"position = [{x}, {y}, {z + dz}]"

    return re.sub(r"position = \[([^\]]*)\]", up, text).replace('name = "my-scene"', f'name = "my-scene"\ntable_z = {dz}')


@pytest.mark.parametrize("dz", [-0.1, 0.2, 0.35])
def test_a_raised_table_lifts_start_objects_and_grasps_unchanged(tmp_path: Path, dz: float) -> None:
    """Lifting everything with the table keeps every grasp (the reach heights are above the table top)
    as long as the shoulder sphere still reaches them: the built-in scenes rely on this."""
    flat = load_scene(write(tmp_path, EXAMPLE, "flat.toml"))
    lifted = load_scene(write(tmp_path, _lifted(EXAMPLE, dz), "lifted.toml"))
    assert lifted.table_z == dz
    up = np.array([0.0, 0.0, dz])
    np.testing.assert_allclose(lifted.start.position, flat.start.position + up)
    for a, b in zip(flat.goals, lifted.goals, strict=True):
        assert a.target == b.target and len(a.poses) == len(b.poses)
        for p, q in zip(a.poses, b.poses):
            np.testing.assert_allclose(q.position, p.position + up, atol=1e-12)
            np.testing.assert_allclose(q.quat_wxyz, p.quat_wxyz, atol=1e-12)


def test_reach_heights_are_above_the_table_top() -> None:
    pose = grasp_pose([0.4, 0.0, 0.21], np.array([0.0, 0.0, -1.0]), np.array([0.0, 1.0, 0.0]))
    assert is_reachable(pose, table_z=0.2)  # TCP 1 cm above the table top
    assert not is_reachable(pose, table_z=0.207)  # TCP 3 mm above it: below the 5 mm floor
