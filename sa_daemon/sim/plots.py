"""Figures of the evaluation, after the paper's Fig. 4 (one trial's timeline) and Fig. 7 (summary bars).

Both functions write one PNG with the non-interactive Agg backend and close their figure, so they can be
called for many trials without a display and without figures piling up.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from .episode import TrialResult

ACTION_ROWS = ("move", "ho", "none", "ask")  # strip rows of panel (b), top to bottom
AXIS_COLOURS = ("tab:red", "tab:green", "tab:blue")  # x, y, z
FIXED_ACTION_COLOURS = {"ho": "tab:purple", "none": "0.6"}
# (key, axis label) of the Fig. 7 panels; units in the labels.
SUMMARY_METRICS: tuple[tuple[str, str], ...] = (
    ("completion_time_s", "Completion time (s)"),
    ("mode_changes", "Mode changes (count)"),
    ("joystick_input", "Joystick input (sum |axis|)"),
    ("opposing_pct", "Opposing time (%)"),
    ("correct_prediction_rate", "Correct prediction rate (0-1)"),
    ("questions", "Questions asked (per trial)"),
    ("success_rate", "Success rate (0-1)"),
)


def _save(fig: Figure, path: str | Path) -> Path:
    """Write ``fig`` as PNG to ``path`` (parents created) and close it."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    try:
        fig.savefig(p, format="png", dpi=100)
    finally:
        plt.close(fig)
    return p


def _runs(values: Sequence[object]) -> list[tuple[int, int, object]]:
    """Maximal runs of equal consecutive values as ``(start index, end index exclusive, value)``."""
    out: list[tuple[int, int, object]] = []
    start = 0
    for i in range(1, len(values) + 1):
        if i == len(values) or values[i] != values[start]:
            out.append((start, i, values[start]))
            start = i
    return out


def _twist_panel(ax: Axes, t: np.ndarray, user: np.ndarray, robot: np.ndarray, label: str) -> None:
    """x/y/z components of user (solid) and robot (dashed) twists; ``label`` carries the unit."""
    for who, twist, style in (("user", user, "-"), ("robot", robot, "--")):
        for i, (name, colour) in enumerate(zip("xyz", AXIS_COLOURS)):
            ax.step(t, twist[:, i], where="post", color=colour, lw=1.2, ls=style, label=f"{who} {name}")
    ax.axhline(0.0, color="0.8", lw=0.6, zorder=0)
    ax.set_ylabel(label)
    ax.legend(loc="upper left", bbox_to_anchor=(1.005, 1.0), fontsize=7, ncol=2, frameon=False)


