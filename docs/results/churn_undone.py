"""Does the assistance undo, in the mode the user left, what they did in it? Switch by switch, on the trials
the yield to mode churn changed (session 51; ``blend.churn_window_s``, session 49).

    python docs/results/churn_undone.py OFF.json ON.json [OFF.json ON.json ...] [--method policy --method ho]
        [--jobs 2] [--json OUT]

Each pair is one evaluation recorded with the yield off and again with it on (``rerun_switching.py`` made
the ``-churn`` files from the ``-pose`` ones). The trials of the methods ``--method`` names (default the
policy and HO) whose time or success differ between the two are run again with the yield off (``ON``'s
recorded configuration, ``blend.churn_window_s = 0``) and every mode switch is scored. On entering mode
``M`` (translation or rotation) after time away from it:

* ``d``, the user's direction in ``M``: the sum of their twist's ``M`` part over their last visit to ``M``;
* ``s``, what the arm did in ``M`` while they were away: the commanded twist's ``M`` part integrated over
  the absence (m or rad; the user's input is in the other mode then, so this is the assistance's);
* the switch is *undone* when ``s . d / |d| < 0``: the assistance moved back against the way the user
  last drove in ``M``. A switch is not scored when the user gave no input on their last visit to ``M`` (or
  there was none).

The livelock session 49 described (the own-pose users switch out to fix one part of the pose while the
assistance undoes the other) should make many switches undone; the imprecise user's corrective glances
few. Prints, by user kind (the imprecise user against the own-pose users) and by what the yield did to the
trial (mended: a time-out became a success; faster; slower): the switches and the undone ones; then, for
each ``k``, in how many trials a churn rule would fire that asks, besides 6 switches within 10 s, at least
``k`` undone ones among them (``k = 0``: today's rule), and how much later than today's it fires (s). It
says how many of the reruns did not reproduce ``OFF``'s time (a trial recorded by older code, or a near tie
on another machine); those are scored as they now run.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections import defaultdict
from multiprocessing import Pool
from pathlib import Path

import numpy as np
from rerun import recorded_config

from sa_daemon.sim.episode import run_trial
from sa_daemon.sim.users import load_user
from sa_daemon.world.scene import load_scene

PART = {"translation": slice(0, 3), "rotation": slice(3, 6)}
WINDOW_S, SWITCHES = 10.0, 6  # the default churn rule's


def changed(off: Path, on: Path, methods: list[str]) -> list[dict]:
    """The trials of ``methods`` in ``on`` whose time or success differ from ``off``'s, each with what the
    yield did and ``off``'s time."""
    before = {(t["scene"], t["task"], t["user"], t["method"], t["seed"]): t for t in json.loads(off.read_text())["trials"]}
    out = []
    for t in json.loads(on.read_text())["trials"]:
        o = before[(t["scene"], t["task"], t["user"], t["method"], t["seed"])]
        if t["method"] not in methods or (o["completion_time_s"], o["success"]) == (t["completion_time_s"], t["success"]):
            continue
        kind = ("mended" if t["success"] and not o["success"] else "lost" if o["success"] and not t["success"]
                else "slower" if t["completion_time_s"] > o["completion_time_s"] else "faster")
        out.append({"src": str(on), "scene": t["scene"], "task": t["task"], "user": t["user"],
                    "method": t["method"], "seed": t["seed"], "kind": kind, "off_s": o["completion_time_s"]})
    return out


