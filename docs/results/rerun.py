"""Re-run every evaluation recorded in ``docs/results/*.json`` from its own ``meta`` (scene, tasks, methods,
seeds, arm, configuration) with the current code, and print each summary row old -> new.

    python docs/results/rerun.py [--jobs 2] [--write] [FILE ...]

Without ``--write`` nothing is changed: the old and new summaries are only compared. With it, each file is
rewritten (trials, summary, and ``meta.config`` as the current code spells it). Files that are not
evaluations (bench figures) and files a results script wrote (``meta.script``) are skipped.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from sa_daemon.config import Config, config_from_dict
from sa_daemon.sim.evaluate import (
    TrialSpec,
    compare,
    run_trials,
    summarise,
    write_results,
)

HERE = Path(__file__).resolve().parent
KEYS = ("success_rate", "completion_time_s", "mode_changes", "joystick_input", "opposing_pct",
        "correct_prediction_rate", "questions")


BEFORE_THE_KEY = {
    "planner": {"model": "commit", "ho_belief": "fixed", "watch_evidence": 1.0, "rank_goals": "goal",
                "user_speed_unused": "zero"},
    "intent": {"step_cost": "time", "rationality": 1.0, "poses": "nearest", "turn_charge": 0.0,
               "copy_weights": "equal", "reach_pose": "closest", "keep_pose_posterior": False},
    "ho": {"generator": "gradient"},
    "reward": {"question_time_s": 0.0},
    "limits": {"tcp_mps": 1.0},
    "asking": {"withdraw_no_s": 0.0, "withdraw_yes_s": 0.0, "learn_answer_time": False},
    "blend": {"churn_window_s": 0.0, "churn_counts": "switches"},
}
"""Keys whose default changed after files were recorded without them: a file that lacks one ran with the
behaviour it had before the key existed (session 9 made the watch model, the path step cost and the
move-generator HO the defaults, and a question's time 2.5 s; session 10 HO following the tracked belief
in the rollouts, and a TCP speed limit of 0.25 m/s where there was none: 1 m/s never binds). A file without
``intent.rotation_rationality`` (session 14) weighed rotation input with its ``intent.rationality``; one
without ``intent.poses`` (session 18) read a goal's input against its lowest-value pose alone; one without
``intent.turn_charge`` (session 22) charged a turn nothing; one without ``asking.withdraw_no_s`` (session 28)
held every "no" final; one without ``planner.watch_evidence`` (session 31) credited a watch with all
of the predicted input's evidence; one without ``asking.withdraw_yes_s`` held every "yes" final (the key
existed since session 27, off; files recorded before it lack it, and it became 2 s in session 33); one
without ``planner.rank_goals`` (session 32) ranked the top goals by their own probability (``"goal"``;
``"cover"`` since session 33); one without ``intent.copy_weights`` (session 19) gave a target's copies
equal shares, and one without ``planner.user_speed_unused`` (session 35) predicted a mode not yet entered
still (``"poses"`` and ``"deflection"`` since session 37); one without ``asking.learn_answer_time``
(session 39) charged every question ``reward.question_time_s``; one without ``intent.reach_pose`` (session
25) drove the moves to ``k_c`` (``"tracked_moves"`` since session 43), one without ``blend.churn_window_s``
(session 49) never yielded to a user who keeps switching mode, and one without
``intent.keep_pose_posterior`` (session 42) started each copy's pose weights afresh (kept since session 43). The ``-turn-charge`` files (session 22) measured
the charge where the gripper was; since session 23 it is measured where the user last translated, so they
rerun with that measure (the ``-turn-anchor`` files')."""


def recorded_config(recorded: dict) -> Config:
    """The recorded configuration, keeping only the keys the current code knows. Keys the file lacks take
    their value from before they existed (``BEFORE_THE_KEY``), or else their defaults (a removed key
    cannot have changed the trials of the current code)."""
    recorded = {**recorded}
    for section, keys in BEFORE_THE_KEY.items():
        recorded[section] = {**keys, **recorded.get(section, {})}
    # one beta for both parts of the tracker's evidence before session 14 split out the rotation part's
    recorded["intent"].setdefault("rotation_rationality", recorded["intent"]["rationality"])
    # session 22 moved the user's stand-off from the planner's section to the user model's
    if "user_standoff_m" in recorded.get("planner", {}):
        recorded["intent"].setdefault("user_standoff_m", recorded["planner"]["user_standoff_m"])
    # before session 19 the watch model rounded its times to whole rollout steps itself (Python's round, at
    # least one step: a question's 2.5 s ran as 2 s); the configuration now refuses a time off that grid
    if recorded["planner"].get("model") == "watch":
        dt = recorded["planner"].get("rollout_step_s", Config().planner.rollout_step_s)
        for section, key in (("planner", "horizon_s"), ("planner", "watch_s"), ("reward", "question_time_s")):
            if key in recorded.get(section, {}):
                recorded[section] = {**recorded[section], key: max(1, round(recorded[section][key] / dt)) * dt}
    current = Config().model_dump(mode="json")

    def keep(rec: dict, cur: dict) -> dict:
        return {k: (keep(v, cur[k]) if isinstance(v, dict) and isinstance(cur.get(k), dict) else v)
                for k, v in rec.items() if k in cur}

    return config_from_dict(keep(recorded, current), "recorded meta.config")


def _fmt(row: dict | None) -> str:
    if row is None:
        return "-"
    return " ".join("-" if row.get(k) is None else f"{row[k]:.2f}" for k in KEYS)


def rerun(path: Path, jobs: int, write: bool) -> None:
    data = json.loads(path.read_text())
    meta = data.get("meta", {})
    if "script" in meta:  # written by a results script, not by sa-daemon eval: that script runs it again
        return
    parts = meta.get("parts") or ([{"scene": meta["scene"], "tasks": meta["tasks"], "methods": meta["methods"]}]
                                  if "tasks" in meta and "methods" in meta else [])
    if not parts:
        return
    cfg = recorded_config(meta["config"])
    users = meta.get("users") or ["calibrated"]
    # The seeds the file holds (runs with --first-seed start elsewhere than 0), else the first meta["seeds"].
    seeds = sorted({t["seed"] for t in data.get("trials", [])}) or range(meta["seeds"])
    specs = [TrialSpec(p["scene"], task, method, seed, user) for p in parts for task in p["tasks"] for user in users
             for method in p["methods"] for seed in seeds]
    trials = run_trials(specs, cfg, jobs=jobs, progress=False, arm=meta.get("arm", "kinematic"))
    summary = summarise(trials)
    comparisons = compare(trials)

    def key(r: dict) -> tuple:
        return r.get("scene"), r["task"], r.get("user", "calibrated"), r["method"]

    old = {key(r): r for r in data["summary"]}
    print(f"\n{path.name} ({meta.get('arm', 'kinematic')}): {' '.join(KEYS)}")
    for r in summary:
        o = old.get(key(r)) or old.get((None, r["task"], "calibrated", r["method"]))
        same = o is not None and all(o.get(k) == r[k] for k in KEYS)
        print(f"  {r['task']:<24} {r['user']:<18} {r['method']:<24} {'=' if same else '*'} {_fmt(o)}  ->  {_fmt(r)}")
    if write:
        write_results(path, trials, summary, {**meta, "config": cfg.model_dump(mode="json")}, comparisons)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("files", nargs="*", type=Path)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--write", action="store_true", help="rewrite the files with the new trials")
    args = ap.parse_args()
    for f in args.files or sorted(HERE.glob("*.json")):
        rerun(f, args.jobs, args.write)
    return 0


if __name__ == "__main__":
    sys.exit(main())