def plot_timeline(result: TrialResult, path: str | Path) -> Path:
    """Fig. 4 style timeline of one recorded trial, written as a PNG to ``path``; returns the path.

    Panels share the time axis (s): (a) belief per high-level target (probability 0-1, task target
    thicker), (b) the action applied each control step, (c) opposing flags, (d) user/robot linear
    velocity (m/s), (e) user/robot angular velocity (rad/s), (f) teleoperation mode.
    ``ValueError`` if the trial was run without ``record=True`` or recorded no step.
    """
    tl = result.timeline
    if tl is None or not tl.t:
        raise ValueError("the trial has no timeline: run it with record=True")
    t = np.asarray(tl.t, dtype=float)
    dt = float(t[1] - t[0]) if t.size > 1 else 0.025
    t_end = float(t[-1]) + dt
    belief = np.asarray(tl.belief, dtype=float).reshape(t.size, -1)
    user = np.asarray(tl.user_twist, dtype=float).reshape(t.size, 6)
    robot = np.asarray(tl.robot_twist, dtype=float).reshape(t.size, 6)
    targets = list(result.targets) or [f"target {i}" for i in range(belief.shape[1])]
    cmap = plt.get_cmap("tab10")
    colours = {name: cmap(i % 10) for i, name in enumerate(targets)}

    fig, axs = plt.subplots(
        6, 1, figsize=(11, 12.5), sharex=True, gridspec_kw={"height_ratios": [2.2, 1.3, 0.7, 1.6, 1.6, 0.8]},
    )
    a_bel, a_act, a_opp, a_lin, a_ang, a_mode = axs

    for j, name in enumerate(targets):
        task = name == result.task
        a_bel.step(t, belief[:, j], where="post", color=colours[name], lw=2.6 if task else 1.2,
                   label=f"{name} (task)" if task else name, zorder=3 if task else 2)
    a_bel.set_ylim(-0.03, 1.03)
    a_bel.set_ylabel("belief (p)")
    a_bel.legend(loc="upper left", bbox_to_anchor=(1.005, 1.0), fontsize=8, frameon=False)

    seen: dict[str, object] = {}
    for i0, i1, label in _runs(tl.action):
        kind, _, target = str(label).partition(" ")
        row = ACTION_ROWS.index(kind) if kind in ACTION_ROWS else ACTION_ROWS.index("none")
        colour = colours.get(target, "0.3") if target else FIXED_ACTION_COLOURS.get(kind, "0.3")
        x1 = float(t[i1]) if i1 < t.size else t_end
        a_act.broken_barh([(float(t[i0]), x1 - float(t[i0]))], (row - 0.35, 0.7), facecolors=colour)
        if target:
            seen.setdefault(target, colour)
    a_act.set_yticks(range(len(ACTION_ROWS)), ["move", "ho", "no assist", "question"])
    a_act.set_ylim(len(ACTION_ROWS) - 0.5, -0.5)
    a_act.set_ylabel("action")
    handles = [plt.Rectangle((0, 0), 1, 1, color=c) for c in seen.values()]
    if handles:
        a_act.legend(handles, list(seen), loc="upper left", bbox_to_anchor=(1.005, 1.0), fontsize=7,
                     frameon=False)

    opp = np.asarray(tl.opposed, dtype=bool)
    a_opp.fill_between(np.append(t, t_end), 0, 1, where=np.append(opp, opp[-1]), step="post",
                       color="tab:red", alpha=0.7, lw=0)
    a_opp.set_ylim(0, 1)
    a_opp.set_yticks([])
    a_opp.set_ylabel("opposed")
    if not opp.any():
        a_opp.text(0.5, 0.5, "never opposed", transform=a_opp.transAxes, ha="center", va="center",
                   fontsize=8, color="0.4")
    else:
        a_opp.text(1.005, 0.5, f"{100.0 * opp.mean():.1f}% of steps", transform=a_opp.transAxes,
                   va="center", fontsize=8)

    _twist_panel(a_lin, t, user[:, :3], robot[:, :3], "linear vel. (m/s)")
    _twist_panel(a_ang, t, user[:, 3:], robot[:, 3:], "angular vel. (rad/s)")

    rotation = np.array([m == "rotation" for m in tl.mode], dtype=float)
    a_mode.step(np.append(t, t_end), np.append(rotation, rotation[-1]), where="post", color="k", lw=1.4)
    a_mode.set_yticks([0, 1], ["translation", "rotation"])
    a_mode.set_ylim(-0.3, 1.3)
    a_mode.set_ylabel("mode")
    a_mode.set_xlabel("time (s)")
    a_mode.set_xlim(float(t[0]), t_end)

    for ax, letter in zip(axs, "abcdef"):
        ax.set_ylabel(f"({letter}) {ax.get_ylabel()}")
        ax.grid(axis="x", color="0.9", lw=0.6)
        ax.set_axisbelow(True)
    fig.align_ylabels(axs)
    outcome = "success" if result.success else "failure"
    fig.suptitle(f"{result.scene} | task {result.task} | method {result.method} | seed {result.seed} | "
                 f"{outcome} in {result.completion_time_s:.2f} s")
    fig.subplots_adjust(left=0.12, right=0.80, top=0.95, bottom=0.05, hspace=0.18)
    return _save(fig, path)


def _key(row: dict) -> tuple[str, str, str]:
    return str(row.get("scene", "")), str(row["task"]), str(row.get("user", "calibrated"))


# summary key -> the metric name of sim/evaluate.py's comparisons
_COMPARED = {"completion_time_s": "completion_time_s", "mode_changes": "mode_changes",
             "joystick_input": "joystick_input", "opposing_pct": "opposing_pct", "questions": "questions",
             "success_rate": "success"}


