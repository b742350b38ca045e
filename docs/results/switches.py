"""Compare evaluations of one method under different configs, user by user (issue 19's switches).

    python docs/results/switches.py [--method M] BASE.json LABEL=OTHER.json [LABEL=OTHER.json ...]

Each file is an ``sa-daemon eval --json`` of the same scene, tasks, users and seeds; ``--method`` picks one
method's trials from files that hold several (default: the files hold one). For every user, pooled
over the tasks: successes / trials, mean completion time of the successful trials, questions per task,
the share of time the user opposed the assistance, joystick input (successful trials) and the share of the
first 2 s's plans that chose HO or no assistance; then, for each other file, the same figures with the
change in completion time against the base (median of the paired differences over (task, seed) pairs
where both succeeded) and its paired Wilcoxon p-value, Holm-corrected across the users of that file,
and the change in successes. Markdown tables, one per file.
"""

from __future__ import annotations

import json
import sys
from collections import defaultdict

import numpy as np

from sa_daemon.sim.stats import holm, paired_wilcoxon, stars


def load(path: str, method: str | None = None) -> dict[str, dict[tuple[str, int], dict]]:
    """user -> (task, seed) -> trial, of ``method`` alone if given."""
    out: dict[str, dict[tuple[str, int], dict]] = defaultdict(dict)
    for t in json.load(open(path))["trials"]:  # noqa: SIM115
        if method is None or t["method"] == method:
            key = (t["task"], t["seed"])
            if key in out[t["user"]]:
                raise SystemExit(f"{path}: several trials of {t['user']} {key}: pick one method with --method")
            out[t["user"]][key] = t
    return out


def figures(trials: dict[tuple[str, int], dict]) -> tuple[int, int, float, float, float, float, float]:
    """Successes, trials, mean time (s), questions a task, opposing %, joystick input, early HO/none share."""
    ts = list(trials.values())
    ok = [t for t in ts if t["success"]]
    early = [sum(t["early_plans"].values()) for t in ts]
    passive = [t["early_plans"].get("ho", 0) + t["early_plans"].get("none", 0) for t in ts]
    return (len(ok), len(ts), float(np.mean([t["completion_time_s"] for t in ok])) if ok else float("nan"),
            float(np.mean([t["questions"] for t in ts])), float(np.mean([t["opposing_pct"] for t in ok])) if ok else 0.0,
            float(np.mean([t["joystick_input"] for t in ok])) if ok else float("nan"),
            sum(passive) / sum(early) if sum(early) else float("nan"))


def main(argv: list[str]) -> None:
    method = None
    if argv[:1] == ["--method"]:
        method, argv = argv[1], argv[2:]
    base = load(argv[0], method)
    users = list(base)
    print(f"base: {argv[0]}" + (f", method {method}" if method else "") + "\n")
    print("| user | success | time s | questions | opposing % | input | first 2 s HO/none |\n|---|---|---|---|---|---|---|")
    for u in users:
        s, n, t, q, o, j, e = figures(base[u])
        print(f"| {u} | {s}/{n} | {t:.2f} | {q:.2f} | {o:.1f} | {j:.0f} | {e:.2f} |")
    for arg in argv[1:]:
        label, path = arg.split("=", 1)
        other = load(path, method)
        rows, ps = [], []
        for u in users:
            keys = sorted(base[u].keys() & other[u].keys())
            a = [other[u][k]["completion_time_s"] if other[u][k]["success"] else None for k in keys]
            b = [base[u][k]["completion_time_s"] if base[u][k]["success"] else None for k in keys]
            test = paired_wilcoxon(a, b)
            ps.append(test.p_value)
            rows.append((u, figures(other[u]), figures(base[u]), test))
        print(f"\n{label}: {path}\n")
        print("| user | success (base) | time s (base) | change in time, median [p Holm] | questions (base) | "
              "opposing % | input (base) | first 2 s HO/none (base) |")
        print("|---|---|---|---|---|---|---|---|")
        for (u, (s, n, t, q, o, j, e), (sb, _, tb, qb, _, jb, eb), test), p in zip(rows, holm(ps), strict=True):
            change = f"{test.median_diff:+.2f} [{p:.2g}]{stars(p)}" if test.median_diff is not None and p is not None else "-"
            print(f"| {u} | {s}/{n} ({sb}) | {t:.2f} ({tb:.2f}) | {change} | {q:.2f} ({qb:.2f}) | {o:.1f} | "
                  f"{j:.0f} ({jb:.0f}) | {e:.2f} ({eb:.2f}) |")


if __name__ == "__main__":
    main(sys.argv[1:])
