"""How much of the evidence the watch model predicts does a user's input give?

    python docs/results/evidence.py [--user U ...] [--first-seed 300] [--seeds 5] [--config FILE] [--json OUT]
                                    [--scene S --task T ...]

The watch search (``planner/watch.py``) predicts, for a user heading to goal ``g``, the joystick input of
the next ``planner.watch_s`` and the belief the tracker will reach reading it. This runs policy trials as
``sa-daemon eval`` does (Table I's ``cup:top`` and the simple study's three tasks, or ``--scene``'s
``--task`` tasks; kinematic arm) and, at
every plan that is not a question and is followed by no question for ``watch_s``, compares two changes of
the log-odds of the user's true target ``T`` against every other target ``t`` (both above 1e-3):

    predicted[t] = log(P'(T) / P'(t)) - log(P(T) / P(t))    P' the watch's belief for branch T under the
                                                            chosen motion (copies of T weighted by belief)
    realised[t]  = log(P1(T) / P1(t)) - log(P(T) / P(t))    P1 the tracker's belief watch_s later

and reports per user the least-squares slope through the origin, ``lambda = sum(realised * predicted) /
sum(predicted^2)``: 1 means the input tells the targets apart as fast as the watch expects, 0.5 half as
fast. The prediction is the whole evidence (``lambda = 1``) whatever the configuration says:
``planner.watch_evidence`` is the share the model takes of it (docs/model.md, session 31), and this
measures what that share should be. The trials run with the configuration given (the policy's choices
depend on it). A diagnostic, not an interface: it reads the search's internals.
"""

from __future__ import annotations

import argparse
import json

import numpy as np

from sa_daemon.config import Config, load_config
from sa_daemon.model.actions import ActionKind
from sa_daemon.model.model import SharedAutonomyModel
from sa_daemon.planner.watch import WatchSearch
from sa_daemon.planner.watched_beliefs import watched_beliefs
from sa_daemon.sim.episode import run_trial
from sa_daemon.sim.users import builtin_user_names, load_user
from sa_daemon.world.scene import load_scene

TASKS = (("scene1", "cup:top"),) + tuple(("study-simple", t) for t in ("bottle:side", "spoon:top", "cup:top"))
"""Table I's task and the simple study's three."""


def _target_masses(goals, probs: np.ndarray, targets: tuple[str, ...]) -> np.ndarray:
    """Each of ``targets``' probability under ``goals``' belief ``probs`` (by name: resampling may reorder
    the copies), floored at 1e-6 for the log-odds."""
    by_name = goals.target_probabilities(probs)
    return np.maximum([by_name.get(t, 0.0) for t in targets], 1e-6)


def windows(cfg: Config, scene: str, task: str, seed: int, user: str) -> list[tuple[float, float, str, str]]:
    """One policy trial's windows: ``(sum realised * predicted, sum predicted^2, motion kind, joystick
    mode)`` each."""
    model = SharedAutonomyModel(cfg)
    plans: list = []
    run_trial(load_scene(scene), task, "policy", seed, cfg, user_name=user,
              on_plan=lambda t, snap, result: plans.append((t, snap, result)))
    times = np.array([p[0] for p in plans])
    asked = np.array([p[2].action.kind is ActionKind.QUESTION for p in plans])
    out = []
    for i, (t, snap, result) in enumerate(plans):
        j = int(np.searchsorted(times, t + cfg.planner.watch_s - 1e-6))
        if j >= len(plans) or abs(times[j] - t - cfg.planner.watch_s) > 0.5 * cfg.planner.period_s or asked[i:j + 1].any():
            continue
        goals = snap.goals
        T = goals.targets.index(task)
        P0 = _target_masses(goals, snap.probs, goals.targets)
        others = (P0 > 1e-3) & (np.arange(len(P0)) != T)
        if not (1e-3 < P0[T] < 0.999 and others.any()):
            continue
        search = WatchSearch(model, snap)
        if not search.watched:
            raise SystemExit("this configuration watches no motion (planner.watch_levels = 0): nothing to measure")
        copies = [g for g in search.branches if goals.target_index[g] == T]
        if result.action not in search.moves or not copies:
            continue
        a = search.moves.index(result.action)
        R = search.root_rollouts()
        w = search.b0[copies] / search.b0[copies].sum()
        child = watched_beliefs(search.b0, R.loglik[0, copies, a], goals.target_index)  # all of it: lambda = 1
        predicted = sum(wk * (np.log(P[T] / P) - np.log(P0[T] / P0))
                        for wk, P in zip(w, (_target_masses(goals, c, goals.targets) for c in child)))
        P1 = _target_masses(plans[j][1].goals, plans[j][1].probs, goals.targets)
        realised = np.log(P1[T] / P1) - np.log(P0[T] / P0)
        out.append((float(predicted[others] @ realised[others]), float(predicted[others] @ predicted[others]),
                    result.action.kind.value, snap.mode.value))
    return out


