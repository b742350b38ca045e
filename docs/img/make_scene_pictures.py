"""Draw the pictures used by docs/scenes.md (run from anywhere: ``python docs/img/make_scene_pictures.py``).

Writes ``scene1.png``, ``scene2.png``, ``study-simple.png``, ``study-complex.png`` (top and side view of
each built-in scene: objects, start pose and every grasp pose as an approach arrow with a closing-axis
tick, coloured by goal) and ``grasp_types.png`` (the six grasp types) next to this script. Lengths in m.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.patches import Circle, Polygon, Rectangle

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parents[1]))

from sa_daemon.geometry import Pose
from sa_daemon.world.grasps import SHOULDER_M, grasp_pose, wrist_point
from sa_daemon.world.scene import Scene, SceneObject, load_scene

ARROW_M = 0.05  # drawn length of an approach arrow
TICK_M = 0.012  # half-length of a closing-axis tick


def _footprint(obj: SceneObject) -> np.ndarray:
    """Corners (x, y) of a box's footprint in the base frame."""
    hx, hy = obj.size[0] / 2, obj.size[1] / 2
    c, s = math.cos(obj.yaw), math.sin(obj.yaw)
    corners = np.array([[hx, hy], [-hx, hy], [-hx, -hy], [hx, -hy]])
    return corners @ np.array([[c, s], [-s, c]]) + np.array(obj.position[:2])


def _draw_objects(top: plt.Axes, side: plt.Axes, scene: Scene) -> None:
    """Objects in grey. Top view: horizontal axis is -y (left of the robot on the left), vertical is x."""
    for obj in scene.objects:
        x, y, z = obj.position
        style = {"facecolor": "0.85", "edgecolor": "0.35", "lw": 0.8, "zorder": 1}
        if obj.shape == "box":
            fp = _footprint(obj)
            top.add_patch(Polygon(np.column_stack((-fp[:, 1], fp[:, 0])), **style))
            x0, x1 = fp[:, 0].min(), fp[:, 0].max()
            side.add_patch(Rectangle((x0, z - obj.size[2] / 2), x1 - x0, obj.size[2], **style))
        else:
            r = obj.size[0]
            top.add_patch(Circle((-y, x), r, **style))
            if obj.shape == "cylinder":
                side.add_patch(Rectangle((x - r, z - obj.size[1] / 2), 2 * r, obj.size[1], **style))
            else:
                side.add_patch(Circle((x, z), r, **style))
        top.text(-y, x, obj.name, ha="center", va="center", fontsize=6.5, zorder=5)


def _draw_pose(top: plt.Axes, side: plt.Axes, pose: Pose, color: str, lw: float = 0.9) -> None:
    """Approach arrow ending at the TCP and a tick along the closing axis, in both views."""
    rot = pose.rotation
    p, y, z = pose.position, rot[:, 1], rot[:, 2]
    tail = p - ARROW_M * z
    for ax, (i, si), (j, sj) in ((top, (1, -1), (0, 1)), (side, (0, 1), (2, 1))):
        def u(v, i=i, si=si, j=j, sj=sj):  # the view's two axes, signed
            return si * v[i], sj * v[j]

        (tx, ty), (px, py) = u(tail), u(p)
        if math.hypot(px - tx, py - ty) > 1e-4:
            ax.annotate("", xy=(px, py), xytext=(tx, ty),
                        arrowprops={"arrowstyle": "-|>", "color": color, "lw": lw, "mutation_scale": 6}, zorder=3)
        else:  # arrow along the viewing direction: a dot
            ax.plot(px, py, "o", color=color, ms=2.5, zorder=3)
        (ax0, ay0), (ax1, ay1) = u(p - TICK_M * y), u(p + TICK_M * y)
        ax.plot([ax0, ax1], [ay0, ay1], color=color, lw=lw * 1.6, solid_capstyle="butt", zorder=4)


