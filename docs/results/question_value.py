"""What a question was worth to the person: each question the policy asked, against the same trial without it.

    python docs/results/question_value.py --scene study-complex --task bowl:top_horizontal [--task ...] \\
        [--user calibrated ...] [--first-seed 300] [--seeds 10] [--config FILE] [--window 5] [--json OUT]

For every policy trial (kinematic arm, ``eval.node_budget``, as ``sa-daemon eval`` runs it) and every
question it asked at time ``t_q``, the trial is run again from the same seed with questions *vetoed* from
``t_q`` for ``--window`` seconds (default ``planner.horizon_s``, the span the planner judged the question
over): wherever the planner chose a question in that window, the controller is handed the best action
that is not a question, by the same plan's root values. Up to ``t_q`` the two runs are the same trial
(deterministic per seed); after it they part, and the user's later random draws part with them, so one
pair is noisy and the mean over many is the measure.

Printed per question and summed (:func:`summary`, which also reads a ``--json`` file's records): the
model's **predicted margin** (the question's root value minus the best other action's, reward units, at
the plan that asked) and the **realised saving** (completion time without the question minus with it, s;
a trial that fails on either side is counted apart). A question the model values well above watching
that saves the person no time on average is one the model overvalues. A measuring script, not an
interface: it reads the plan's root values and swaps the controller's input at one point
(``Controller.accept_plan``).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math

import numpy as np

from sa_daemon.config import load_config
from sa_daemon.control.controller import Controller
from sa_daemon.model.actions import ActionKind
from sa_daemon.sim.episode import run_trial
from sa_daemon.sim.users import builtin_user_names, load_user
from sa_daemon.world.scene import load_scene

STILL = 0.005
"""A question counts as asked at a predicted standstill where the user's predicted speed in the mode it was
asked in is below this (m/s in translation, rad/s in rotation): the watch then expects no evidence."""


def summary(rows: list[dict]) -> list[str]:
    """The summary lines of the per-question records ``rows`` (as written to ``--json``): the saving
    (vetoed time minus asked time, s) over the questions both runs succeeded on, by the model's margin, by
    the answer (yes: the asked target is the task's), and by whether the user was predicted still
    (:data:`STILL`); then the failures the question added or mended."""
    out = []
    both = [r for r in rows if r["success"] and r["veto_success"]]
    if both:
        saving = np.array([r["veto_time_s"] - r["time_s"] for r in both])
        margins = np.array([r["margin"] for r in both])
        se = saving.std(ddof=1) / math.sqrt(len(saving)) if len(saving) > 1 else math.nan
        out.append(f"{len(rows)} questions; {len(both)} with both runs successful: saving mean {saving.mean():.2f} s "
                   f"(se {se:.2f}), median {np.median(saving):.2f} s, the question faster in "
                   f"{int((saving > 0).sum())}, slower in {int((saving < 0).sum())}; predicted margin median "
                   f"{np.median(margins):.1f}")
        for lo, hi in ((-math.inf, 10), (10, 30), (30, 100), (100, math.inf)):
            sel = (margins >= lo) & (margins < hi)
            if sel.any():
                out.append(f"  margin [{lo}, {hi}): {int(sel.sum()):4} questions, saving mean {saving[sel].mean():6.2f} s")
        yes = np.array([r["target"] == r["task"] for r in both])
        still = np.array([_predicted_still(r) for r in both])
        for label, sel in (("answered yes", yes), ("answered no", ~yes),
                           ("predicted still in its mode", still), ("predicted moving", ~still)):
            if sel.any():
                out.append(f"  {label}: {int(sel.sum()):4} questions, saving mean {saving[sel].mean():6.2f} s, "
                           f"margin median {np.median(margins[sel]):.1f}")
    lost = sum(r["success"] and not r["veto_success"] for r in rows)
    gained = sum(r["veto_success"] and not r["success"] for r in rows)
    out.append(f"failures without the question: {lost} added, {gained} mended")
    return out


def _predicted_still(row: dict) -> bool:
    """The user's predicted speed in the mode the question was asked in is below :data:`STILL` (``False``
    where the plan was not found: no mode recorded)."""
    if not row["mode"]:
        return False
    linear, angular = row["user_speed"]
    return (angular if row["mode"] == "rotation" else linear) < STILL


def margin(result) -> float:
    """The chosen question's root value minus the best non-question action's (reward units)."""
    others = [v for a, v in result.root_values.items() if a.kind is not ActionKind.QUESTION]
    return result.root_values[result.action] - max(others) if others else math.inf


def without_questions(result):
    """``result`` with its question replaced by the best action that is not a question (root values)."""
    others = {a: v for a, v in result.root_values.items() if a.kind is not ActionKind.QUESTION}
    best = max(others, key=others.__getitem__)
    return dataclasses.replace(result, action=best, value=others[best])


def run(scene, task: str, user: str, seed: int, cfg, veto: tuple[float, float] | None = None):
    """One policy trial; with ``veto = (t0, t1)`` no question is adopted at ``t0 <= t < t1``. Returns the
    trial and, per plan that chose a question, ``(t, margin, mode, user_speed)``."""
    chosen: list[tuple[float, float, str, tuple[float, float]]] = []

    def on_plan(t, snap, result):
        if result.action.kind is ActionKind.QUESTION:
            chosen.append((t, margin(result), snap.mode.value, snap.user_speed))

    original = Controller.accept_plan

    def accept(self, snap, result, t):
        if veto is not None and veto[0] <= t < veto[1] and result.action.kind is ActionKind.QUESTION:
            result = without_questions(result)
        return original(self, snap, result, t)

    Controller.accept_plan = accept
    try:
        trial = run_trial(scene, task, "policy", seed, load_user(user).apply(cfg), user_name=user,
                          on_plan=on_plan)
    finally:
        Controller.accept_plan = original
    return trial, chosen


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scene", required=True)
    ap.add_argument("--task", action="append", required=True)
    ap.add_argument("--user", action="append", help="repeatable; default all the built-in users")
    ap.add_argument("--first-seed", type=int, default=300)
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--config")
    ap.add_argument("--window", type=float, help="s without questions from each question (planner.horizon_s)")
    ap.add_argument("--json", help="write the per-question records here")
    args = ap.parse_args()
    cfg = load_config(args.config)
    window = args.window if args.window is not None else cfg.planner.horizon_s
    scene = load_scene(args.scene)
    rows = []
    for task in args.task:
        for user in args.user or builtin_user_names():
            for seed in range(args.first_seed, args.first_seed + args.seeds):
                trial, chosen = run(scene, task, user, seed, cfg)
                for rec in trial.asked:
                    t_q = rec["t"]
                    _, m, mode, speed = next((c for c in chosen if abs(c[0] - t_q) < 1e-9),
                                             (t_q, math.nan, "", (math.nan, math.nan)))
                    alt, _ = run(scene, task, user, seed, cfg, veto=(t_q, t_q + window))
                    row = {"task": task, "user": user, "seed": seed, "t": t_q, "target": rec["target"],
                           "p_max": rec["p_max"], "object_rank": rec["object_rank"], "margin": m,
                           "mode": mode, "user_speed": list(speed),
                           "success": trial.success, "time_s": trial.completion_time_s,
                           "questions": trial.questions, "veto_success": alt.success,
                           "veto_time_s": alt.completion_time_s, "veto_questions": alt.questions}
                    rows.append(row)
                    print(f"{task:22} {user:18} {seed:4} t {t_q:5.1f} {rec['target']:24} p {rec['p_max']:.2f} {mode[:5]} "
                          f"v {speed[0]:.3f} m/s {speed[1]:.3f} rad/s "
                          f"margin {m:7.1f}  asked {trial.completion_time_s:5.1f} s ({trial.questions} q, "
                          f"{'ok' if trial.success else 'FAIL'})  vetoed {alt.completion_time_s:5.1f} s "
                          f"({alt.questions} q, {'ok' if alt.success else 'FAIL'})", flush=True)
    print("\n" + "\n".join(summary(rows)))
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"scene": args.scene, "tasks": args.task, "window_s": window, "config": args.config,
                       "questions": rows}, f, indent=1)


if __name__ == "__main__":
    main()