def switches(trial: dict, recorded: dict) -> tuple[float, list[tuple[float, float | None]]]:
    """The trial run again with the yield off, from its file's recorded configuration (``meta.config``):
    its completion time (s) and every mode switch as ``(t s, s . d / |d|)`` (module doc; ``None``: not
    scored)."""
    cfg = recorded_config(recorded)
    cfg = cfg.model_copy(update={"blend": cfg.blend.model_copy(update={"churn_window_s": 0.0})})
    profile = load_user(trial["user"])
    result = run_trial(load_scene(trial["scene"]), trial["task"], trial["method"], trial["seed"],
                       profile.apply(cfg), record=True, user_name=profile.name)
    tl, dt = result.timeline, 1.0 / cfg.eval.control_hz
    user, command = np.asarray(tl.user_twist), np.asarray(tl.command_twist)
    last_drive: dict[str, np.ndarray] = {}
    left_at: dict[str, int] = {}
    mode, drive, out = "translation", np.zeros(3), []
    for i, m in enumerate(tl.mode):
        if m != mode:
            last_drive[mode], left_at[mode] = drive, i
            d = last_drive.get(m)
            if d is None or not np.any(d):
                out.append((i * dt, None))
            else:
                away = command[left_at[m]:i, PART[m]].sum(axis=0) * dt
                out.append((i * dt, float(away @ d / np.linalg.norm(d))))
            mode, drive = m, np.zeros(3)
        drive = drive + user[i, PART[m]]
    return result.completion_time_s, out


def fires(events: list[tuple[float, float | None]], k: int) -> float | None:
    """When a rule asking 6 switches within 10 s with at least ``k`` undone among them first fires (s)."""
    times = [t for t, _ in events]
    for i in range(SWITCHES - 1, len(times)):
        if times[i] - times[i - SWITCHES + 1] <= WINDOW_S:
            undone = sum(s is not None and s < 0.0 for t, s in events if times[i] - WINDOW_S <= t <= times[i])
            if undone >= k:
                return times[i]
    return None


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("files", type=Path, nargs="+", help="OFF.json ON.json pairs")
    ap.add_argument("--method", action="append", help="the methods whose trials are scored (repeatable)")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--json", type=Path)
    args = ap.parse_args()
    if len(args.files) % 2:
        ap.error("files come in pairs: OFF.json ON.json")
    methods = args.method or ["policy", "ho"]
    trials = [t for off, on in zip(args.files[::2], args.files[1::2], strict=True) for t in changed(off, on, methods)]
    recorded = {str(on): json.loads(on.read_text())["meta"]["config"] for on in args.files[1::2]}  # once a file
    with Pool(args.jobs) as pool:
        scored = pool.starmap(switches, [(t, recorded[t["src"]]) for t in trials], chunksize=1)
    for t, (off_s, events) in zip(trials, scored, strict=True):
        t["rerun_off_s"], t["switches"] = off_s, events
    moved = sum(abs(t["rerun_off_s"] - t["off_s"]) > 1e-9 for t in trials)
    print(f"{len(trials)} trials the yield changed ({', '.join(methods)}); {moved} of their reruns with the yield off "
          "did not reproduce the recorded time\n")
    if args.json:  # meta.script: rerun.py leaves the file to this script
        args.json.write_text(json.dumps({"meta": {"script": "docs/results/churn_undone.py", "files": [str(f) for f in args.files],
                                                  "methods": methods}, "switches": trials}))
    groups: dict[tuple[str, str], list[dict]] = defaultdict(list)
    for t in trials:
        groups[("imprecise" if t["user"] == "imprecise" else t["user"], t["kind"])].append(t)
    print("| user | the yield | trials | switches | undone | " + " | ".join(
        f"fires, k = {k} (later s)" for k in range(4)) + " |\n|---|---|---|---|---|---|---|---|---|")
    for (user, kind), ts in sorted(groups.items()):
        n = sum(len(t["switches"]) for t in ts)
        undone = sum(s is not None and s < 0.0 for t in ts for _, s in t["switches"])
        cells = []
        for k in range(4):
            pairs = [(fires(t["switches"], 0), fires(t["switches"], k)) for t in ts]
            late = [b - a for a, b in pairs if a is not None and b is not None]
            cells.append(f"{sum(b is not None for _, b in pairs)} ({np.mean(late) if late else 0.0:.1f})")
        print(f"| {user} | {kind} | {len(ts)} | {n} | {undone} ({undone / max(n, 1):.2f}) | " + " | ".join(cells) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
