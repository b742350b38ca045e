"""Compare evaluations of one method under different configs, user by user (issue 19's switches).

    python docs/results/switches.py BASE.json LABEL=OTHER.json [LABEL=OTHER.json ...]

Each file is an ``sa-daemon eval --json`` of the same scene, tasks, users and seeds. For every user, pooled
over the tasks: successes / trials, mean completion time of the successful trials, questions per task and
the share of time the user opposed the assistance; then, for each other file, the same figures with the
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


def load(path: str) -> dict[str, dict[tuple[str, int], dict]]:
    """user -> (task, seed) -> trial."""
    out: dict[str, dict[tuple[str, int], dict]] = defaultdict(dict)
    for t in json.load(open(path))["trials"]:  # noqa: SIM115
        out[t["user"]][(t["task"], t["seed"])] = t
    return out


def figures(trials: dict[tuple[str, int], dict]) -> tuple[int, int, float, float, float]:
    ts = list(trials.values())
    ok = [t for t in ts if t["success"]]
    return (len(ok), len(ts), float(np.mean([t["completion_time_s"] for t in ok])) if ok else float("nan"),
            float(np.mean([t["questions"] for t in ts])), float(np.mean([t["opposing_pct"] for t in ok])) if ok else 0.0)


def main(argv: list[str]) -> None:
    base = load(argv[0])
    users = list(base)
    print(f"base: {argv[0]}\n")
    print("| user | success | time s | questions | opposing % |\n|---|---|---|---|---|")
    for u in users:
        s, n, t, q, o = figures(base[u])
        print(f"| {u} | {s}/{n} | {t:.2f} | {q:.2f} | {o:.1f} |")
    for arg in argv[1:]:
        label, path = arg.split("=", 1)
        other = load(path)
        rows, ps = [], []
        for u in users:
            keys = sorted(base[u].keys() & other[u].keys())
            a = [other[u][k]["completion_time_s"] if other[u][k]["success"] else None for k in keys]
            b = [base[u][k]["completion_time_s"] if base[u][k]["success"] else None for k in keys]
            test = paired_wilcoxon(a, b)
            ps.append(test.p_value)
            rows.append((u, figures(other[u]), figures(base[u]), test))
        print(f"\n{label}: {path}\n")
        print("| user | success (base) | time s (base) | change in time, median [p Holm] | questions (base) | opposing % |")
        print("|---|---|---|---|---|---|")
        for (u, (s, n, t, q, o), (sb, _, tb, qb, _), test), p in zip(rows, holm(ps), strict=True):
            change = f"{test.median_diff:+.2f} [{p:.2g}]{stars(p)}" if test.median_diff is not None and p is not None else "-"
            print(f"| {u} | {s}/{n} ({sb}) | {t:.2f} ({tb:.2f}) | {change} | {q:.2f} ({qb:.2f}) | {o:.1f} |")


if __name__ == "__main__":
    main(sys.argv[1:])