def plot_summary_bars(rows: list[dict], path: str | Path, title: str | None = None,
                      comparisons: list[dict] | None = None) -> Path:
    """Fig. 7 style grouped bars of ``summarise()`` rows, written as a PNG to ``path``; returns the path.

    One panel per metric of ``SUMMARY_METRICS`` (units in the axis labels), tasks (and users, when there
    are several) on the x axis, one bar per method in a colour kept across panels, error bars from the
    95 % bootstrap interval (``ci95``) when present, else one standard deviation (``_std``), a small 'x'
    at zero where a value is missing (None, e.g. no successful trial), and, with ``comparisons``, the
    stars of policy's Holm-corrected difference from that method above its bar.
    ``ValueError`` if ``rows`` is empty.
    """
    if not rows:
        raise ValueError("no summary rows to plot")
    star = {(c["scene"], c["task"], c["user"], c["baseline"], c["metric"]): c["stars"] for c in comparisons or []}
    tasks = list(dict.fromkeys(_key(r) for r in rows))
    methods = list(dict.fromkeys(str(r["method"]) for r in rows))
    table = {(_key(r), str(r["method"])): r for r in rows}
    multi_scene = len({s for s, _, _ in tasks}) > 1
    multi_user = len({u for _, _, u in tasks}) > 1
    tick_labels = [("\n".join(x for x in ((s if multi_scene else ""), task, (u if multi_user else "")) if x))
                   for s, task, u in tasks]
    cmap = plt.get_cmap("tab10")
    colours = {m: cmap(i % 10) for i, m in enumerate(methods)}
    width = 0.8 / len(methods)
    x = np.arange(len(tasks), dtype=float)

    ncols = 4
    nrows = int(np.ceil((len(SUMMARY_METRICS) + 1) / ncols))
    fig, axs = plt.subplots(nrows, ncols, figsize=(max(14.0, 1.2 * len(tasks) * len(methods) * ncols / 3), 4.2 * nrows),
                            squeeze=False)
    flat = list(axs.ravel())
    for ax, (key, label) in zip(flat, SUMMARY_METRICS):
        for k, method in enumerate(methods):
            xs = x - 0.4 + width * (k + 0.5)
            present = [(task, method) in table for task in tasks]  # no row: nothing drawn
            vals = [table[(task, method)].get(key) if p else None for task, p in zip(tasks, present)]
            lo_hi = []
            for task, p, v in zip(tasks, present, vals):
                r = table[(task, method)] if p else {}
                ci = (r.get("ci95") or {}).get(key)
                sd = r.get(key + "_std")
                if v is None:
                    continue
                if ci is not None:
                    lo_hi.append((float(v) - ci[0], ci[1] - float(v)))
                elif sd is not None:
                    lo_hi.append((float(sd), float(sd)))
                else:
                    lo_hi.append((np.nan, np.nan))
            ok = np.array([v is not None for v in vals])
            missing = np.array(present) & ~ok
            if ok.any():
                heights = np.array([float(v) for v in vals if v is not None])
                yerr = np.maximum(np.array(lo_hi, dtype=float).T, 0.0)
                ax.bar(xs[ok], heights, width * 0.95, color=colours[method],
                       yerr=None if np.isnan(yerr).all() else yerr,
                       error_kw={"elinewidth": 0.9, "capsize": 2.5, "ecolor": "0.2"})
                metric = _COMPARED.get(key)
                for xi, (task, h, e) in zip(xs[ok], [(t, hv, ev) for t, hv, ev in
                                                      zip([t for t, v in zip(tasks, vals) if v is not None],
                                                          heights, yerr.T)]):
                    mark = star.get((task[0], task[1], task[2], method, metric), "") if metric else ""
                    if mark:
                        ax.text(xi, h + (0.0 if np.isnan(e[1]) else e[1]), mark, ha="center", va="bottom",
                                fontsize=7, rotation=90 if len(mark) > 2 else 0)
            if missing.any():
                ax.plot(xs[missing], np.zeros(int(missing.sum())), "x", color=colours[method], ms=7, mew=1.8,
                        clip_on=False)
        ax.set_title(label, fontsize=10)
        ax.set_xticks(x, tick_labels, rotation=30 if len(tasks) > 3 else 0, ha="right" if len(tasks) > 3 else "center",
                      fontsize=8)
        ax.set_xlim(-0.6, len(tasks) - 0.4)
        ax.set_ylim(bottom=0)
        ax.grid(axis="y", color="0.9", lw=0.6)
        ax.set_axisbelow(True)
    legend_ax = flat[len(SUMMARY_METRICS)]
    legend_ax.axis("off")
    handles = [plt.Rectangle((0, 0), 1, 1, color=colours[m]) for m in methods]
    labels = list(methods)
    if any(r.get(k) is None for r in rows for k, _ in SUMMARY_METRICS):
        handles.append(plt.Line2D([], [], ls="", marker="x", color="0.3", mew=1.8))
        labels.append("no value (e.g. no success)")
    legend_ax.legend(handles, labels, loc="center", title="method", frameon=False)
    for ax in flat[len(SUMMARY_METRICS) + 1:]:
        ax.axis("off")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return _save(fig, path)