def draw_scene(scene: Scene, path: Path) -> None:
    """Top view and side view of ``scene`` with the grasp poses of every goal."""
    fig, (top, side) = plt.subplots(1, 2, figsize=(13, 5.4), gridspec_kw={"width_ratios": [1.1, 1]})
    _draw_objects(top, side, scene)
    colors = plt.get_cmap("tab20" if len(scene.goals) > 10 else "tab10")
    for k, goal in enumerate(scene.goals):
        c = colors(k % colors.N)
        for pose in goal.poses:
            _draw_pose(top, side, pose, c)
        top.plot([], [], color=c, lw=2, label=f"{goal.target} ({len(goal.poses)})")
    _draw_pose(top, side, scene.start, "black", lw=1.6)
    w = wrist_point(scene.start)
    side.plot([scene.start.position[0], w[0]], [scene.start.position[2], w[2]], color="black", lw=3, alpha=0.4)
    top.plot([], [], color="black", lw=2, label="start pose")
    top.plot(0, 0, "ks", ms=8)
    top.text(0.0, 0.02, "robot base", ha="center", fontsize=7)
    side.plot([0, 0], [0, SHOULDER_M[2]], color="0.3", lw=4)
    side.plot(0, SHOULDER_M[2], "ko", ms=5)
    side.axhline(scene.table_z, color="0.3", lw=1)  # the table top
    top.set(xlim=(-0.45, 0.45), ylim=(-0.05, 0.68), aspect="equal", xlabel="-y (m)  (robot's left is left)",
            ylabel="x (m)  forward", title=f"{scene.name}: top view")
    side.set(xlim=(-0.05, 0.72), ylim=(-0.03, 0.75), aspect="equal", xlabel="x (m)", ylabel="z (m)",
             title=f"{scene.name}: side view (looking from the right)")
    for ax in (top, side):
        ax.grid(lw=0.3, alpha=0.5)
    fig.legend(*top.get_legend_handles_labels(), fontsize=7.5, loc="center right", title="target (poses)")
    fig.text(0.5, 0.01, "arrow: approach (tool z) ending at the TCP; bar: closing axis (tool y); "
             "black: start pose (grey: TCP to wrist)", ha="center", fontsize=8)
    fig.tight_layout(rect=(0, 0.03, 0.8, 1))
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _gripper(ax, tcp: np.ndarray, approach: np.ndarray, closing: np.ndarray, color: str) -> None:
    """Schematic parallel-jaw gripper in 3D: two fingers, palm and the approach arrow."""
    pose = grasp_pose(tcp, approach, closing)
    y, z = pose.rotation[:, 1], pose.rotation[:, 2]
    half, finger = 0.045, 0.04
    for sgn in (-1, 1):
        tip = tcp + sgn * half * y
        seg = np.array([tip, tip - finger * z])
        ax.plot(*seg.T, color=color, lw=3)
    palm = np.array([tcp - half * y - finger * z, tcp + half * y - finger * z])
    ax.plot(*palm.T, color=color, lw=3)
    start = tcp - (finger + 0.07) * z
    ax.quiver(*start, *(0.065 * z), color=color, lw=1.5, arrow_length_ratio=0.3)
    ax.quiver(*(tcp - finger * z), *(0.03 * y), color="tab:red", lw=1.2, arrow_length_ratio=0.3)


def draw_grasp_types(path: Path) -> None:
    """The six grasp types on a small box, with the base axes and the rule of each."""
    o = np.zeros(3)
    down, fwd = np.array([0, 0, -1.0]), np.array([1.0, 0, 0])
    ex, ey, ez = np.eye(3)
    panels = [
        ("top", "approach within 30 deg of straight down", down, ey, True),
        ("top_horizontal", "top, closing axis nearer base y than x", down, ey, False),
        ("top_vertical", "top, closing axis nearer base x than y", down, ex, False),
        ("side", "approach within 30 deg of horizontal", fwd, ey, True),
        ("side_horizontal", "side, closing axis nearer horizontal", fwd, ey, False),
        ("side_vertical", "side, closing axis nearer vertical", fwd, ez, False),
    ]
    fig = plt.figure(figsize=(12, 7.5))
    for k, (name, rule, approach, closing, cone) in enumerate(panels):
        ax = fig.add_subplot(2, 3, k + 1, projection="3d")
        ax.bar3d(-0.025, -0.025, -0.04, 0.05, 0.05, 0.08, color="0.8", alpha=0.5, shade=True)
        _gripper(ax, o - 0.005 * approach, approach, closing, "tab:blue")
        if cone:  # the 30-deg cone (top) or band (side) of approach directions
            t = np.linspace(0, 2 * np.pi, 60)
            if name == "top":
                for a in (math.radians(30),):
                    ring = np.stack((np.sin(a) * np.cos(t), np.sin(a) * np.sin(t), np.full_like(t, math.cos(a))))
                    ax.plot(*(0.13 * ring), color="tab:green", lw=1)
                    for j in range(0, 60, 10):
                        ax.plot([0, 0.13 * ring[0, j]], [0, 0.13 * ring[1, j]], [0, 0.13 * ring[2, j]],
                                color="tab:green", lw=0.6)
            else:
                for e in (-30, 30):
                    a = math.radians(e)
                    ring = np.stack((np.cos(a) * np.cos(t), np.cos(a) * np.sin(t), np.full_like(t, np.sin(a))))
                    ax.plot(*(0.11 * ring), color="tab:green", lw=0.8)
        for v, lab in ((ex, "x"), (ey, "y"), (ez, "z")):
            ax.quiver(-0.1, -0.1, -0.08, *(0.04 * v), color="k", lw=1, arrow_length_ratio=0.25)
            ax.text(*(np.array([-0.1, -0.1, -0.08]) + 0.05 * v), lab, fontsize=8)
        ax.set(xlim=(-0.12, 0.12), ylim=(-0.12, 0.12), zlim=(-0.1, 0.16), xticks=[], yticks=[], zticks=[])
        ax.set_box_aspect((1, 1, 1.1))
        ax.view_init(elev=22, azim=-60)
        ax.set_title(f"{name}\n{rule}", fontsize=9)
    fig.text(0.5, 0.02, "blue: gripper (arrow = approach, tool z); red: closing axis (tool y); green: 30-deg limits "
             "of the approach; black: base axes (x forward, y left, z up)", ha="center", fontsize=9)
    fig.tight_layout(rect=(0, 0.04, 1, 1))
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main() -> None:
    for name in ("scene1", "scene2", "study-simple", "study-complex"):
        draw_scene(load_scene(name), HERE / f"{name}.png")
    draw_grasp_types(HERE / "grasp_types.png")
    print(f"wrote pictures to {HERE}")


if __name__ == "__main__":
    main()
