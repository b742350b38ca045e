"""Score the belief tracker alone on manual trials: the mean log probability of the true target.

    python docs/results/tracker_score.py [--config FILE ...] [--seeds 2] [--jobs 2]

With no assistance (method ``manual``) the arm goes where the simulated user drives it whatever the belief,
so these trials measure the tracker without the planner. For every built-in user, every task of the suites
(``sa_daemon.sim.suites``) and every seed, the tracker's target probabilities are read at each plan instant
(0.1 s); the score is the mean of ``log p(true target)`` (a proper scoring rule: confident misreadings cost
most), with the share of instants where the true target is the most likely, the worst trial's mean, and the
share of trials that end with the true target above 0.7 (the correct prediction of the paper's metric). Each
``--config`` is scored in turn (``-`` is the built-in defaults), each after the first also paired with it
trial by trial (the mean difference of the trials' mean log p with a 95 % normal interval). ``docs/model.md`` ("The tracker") chose
``intent.rationality`` and ``intent.rotation_rationality`` with it.
"""

from __future__ import annotations

import argparse
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from sa_daemon.config import load_config
from sa_daemon.sim.episode import run_trial
from sa_daemon.sim.suites import SUITES
from sa_daemon.sim.users import builtin_user_names, load_user
from sa_daemon.world.scene import load_scene


def score_trial(job: tuple[str, str, str, str, int]) -> tuple[str, float, float, bool]:
    """``(task, mean log p(true target), share of instants the true target leads, correct prediction at the
    end)`` of one manual trial."""
    config, scene_name, task, user, seed = job
    cfg = load_user(user).apply(load_config(None if config == "-" else config))
    rows: list[tuple[float, bool]] = []

    def on_plan(_t, snap, _result) -> None:
        tp = snap.goals.target_probabilities(snap.probs)
        rows.append((float(np.log(max(tp[task], 1e-6))), max(tp, key=tp.get) == task))

    trial = run_trial(load_scene(scene_name), task, "manual", seed, cfg, on_plan=on_plan, user_name=user)
    logp, lead = np.array(rows).T
    return task, float(logp.mean()), float(lead.mean()), trial.correct_prediction


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", action="append", default=None, help="config.toml to score ('-': defaults)")
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--jobs", type=int, default=2)
    args = ap.parse_args()
    cells = sorted({(part.scene, task) for s in SUITES.values() for part in s.parts for task in part.tasks})
    first: np.ndarray | None = None
    for config in args.config or ["-"]:
        jobs = [(config, scene, task, user, seed) for scene, task in cells for user in builtin_user_names()
                for seed in range(args.seeds)]
        with ProcessPoolExecutor(args.jobs) as pool:
            res = list(pool.map(score_trial, jobs))
        logp = np.array([r[1] for r in res])
        print(f"{config}: {len(res)} manual trials; mean log p(true target) {logp.mean():.3f}, "
              f"true target leads {np.mean([r[2] for r in res]):.3f}, worst trial {logp.min():.2f}, "
              f"correct prediction at the end {np.mean([r[3] for r in res]):.3f}")
        print(f"    {'task':28s} {'log p':>7s} {'leads':>6s} {'pred':>5s}")
        for task in sorted({r[0] for r in res}):
            mine = [r for r in res if r[0] == task]
            print(f"    {task:28s} {np.mean([r[1] for r in mine]):7.3f} {np.mean([r[2] for r in mine]):6.3f}"
                  f" {np.mean([r[3] for r in mine]):5.2f}")
        if first is None:
            first = logp
        else:  # the same trials (users, tasks, seeds) in the same order: paired against the first config
            diff = logp - first
            half = 1.96 * diff.std(ddof=1) / np.sqrt(len(diff))
            print(f"    paired with {args.config[0]}: mean log p {diff.mean():+.3f} (95 % CI {diff.mean() - half:+.3f} "
                  f"to {diff.mean() + half:+.3f}); better in {np.sum(diff > 1e-9)}, worse in {np.sum(diff < -1e-9)} "
                  f"of {len(diff)} trials")


if __name__ == "__main__":
    main()
