"""Grasp classification, generation from primitives, clustering and the reachability filter."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sa_daemon.geometry import Pose, quat_angle
from sa_daemon.world.goals import GraspType as G
from sa_daemon.world.grasps import (
    GRIPPER_MAX_OPENING_M,
    GraspInfeasibleError,
    UnreachableGraspError,
    classify_grasp,
    cluster_grasps,
    flip_grasp,
    generate_grasps,
    grasp_pose,
    is_reachable,
    wrist_point,
)

P = [0.45, 0.0, 0.1]  # a comfortably reachable TCP position (m)


def tilted(theta_deg: float, closing=(0.0, 1.0, 0.0), position=P) -> Pose:
    """Approach tilted ``theta`` from straight down towards +x (90 = horizontal forward, 180 = up)."""
    t = math.radians(theta_deg)
    return grasp_pose(position, np.array([math.sin(t), 0.0, -math.cos(t)]), np.array(closing))


@pytest.mark.parametrize(
    "theta, coarse",
    [
        (0.0, G.TOP),
        (29.9, G.TOP),
        (30.0, G.TOP),
        (30.1, None),
        (45.0, None),
        (59.9, None),
        (60.0, G.SIDE),
        (60.1, G.SIDE),
        (90.0, G.SIDE),
        (119.9, G.SIDE),
        (120.0, G.SIDE),
        (120.1, None),
        (180.0, None),
    ],
)
def test_approach_cones_at_30_degrees(theta: float, coarse: G | None) -> None:
    pose = tilted(theta)
    assert classify_grasp(pose, fine=False) == coarse
    fine = classify_grasp(pose, fine=True)
    if coarse is None:
        assert fine is None
    else:  # closing axis is base y: horizontal for both families
        assert fine == (G.TOP_HORIZONTAL if coarse is G.TOP else G.SIDE_HORIZONTAL)


@pytest.mark.parametrize(
    "psi, expected",
    [(0.0, G.TOP_VERTICAL), (44.9, G.TOP_VERTICAL), (45.0, G.TOP_HORIZONTAL), (45.1, G.TOP_HORIZONTAL),
     (90.0, G.TOP_HORIZONTAL), (134.9, G.TOP_HORIZONTAL), (135.1, G.TOP_VERTICAL), (-30.0, G.TOP_VERTICAL)],
)
def test_top_closing_axis_rule(psi: float, expected: G) -> None:
    a = math.radians(psi)
    pose = tilted(0.0, closing=(math.cos(a), math.sin(a), 0.0))
    assert classify_grasp(pose, fine=True) == expected
    assert classify_grasp(pose, fine=False) == G.TOP


@pytest.mark.parametrize(
    "beta, expected",
    [(0.0, G.SIDE_HORIZONTAL), (44.9, G.SIDE_HORIZONTAL), (45.0, G.SIDE_VERTICAL), (45.1, G.SIDE_VERTICAL),
     (90.0, G.SIDE_VERTICAL), (-60.0, G.SIDE_VERTICAL)],
)
def test_side_closing_axis_rule(beta: float, expected: G) -> None:
    b = math.radians(beta)
    pose = tilted(90.0, closing=(0.0, math.cos(b), math.sin(b)))
    assert classify_grasp(pose, fine=True) == expected
    assert classify_grasp(pose, fine=False) == G.SIDE


def test_flip_reverses_closing_axis_only() -> None:
    pose = tilted(70.0, closing=(0.0, 0.6, 0.8))
    flipped = flip_grasp(pose)
    r, f = pose.rotation, flipped.rotation
    np.testing.assert_allclose(f[:, 2], r[:, 2], atol=1e-12)
    np.testing.assert_allclose(f[:, 1], -r[:, 1], atol=1e-12)
    np.testing.assert_allclose(flipped.position, pose.position)
    assert quat_angle(flipped.quat_wxyz, pose.quat_wxyz) == pytest.approx(math.pi)
    assert quat_angle(flip_grasp(flipped).quat_wxyz, pose.quat_wxyz) == pytest.approx(0.0, abs=1e-7)


unit = st.floats(-1.0, 1.0, allow_nan=False)


@settings(max_examples=200, deadline=None)
@given(st.tuples(unit, unit, unit, unit).filter(lambda q: np.linalg.norm(q) > 0.1),
       st.tuples(st.floats(-0.8, 0.8), st.floats(-0.8, 0.8), st.floats(-0.2, 0.8)))
def test_flip_keeps_type_and_reachability(q: tuple, p: tuple) -> None:
    pose = Pose(np.array(p), np.array(q))
    flipped = flip_grasp(pose)
    for fine in (False, True):
        assert classify_grasp(flipped, fine) == classify_grasp(pose, fine)
    assert is_reachable(flipped) == is_reachable(pose)


CASES = [
    ("cylinder", [0.04, 0.10], [0.45, 0.0, 0.05], 0.0, True, ["top", "side", "top_horizontal", "top_vertical",
                                                            "side_horizontal"]),
    ("cylinder", [0.03, 0.07], [0.40, 0.2, 0.035], 0.0, False, list(G)),
    ("cylinder", [0.037, 0.25], [0.50, -0.15, 0.125], 0.0, False, ["side", "side_horizontal"]),
    ("cylinder", [0.08, 0.06], [0.40, 0.22, 0.03], 0.0, True, ["top", "top_horizontal", "top_vertical",
                                                             "side", "side_vertical"]),
    ("sphere", [0.03], [0.45, -0.1, 0.03], 0.0, False, list(G)),
    ("box", [0.07, 0.19, 0.06], [0.58, -0.12, 0.03], 0.0, False, ["top", "top_vertical", "side",
                                                                 "side_vertical", "side_horizontal"]),
    ("box", [0.05, 0.06, 0.2], [0.4, 0.1, 0.1], 0.4, False, ["top", "top_horizontal", "top_vertical", "side",
                                                            "side_horizontal"]),
    ("box", [0.035, 0.17, 0.02], [0.36, -0.16, 0.01], 0.0, False, ["top", "side", "top_vertical"]),
]


@pytest.mark.parametrize("shape, size, pos, yaw, rim, types", CASES)
def test_generated_grasps_have_their_type_and_are_reachable(shape, size, pos, yaw, rim, types) -> None:
    for t in types:
        gt = G(t)
        poses = generate_grasps(shape, size, pos, yaw, gt, rim=rim)
        assert 2 <= len(poses) <= 16 and len(poses) % 2 == 0
        fine = gt not in (G.TOP, G.SIDE)
        for pose in poses:
            assert classify_grasp(pose, fine) == gt
            assert is_reachable(pose)
        for a, b in zip(poses[::2], poses[1::2]):  # each pose followed by its flip
            np.testing.assert_allclose(b.rotation, flip_grasp(a).rotation, atol=1e-9)
            np.testing.assert_allclose(b.position, a.position)
        again = generate_grasps(shape, size, pos, yaw, gt, rim=rim)
        assert [p.as_dict() for p in again] == [p.as_dict() for p in poses]


def test_box_yaw_swaps_top_horizontal_and_top_vertical() -> None:
    size, pos = [0.05, 0.20, 0.05], [0.45, 0.0, 0.025]
    assert generate_grasps("box", size, pos, 0.0, "top_vertical")
    with pytest.raises(GraspInfeasibleError, match="top_horizontal.*0.085 m gripper opening"):
        generate_grasps("box", size, pos, 0.0, "top_horizontal")
    assert generate_grasps("box", size, pos, math.pi / 2, "top_horizontal")
    with pytest.raises(GraspInfeasibleError, match="top_vertical"):
        generate_grasps("box", size, pos, math.pi / 2, "top_vertical")
    # closing across the 5 cm faces: the closing axis is the box's narrow local x axis
    for pose in generate_grasps("box", size, pos, 0.3, "top_vertical"):
        y = pose.rotation[:, 1]
        assert abs(np.dot(y, [math.cos(0.3), math.sin(0.3), 0.0])) == pytest.approx(1.0)


def test_rim_grasps_pinch_the_wall_radially() -> None:
    centre = np.array([0.40, 0.22, 0.03])
    for rim in (True, False):  # a bowl wider than the opening gets rim grasps either way
        poses = generate_grasps("cylinder", [0.08, 0.06], centre, 0.0, "top", rim=rim)
        assert len(poses) == 16
        for pose in poses:
            radial = pose.position[:2] - centre[:2]
            assert np.linalg.norm(radial) == pytest.approx(0.077, abs=1e-6)
            y = pose.rotation[:, 1]
            assert abs(np.dot(y[:2], radial / np.linalg.norm(radial))) == pytest.approx(1.0)
            assert pose.position[2] > centre[2]  # near the rim, above the middle


def test_narrow_cylinder_top_grasps_cross_the_top() -> None:
    poses = generate_grasps("cylinder", [0.03, 0.08], [0.4, 0.0, 0.04], 0.0, "top_vertical")
    assert len(poses) == 6
    for pose in poses:
        np.testing.assert_allclose(pose.position[:2], [0.4, 0.0], atol=1e-12)
        assert pose.position[2] == pytest.approx(0.06)


def test_infeasible_types_raise() -> None:
    with pytest.raises(GraspInfeasibleError, match="side_horizontal"):  # 16 cm across
        generate_grasps("cylinder", [0.08, 0.06], [0.4, 0.2, 0.03], 0.0, "side_horizontal", rim=True)
    with pytest.raises(GraspInfeasibleError):  # 10 cm tall: no vertical closing
        generate_grasps("cylinder", [0.04, 0.10], [0.45, 0.0, 0.05], 0.0, "side_vertical")
    with pytest.raises(GraspInfeasibleError):
        generate_grasps("sphere", [0.05], [0.45, 0.0, 0.05], 0.0, "top")
    with pytest.raises(GraspInfeasibleError):
        generate_grasps("box", [0.1, 0.1, 0.1], [0.45, 0.0, 0.05], 0.0, "side")
    assert issubclass(GraspInfeasibleError, ValueError)


def test_far_object_is_unreachable() -> None:
    with pytest.raises(UnreachableGraspError, match="no reachable top grasp"):
        generate_grasps("cylinder", [0.04, 0.10], [0.95, 0.0, 0.05], 0.0, "top", rim=True)
    assert issubclass(UnreachableGraspError, ValueError)


@pytest.mark.parametrize(
    "shape, size, error",
    [("cone", [0.1], "unknown shape"), ("cylinder", [0.04], r"cylinder needs \[radius, height\]"),
     ("box", [0.1, -0.1, 0.1], "positive"), ("sphere", [float("nan")], "positive and finite")],
)
def test_bad_primitive_raises(shape: str, size: list[float], error: str) -> None:
    with pytest.raises(ValueError, match=error):
        generate_grasps(shape, size, [0.4, 0.0, 0.1], 0.0, "top")


def test_rim_needs_a_cylinder() -> None:
    with pytest.raises(ValueError, match="rim"):
        generate_grasps("box", [0.05, 0.05, 0.05], [0.4, 0.0, 0.025], 0.0, "top", rim=True)


def test_reachability_rule() -> None:
    assert is_reachable(tilted(0.0))
    np.testing.assert_allclose(wrist_point(tilted(0.0)), [0.45, 0.0, 0.272])
    # wrist 0.70 m from the shoulder (0, 0, 0.267) is the limit
    assert is_reachable(tilted(90.0, position=[0.172 + 0.699, 0.0, 0.267]))
    assert not is_reachable(tilted(90.0, position=[0.172 + 0.701, 0.0, 0.267]))
    # horizontal approach: the wrist is as low as the TCP
    assert not is_reachable(tilted(90.0, position=[0.4, 0.0, 0.029]))
    assert is_reachable(tilted(90.0, position=[0.4, 0.0, 0.031]))
    # straight down: the wrist is high but the TCP must stay above the table
    assert not is_reachable(tilted(0.0, position=[0.4, 0.0, 0.004]))
    assert is_reachable(tilted(0.0, position=[0.4, 0.0, 0.006]))


def test_cluster_raw_grasps() -> None:
    down_y = tilted(5.0)  # top, closing along base y
    down_x = tilted(0.0, closing=(1.0, 0.0, 0.0))  # top, closing along base x
    side_h = tilted(95.0)  # side, closing horizontal
    side_v = tilted(80.0, closing=(0.0, 0.0, 1.0))  # side, closing (nearly) vertical
    oblique = tilted(45.0)  # no type
    raw = [down_y, oblique, side_h, down_x, side_v]
    out = cluster_grasps(raw, ["top", G.TOP_VERTICAL, "side_horizontal", G.SIDE_VERTICAL])
    assert list(out) == [G.TOP, G.TOP_VERTICAL, G.SIDE_HORIZONTAL, G.SIDE_VERTICAL]
    assert out[G.TOP] == [down_y, down_x]
    assert out[G.TOP_VERTICAL] == [down_x]
    assert out[G.SIDE_HORIZONTAL] == [side_h]
    assert out[G.SIDE_VERTICAL] == [side_v]
    assert all(oblique not in v for v in out.values())
    assert cluster_grasps(raw, ["top_horizontal", "side"]) == {
        G.TOP_HORIZONTAL: [down_y], G.SIDE: [side_h, side_v]}


def box_chord(pose: Pose, size: np.ndarray, centre: np.ndarray, yaw: float) -> float:
    """Length (m) of the closing-axis line through the TCP inside a yawed box (0 if it misses)."""
    c, s = math.cos(yaw), math.sin(yaw)
    to_local = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
    p = to_local @ (pose.position - centre)
    d = to_local @ pose.rotation[:, 1]
    lo, hi = -np.inf, np.inf
    for i in range(3):
        if abs(d[i]) < 1e-12:
            if abs(p[i]) > size[i] / 2:
                return 0.0
            continue
        a, b = sorted(((-size[i] / 2 - p[i]) / d[i], (size[i] / 2 - p[i]) / d[i]))
        lo, hi = max(lo, a), min(hi, b)
    return max(hi - lo, 0.0)


@pytest.mark.parametrize(
    "size, pos, yaw",
    [([0.07, 0.19, 0.06], [0.58, -0.12, 0.03], 0.0), ([0.08, 0.05, 0.08], [0.4, 0.1, 0.04], 0.5),
     ([0.035, 0.17, 0.02], [0.36, -0.16, 0.01], 1.2), ([0.05, 0.06, 0.2], [0.4, 0.1, 0.1], -0.4)],
)
def test_generated_box_grasps_fit_the_gripper(size, pos, yaw) -> None:
    """The object's extent along the closing axis through the TCP is at most the 0.085 m opening."""
    size, pos = np.array(size), np.array(pos)
    n = 0
    for t in G:
        try:
            poses = generate_grasps("box", size, pos, yaw, t)
        except GraspInfeasibleError:
            continue
        for pose in poses:
            chord = box_chord(pose, size, pos, yaw)
            assert 0.0 < chord <= GRIPPER_MAX_OPENING_M + 1e-9
            n += 1
    assert n > 0
