"""What the low-level target costs: the same trials with the user's own grasp pose known to the controller.

    python docs/results/pose_known.py --scene scene1 --task cup:top --user own-pose --user own-pose-off-list \\
        [--method policy --method ho] [--first-seed 300] [--seeds 10] [--jobs 2] [--json OUT]

Runs every (task, user, method, seed) twice as ``sa-daemon eval`` does (kinematic arm, the built-in
defaults): as recorded, and with ``run_trial(..., pose_known=True)``, where the controller's goal for the
task holds the pose the simulated user wants and no other (an oracle: the paper's "uncertainty over the
user's desired grasp pose (low-level target)", section IV-A, removed; the same seed draws the same user).
Prints, per (task, user), the mean time of the trials both methods finished and the median paired
difference policy - HO, listed and known. An upper bound on what inferring the grasp pose could buy,
and a test of whether a method's lead over another is about it. ``docs/results.md`` ("Session 42") used it.
"""

from __future__ import annotations

import argparse
import json
import statistics
from collections import defaultdict
from concurrent.futures import ProcessPoolExecutor

from sa_daemon.config import load_config
from sa_daemon.sim.episode import run_trial
from sa_daemon.sim.users import load_user
from sa_daemon.world.scene import load_scene

Job = tuple[str, str, str, str, int, bool]
"""(scene, task, user, method, seed, pose known)."""


def trial(job: Job) -> dict:
    """One trial's record (as ``sa-daemon eval`` writes it) with ``pose_known`` added."""
    scene, task, user, method, seed, known = job
    cfg = load_user(user).apply(load_config(None))
    r = run_trial(load_scene(scene), task, method, seed, cfg, user_name=user, pose_known=known)
    return {**r.metrics(), "pose_known": known}


def paired(trials: list[dict], known: bool) -> dict[tuple[str, str], tuple[float, float, float, int]]:
    """Per (task, user): the policy's and HO's mean time over the seeds both finished, the median of the
    paired differences policy - HO (s), and how many pairs."""
    by: dict[tuple, dict[str, dict]] = defaultdict(dict)
    for t in trials:
        if t["pose_known"] == known:
            by[(t["task"], t["user"], t["seed"])][t["method"]] = t
    cells: dict[tuple[str, str], list[tuple[float, float]]] = defaultdict(list)
    for (task, user, _), m in by.items():
        if "policy" in m and "ho" in m and m["policy"]["success"] and m["ho"]["success"]:
            cells[(task, user)].append((m["policy"]["completion_time_s"], m["ho"]["completion_time_s"]))
    return {k: (statistics.mean(p for p, _ in v), statistics.mean(h for _, h in v),
                statistics.median(p - h for p, h in v), len(v)) for k, v in sorted(cells.items())}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scene", required=True)
    ap.add_argument("--task", action="append", required=True)
    ap.add_argument("--user", action="append", required=True)
    ap.add_argument("--method", action="append", default=None)
    ap.add_argument("--first-seed", type=int, default=300)
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--json", default=None, help="write every trial here")
    a = ap.parse_args()
    methods = a.method or ["policy", "ho"]
    jobs = [(a.scene, task, user, method, a.first_seed + s, known) for known in (False, True) for task in a.task
            for user in a.user for method in methods for s in range(a.seeds)]
    with ProcessPoolExecutor(a.jobs) as pool:
        trials = list(pool.map(trial, jobs))
    if a.json:
        with open(a.json, "w") as f:
            json.dump({"meta": {"script": "docs/results/pose_known.py", "scene": a.scene, "tasks": a.task,
                                "users": a.user, "methods": methods, "first_seed": a.first_seed,
                                "seeds": a.seeds, "config": "built-in defaults"}, "trials": trials}, f)
    listed, known = paired(trials, False), paired(trials, True)
    print("task         user               pairs  listed: policy   HO  median p-HO | known: policy   HO  median p-HO")
    for k in sorted(listed.keys() | known.keys()):
        row = [f"{k[0]:12} {k[1]:18}"]
        for cells in (listed, known):
            c = cells.get(k)
            row.append("   -" if c is None else f"{c[3]:5}  {c[0]:12.1f} {c[1]:5.1f} {c[2]:+8.2f}")
        print(" ".join(row))


if __name__ == "__main__":
    main()
