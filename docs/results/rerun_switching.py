"""A recorded evaluation again with the robot yielding to mode churn (``blend.churn_window_s``, session 49),
exactly, rerunning only the trials it can change.

    python docs/results/rerun_switching.py SRC.json DST.json [--window 10] [--switches 6]
        [--counts switches|driven] [--jobs 2]

The robot yields only once the user has switched joystick mode ``churn_switches`` times within
``churn_window_s``; a trial whose user switched fewer times than that in all (its ``mode_changes``) never
yields (nor does it when only changes of the mode driven in count, ``--counts driven``, which are fewer),
so with the key on it runs as recorded, bit for bit (``tests/test_future_work.py`` pins that a
trial without churn is unchanged). This script reruns the other trials of ``SRC`` (every method but
``manual``, which never assists) with ``SRC``'s recorded configuration and the key set, keeps the rest, and
writes ``DST`` with the summary and the paired tests recomputed. ``meta.rerun_switching`` names the trials
rerun.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from rerun import recorded_config

from sa_daemon.sim.evaluate import (
    TrialSpec,
    compare,
    run_trials,
    summarise,
    write_results,
)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("src", type=Path)
    ap.add_argument("dst", type=Path)
    ap.add_argument("--window", type=float, default=10.0, help="blend.churn_window_s (s)")
    ap.add_argument("--switches", type=int, default=6, help="blend.churn_switches")
    ap.add_argument("--counts", choices=("switches", "driven"), default="switches", help="blend.churn_counts")
    ap.add_argument("--jobs", type=int, default=2)
    args = ap.parse_args()
    data = json.loads(args.src.read_text())
    meta = data["meta"]
    cfg = recorded_config(meta["config"])
    cfg = cfg.model_copy(update={"blend": cfg.blend.model_copy(
        update={"churn_window_s": args.window, "churn_switches": args.switches, "churn_counts": args.counts})})
    trials = data["trials"]
    redo = [i for i, t in enumerate(trials) if t["method"] != "manual" and t["mode_changes"] >= args.switches]
    specs = [TrialSpec(trials[i]["scene"], trials[i]["task"], trials[i]["method"], trials[i]["seed"],
                       trials[i]["user"]) for i in redo]
    new = run_trials(specs, cfg, jobs=args.jobs, progress=False, arm=meta.get("arm", "kinematic"))
    for i, record in zip(redo, new, strict=True):
        trials[i] = record
    rerun = [[t["scene"], t["task"], t["user"], t["method"], t["seed"]] for t in (trials[i] for i in redo)]
    meta = {**meta, "config": cfg.model_dump(mode="json"), "rerun_switching": {"from": args.src.name, "trials": rerun}}
    write_results(args.dst, trials, summarise(trials), meta, compare(trials))
    print(f"{args.dst}: {len(redo)} of {len(trials)} trials rerun", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
