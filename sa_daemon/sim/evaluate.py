"""``sa-daemon eval``: every task x method x seed, in parallel processes, summarised like the paper.

Results depend only on the seeds and the configuration (the planner stops at a node budget, never at a
clock), so parallel and serial runs give the same numbers. Summaries follow section IV: completion time,
mode changes, joystick input and opposing time over successful trials; success, correct prediction and
questions over all trials.
"""

from __future__ import annotations

import json
import multiprocessing as mp
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

from ..config import Config
from ..world.scene import load_scene
from .episode import arm_factory, run_trial

SUCCESS_METRICS = ("completion_time_s", "mode_changes", "joystick_input", "opposing_pct")


@dataclass(frozen=True)
class TrialSpec:
    scene: str  # built-in name or path
    task: str
    method: str
    seed: int


def timeline_path(plots: Path, spec: TrialSpec, scene_name: str) -> Path:
    """Where the Fig. 4 timeline of one trial goes."""
    safe = f"{scene_name}_{spec.task}_{spec.method}_seed{spec.seed}".replace(" ", "-").replace(":", "-")
    return plots / f"{safe.replace('+', '_')}.png"


def _run(args: tuple[TrialSpec, Config, Path | None, str]) -> dict:
    spec, cfg, plots, arm = args
    scene = load_scene(spec.scene)
    result = run_trial(
        scene, spec.task, spec.method, spec.seed, cfg, arm_factory=arm_factory(arm), record=plots is not None
    )
    if plots is not None:
        from .plots import plot_timeline

        plot_timeline(result, timeline_path(plots, spec, scene.name))
    return result.metrics()


def run_trials(
    specs: list[TrialSpec], cfg: Config, jobs: int = 1, progress: bool = True, plots: Path | None = None,
    arm: str = "kinematic",
) -> list[dict]:
    """Run ``specs`` (in ``jobs`` spawned processes when > 1); results in the order of ``specs``.

    With ``plots`` every trial also writes its Fig. 4 timeline there. ``arm`` names the arm backend
    (``kinematic`` or ``mujoco``; a name, so the work items pickle for the spawn pool).
    """
    work = [(s, cfg, plots, arm) for s in specs]
    bar = tqdm(total=len(work), desc="trials", unit="trial", file=sys.stderr, disable=not progress)
    out: list[dict] = []
    if jobs <= 1:
        for w in work:
            out.append(_run(w))
            bar.update()
    else:
        with mp.get_context("spawn").Pool(jobs) as pool:
            for r in pool.imap(_run, work):
                out.append(r)
                bar.update()
    bar.close()
    return out


def summarise(trials: list[dict]) -> list[dict]:
    """One summary per (scene, task, method), in first-seen order."""
    groups: dict[tuple[str, str, str], list[dict]] = {}
    for t in trials:
        groups.setdefault((t["scene"], t["task"], t["method"]), []).append(t)
    out = []
    for (scene, task, method), ts in groups.items():
        ok = [t for t in ts if t["success"]]
        row = {"scene": scene, "task": task, "method": method, "n": len(ts)}
        row["success_rate"] = float(np.mean([t["success"] for t in ts]))
        for k in SUCCESS_METRICS:
            vals = [t[k] for t in ok]
            row[k] = float(np.mean(vals)) if vals else None
            row[k + "_std"] = float(np.std(vals)) if vals else None
        row["correct_prediction_rate"] = float(np.mean([t["correct_prediction"] for t in ts]))
        row["questions"] = float(np.mean([t["questions"] for t in ts]))
        out.append(row)
    return out


def format_summary(rows: list[dict], markdown: bool = False) -> str:
    """A table of summaries: aligned plain text, or a Markdown table."""
    cols = [
        ("task", "task", "{}"), ("method", "method", "{}"), ("n", "n", "{}"), ("success", "success_rate", "{:.2f}"),
        ("time s", "completion_time_s", "{:.2f}"), ("modes", "mode_changes", "{:.1f}"),
        ("input", "joystick_input", "{:.1f}"), ("oppose %", "opposing_pct", "{:.1f}"),
        ("pred", "correct_prediction_rate", "{:.2f}"), ("qns", "questions", "{:.2f}"),
    ]
    table = [[h for h, _, _ in cols]]
    for r in rows:
        table.append([("-" if r[k] is None else f.format(r[k])) for _, k, f in cols])
    if markdown:
        lines = ["| " + " | ".join(row) + " |" for row in table]
        return "\n".join([lines[0], "|" + "---|" * len(cols)] + lines[1:])
    widths = [max(len(row[i]) for row in table) for i in range(len(cols))]
    lines = ["  ".join(c.ljust(w) if i < 2 else c.rjust(w) for i, (c, w) in enumerate(zip(row, widths))) for row in table]
    return "\n".join([lines[0], "-" * len(lines[0])] + lines[1:])


def write_results(path: str | Path, trials: list[dict], summary: list[dict], meta: dict) -> None:
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_text(json.dumps({"meta": meta, "trials": trials, "summary": summary}, indent=2) + "\n")
