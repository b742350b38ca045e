"""Why the planner chose what it chose: one trial, plan by plan.

    python docs/results/trace.py --scene scene1 --task cup:top --user own-pose-off-list --seed 213 \\
        [--config FILE] [--method policy] [--from 9.5] [--to 18.5] [--at 12.2 ...]

Runs the trial as ``sa-daemon eval`` does (kinematic arm, ``eval.node_budget``) and prints, for every plan
between ``--from`` and ``--to`` (s), the action chosen, the root values of the best six actions and the
three most likely targets. For each ``--at`` time (the first plan at or after it) it opens the watch
model's search (``planner/watch.py``): for every branch goal ``g`` (the goals the search weighs, with
their belief) the return of committing to each action if the person wants ``g``, the value of each
watched motion, and the return of standing still for a question. A goal held as several copies (its
grasp poses split by resampling) shows once per copy: the search tells them apart, a question cannot.
Reads the search's internals; a diagnostic, not an interface. ``docs/results.md`` ("Where the policy
loses, traced") used it.
"""

from __future__ import annotations

import argparse

from sa_daemon.config import load_config
from sa_daemon.model.model import SharedAutonomyModel
from sa_daemon.planner.watch import WatchSearch
from sa_daemon.sim.episode import run_trial
from sa_daemon.sim.users import load_user
from sa_daemon.world.scene import load_scene


def name(action) -> str:
    """An action's label, with the goal copy a move drives to (``#i``, its index in the goal set)."""
    return action.label if action.goal is None else f"{action.label}#{action.goal}"


def search_parts(model: SharedAutonomyModel, snap) -> dict:
    """The watch search at ``snap`` taken apart (no deadline, no node budget): ``branches`` (goal index,
    belief), ``commit`` {action: (expected return, per-branch returns)}, ``watch`` {action: value},
    ``stay`` (a question's standing still, per branch) and ``complete``. ``plan_watch`` gives an action
    the better of its commit and watch values."""
    ws = WatchSearch(model, snap)
    R = ws.root_rollouts()
    g = ws.branches
    commit = {a: (float(ws.b0 @ R.value[0, :, j, ws.n]), R.value[0, g, j, ws.n].copy())
              for j, a in enumerate(ws.moves)}
    stay = R.stay[0, g] * ws.n_q
    _, watched, complete = ws.run()
    return {"branches": [(int(i), float(ws.b0[i])) for i in g], "commit": commit, "watch": watched,
            "stay": stay, "complete": complete}


def decompose(model: SharedAutonomyModel, snap) -> list[str]:
    """:func:`search_parts` as lines."""
    parts = search_parts(model, snap)
    goals = snap.goals.goals
    out = ["  branch goals: " + ", ".join(f"{goals[i].target}#{i} {p:.3f}" for i, p in parts["branches"])]
    for a, (value, per) in parts["commit"].items():
        out.append(f"  commit {name(a):22} {value:8.1f} | per goal " + " ".join(f"{v:8.1f}" for v in per))
    for a, v in parts["watch"].items():
        out.append(f"  watch  {name(a):22} {v:8.1f}")
    if not parts["complete"]:
        out.append("  (the watched motions were not all searched)")
    out.append("  a question's standing still     | per goal " + " ".join(f"{v:8.1f}" for v in parts["stay"]))
    return out


def trace(scene: str, task: str, user: str, seed: int, config: str | None = None, method: str = "policy",
          start: float = 0.0, stop: float = float("inf"), at: tuple[float, ...] = ()) -> tuple[list[str], object]:
    """The printed lines and the trial's result."""
    cfg = load_user(user).apply(load_config(config))
    if at and cfg.planner.model != "watch":
        raise SystemExit("--at opens the watch model's search; this configuration plans with "
                         f"planner.model = {cfg.planner.model!r}")
    lines: list[str] = []
    due = sorted(at)
    model = SharedAutonomyModel(cfg)  # the planner's model, as the Controller builds it

    def on_plan(t: float, snap, result) -> None:
        if start - 1e-9 <= t <= stop + 1e-9:
            ranked = sorted(result.root_values.items(), key=lambda kv: -kv[1])[:6]
            tp = snap.goals.target_probabilities(snap.probs)
            top = sorted(tp.items(), key=lambda kv: -kv[1])[:3]
            lines.append(f"t={t:6.2f} {name(result.action):22} "
                         + " ".join(f"{name(a)}={v:.1f}" for a, v in ranked)
                         + " | " + " ".join(f"{k}={p:.2f}" for k, p in top))
        while due and t >= due[0] - 1e-9:
            due.pop(0)
            lines.append(f"search at t={t:.2f} (chose {name(result.action)}):")
            lines.extend(decompose(model, snap))

    result = run_trial(load_scene(scene), task, method, seed, cfg, on_plan=on_plan, user_name=user)
    lines.append(f"{'success' if result.success else 'failure: ' + result.failure} at {result.completion_time_s:.2f} s, "
                 f"{result.questions} question(s)")
    return lines, result


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", required=True)
    ap.add_argument("--task", required=True)
    ap.add_argument("--user", default="calibrated")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--config", default=None, help="config.toml (default: built-in defaults)")
    ap.add_argument("--method", default="policy")
    ap.add_argument("--from", dest="start", type=float, default=0.0, help="first plan printed (s)")
    ap.add_argument("--to", dest="stop", type=float, default=float("inf"), help="last plan printed (s)")
    ap.add_argument("--at", type=float, action="append", default=[], help="open the search here (s); repeatable")
    a = ap.parse_args()
    lines, _ = trace(a.scene, a.task, a.user, a.seed, a.config, a.method, a.start, a.stop, tuple(a.at))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