def measure(user: str, seeds: range, config: str | None = None,
            tasks: tuple[tuple[str, str], ...] = TASKS) -> dict:
    """``lambda`` for one user over ``tasks`` (``(scene, task)`` pairs) x ``seeds``, in all, by the motion
    chosen and by the joystick mode of the window's start (translation, rotation)."""
    cfg = load_user(user).apply(load_config(config))
    rows = [w for scene, task in tasks for s in seeds for w in windows(cfg, scene, task, s, user)]
    out = {"windows": len(rows), "realised_x_predicted": sum(r[0] for r in rows),
           "predicted_sq": sum(r[1] for r in rows)}
    out["lambda"] = out["realised_x_predicted"] / max(out["predicted_sq"], 1e-12)
    for kind in ("move", "ho", "none"):
        sel = [r for r in rows if r[2] == kind]
        out[kind] = {"windows": len(sel), "lambda": sum(r[0] for r in sel) / max(sum(r[1] for r in sel), 1e-12)}
    for mode in ("translation", "rotation"):
        sel = [r for r in rows if r[3] == mode]
        out[mode] = {"windows": len(sel), "realised_x_predicted": sum(r[0] for r in sel),
                     "predicted_sq": sum(r[1] for r in sel)}
        out[mode]["lambda"] = out[mode]["realised_x_predicted"] / max(out[mode]["predicted_sq"], 1e-12)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--user", action="append", default=[], help="repeatable; default all the built-in users")
    ap.add_argument("--first-seed", type=int, default=300)
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--config", default=None)
    ap.add_argument("--json", default=None)
    ap.add_argument("--scene", help="measure this scene's --task tasks instead of Table I's and the simple study's")
    ap.add_argument("--task", action="append", default=[], help="with --scene; repeatable")
    a = ap.parse_args()
    if bool(a.scene) != bool(a.task):
        ap.error("--scene and --task go together")
    tasks = tuple((a.scene, t) for t in a.task) or TASKS
    seeds = range(a.first_seed, a.first_seed + a.seeds)
    result = {}
    print(f"{'user':18} {'windows':>7} {'lambda':>7} {'move':>6} {'ho':>6} {'none':>6} {'transl.':>14} {'rotation':>14}")
    for user in a.user or builtin_user_names():
        m = result[user] = measure(user, seeds, a.config, tasks)
        by_mode = " ".join(f"{m[k]['lambda']:6.2f} ({m[k]['windows']:4d})" for k in ("translation", "rotation"))
        print(f"{user:18} {m['windows']:7d} {m['lambda']:7.2f} {m['move']['lambda']:6.2f} {m['ho']['lambda']:6.2f} "
              f"{m['none']['lambda']:6.2f} {by_mode}", flush=True)
    pooled = []
    for k in (None, "translation", "rotation"):
        ms = [m if k is None else m[k] for m in result.values()]
        num, den = sum(m["realised_x_predicted"] for m in ms), sum(m["predicted_sq"] for m in ms)
        pooled.append((sum(m["windows"] for m in ms), num / max(den, 1e-12)))
    print(f"{'pooled':18} {pooled[0][0]:7d} {pooled[0][1]:7.2f} {'':20} "
          + " ".join(f"{lam:6.2f} ({n:4d})" for n, lam in pooled[1:]))
    if a.json:
        with open(a.json, "w") as f:
            json.dump({"seeds": [seeds.start, seeds.stop], "tasks": [list(t) for t in tasks], "users": result}, f,
                      indent=1)


if __name__ == "__main__":
    main()
