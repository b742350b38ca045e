"""Draw the data-flow picture of docs/architecture.md (run from anywhere: ``python docs/img/make_architecture.py``).

Writes ``architecture.png`` next to this script: one box per package, placed in the order data flows from
the joystick to the arm, with the arrows of one control period. The package list is checked against
``sa_daemon/``: a package that exists but is not drawn (or the reverse) stops the script, so the picture
cannot silently fall behind the layout.
"""

from __future__ import annotations

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
from matplotlib.patches import FancyArrowPatch, FancyBboxPatch

HERE = Path(__file__).resolve().parent
PACKAGE = HERE.parents[1] / "sa_daemon"

# name: (x, y, width, height, colour, lines); centres in figure units
BOXES: dict[str, tuple[float, float, float, float, str, str]] = {
    "io": (1.2, 6.2, 2.0, 1.1, "#dbe9f6", "io/\njoystick (evdev), ZeroMQ,\nrecorder, CURVE keys"),
    "sim": (1.2, 4.4, 2.0, 1.1, "#dbe9f6", "sim/\nsimulated user,\nevaluation, metrics"),
    "speech": (1.2, 2.6, 2.0, 1.1, "#dbe9f6", "speech/\nquestions aloud,\nyes/no by voice"),
    "runtime": (4.6, 6.2, 2.2, 1.1, "#f6e7c1", "runtime/\nloops, lifecycle, commands,\nmessages, composition root"),
    "world": (4.6, 0.9, 2.2, 1.0, "#e2f0d9", "world/\nscene, grasp poses,\ngoals, goal set"),
    "model": (4.6, 2.6, 2.2, 1.1, "#e2f0d9", "model/\nbelief (MaxEnt IOC), actions,\ntwists, reward, methods"),
    "planner": (8.2, 2.6, 2.2, 1.1, "#e2f0d9", "planner/\nsnapshot, exact anytime\nsolver, worker process"),
    "control": (8.2, 4.4, 2.2, 1.1, "#f4d5d5", "control/\nController (belief, plan,\nquestion, mode), safety"),
    "arm": (11.6, 4.4, 2.0, 1.1, "#e5dcf2", "arm/\nkinematic, MuJoCo, xArm;\nkinematics, reach"),
    "bench": (8.2, 6.2, 2.2, 1.1, "#eeeeee", "bench/\nplanner, loop, soak,\nvoice figures"),
    "cli": (11.6, 6.2, 2.0, 1.1, "#eeeeee", "cli/\nsa-daemon verbs,\nmonitor"),
    "testing": (11.6, 2.6, 2.0, 1.1, "#eeeeee", "testing/\nfake xArm SDK\n(hardware boundary)"),
}

# (from, to, label): one control period, and the plan's round trip
FLOWS: list[tuple[str, str, str]] = [
    ("io", "runtime", "axes, buttons,\ncommands"),
    ("sim", "runtime", "axes (sim user)"),
    ("runtime", "control", "on_input, on_answer,\ntick(arm state, t)"),
    ("control", "planner", "snapshot"),
    ("planner", "control", "plan + its goal set"),
    ("control", "arm", "safe twist"),
    ("arm", "control", "ArmState\n(pose, joints, gripper)"),
    ("model", "control", "belief update,\nblended command"),
    ("world", "model", "goals"),
    ("model", "planner", "POMDP"),
    ("speech", "runtime", "heard yes/no"),
    ("runtime", "io", "state, events\n(PUB), MCAP"),
]


def _check_layout() -> None:
    packages = {p.name for p in PACKAGE.iterdir() if p.is_dir() and (p / "__init__.py").exists()}
    drawn = set(BOXES)
    if packages != drawn:
        sys.exit(f"architecture picture out of date: not drawn {sorted(packages - drawn)}, "
                 f"no such package {sorted(drawn - packages)}")


def _anchor(name: str, toward: str) -> tuple[float, float]:
    """The point on ``name``'s box edge facing ``toward``'s centre."""
    x, y, w, h = BOXES[name][:4]
    tx, ty = BOXES[toward][:2]
    dx, dy = tx - x, ty - y
    sx = (w / 2) / abs(dx) if dx else float("inf")
    sy = (h / 2) / abs(dy) if dy else float("inf")
    s = min(sx, sy)
    return x + dx * s, y + dy * s


def draw(path: Path) -> None:
    fig, ax = plt.subplots(figsize=(13.5, 7.2))
    ax.set_xlim(0, 12.9)
    ax.set_ylim(0.2, 7.0)
    ax.axis("off")
    for x, y, w, h, colour, text in BOXES.values():
        ax.add_patch(FancyBboxPatch((x - w / 2, y - h / 2), w, h, boxstyle="round,pad=0.04",
                                    fc=colour, ec="#444444", lw=1.2))
        title, rest = text.split("\n", 1)
        ax.text(x, y + h / 2 - 0.2, title, ha="center", va="center", fontsize=11, weight="bold")
        ax.text(x, y - 0.1, rest, ha="center", va="center", fontsize=8.2)
    for a, b, label in FLOWS:
        both_ways = any(f[:2] == (b, a) for f in FLOWS)
        rad = 0.3 if both_ways else 0.0  # the two directions of a pair bend to opposite sides
        p0, p1 = _anchor(a, b), _anchor(b, a)
        ax.add_patch(FancyArrowPatch(p0, p1, arrowstyle="-|>", mutation_scale=14, lw=1.4, color="#333333",
                                     connectionstyle=f"arc3,rad={rad}", shrinkA=4, shrinkB=4))
        # the arc's midpoint: halfway from the chord's midpoint to arc3's control point
        dx, dy = p1[0] - p0[0], p1[1] - p0[1]
        mx, my = (p0[0] + p1[0]) / 2 + 0.5 * rad * dy, (p0[1] + p1[1]) / 2 - 0.5 * rad * dx
        ha, va = "center", "center"
        if both_ways:  # beside its own arc, on the outside
            n = (dx * dx + dy * dy) ** 0.5
            ux, uy = dy / n, -dx / n
            mx, my = mx + 0.12 * ux, my + 0.12 * uy
            ha = "left" if ux > 0.5 else "right" if ux < -0.5 else "center"
            va = "bottom" if uy > 0.5 else "top" if uy < -0.5 else "center"
        ax.text(mx, my, label, ha=ha, va=va, fontsize=7.6, color="#1a3d7c",
                bbox={"fc": "white", "ec": "none", "alpha": 0.85, "pad": 1})
    ax.set_title("sa-daemon: one control period, joystick to arm (arrows: data; grey: tools around the product)",
                 fontsize=11)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    _check_layout()
    out = HERE / "architecture.png"
    draw(out)
    print(out)
