"""Markdown tables of a population suite's JSON (``sa-daemon eval --suite NAME --user ... --json FILE``), for
``docs/results.md``:

    python docs/results/report.py docs/results/suite-table1.json [...]

Per (scene, task): one table, a row per user and method, with the 95 % intervals of time and input and the
stars of policy's Holm-corrected paired difference from that method; then policy's ratios of time and
joystick input to HO and to manual per user with their Holm p-values, and the questions per task beside
the paper's where the suite has them; then, per task and baseline, how many users policy is significantly
faster or slower for, and needs significantly less or more input (Holm p < 0.05). Prints to stdout.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from sa_daemon.sim.evaluate import format_summary
from sa_daemon.sim.stats import bootstrap_ci, stars
from sa_daemon.sim.suites import SUITES


def _p(c: dict | None) -> str:
    if c is None or c["p_holm"] is None:
        return "-"
    return f"{c['p_holm']:.2g}{stars(c['p_holm'])}"


def _ratio(a: float | None, b: float | None) -> str:
    return "-" if a is None or b is None or b == 0 else f"{a / b:.2f}"


def report(path: Path) -> str:
    data = json.loads(path.read_text())
    meta, rows, comps = data["meta"], data["summary"], data.get("comparisons", [])
    s = SUITES.get(meta.get("suite") or "")
    out = [(f"Suite `{meta.get('suite')}`: {meta['seeds']} seeds per cell, users {', '.join(meta['users'])}, "
            f"{meta['arm']} arm; {len(data['trials'])} trials."), ""]
    comp = {(c["scene"], c["task"], c["user"], c["baseline"], c["metric"]): c for c in comps}
    for scene, task in dict.fromkeys((r["scene"], r["task"]) for r in rows):
        group = [r for r in rows if r["scene"] == scene and r["task"] == task]
        out += [f"#### {scene} `{task}`", "", format_summary(group, markdown=True, comparisons=comps, intervals=True),
                ""]
        methods = {r["method"] for r in group}
        head = ["user"]
        for base in ("ho", "manual"):
            if base in methods and "policy" in methods:
                head += [f"time / {base}", "p", f"input / {base}", "p"]
        head += ["questions"]
        if s is not None and s.paper_questions and task in s.paper_questions:
            head += ["paper"]
        lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
        for user in dict.fromkeys(r["user"] for r in group):
            by = {r["method"]: r for r in group if r["user"] == user}
            pol = by.get("policy")
            if pol is None:
                continue
            cells = [user]
            for base in ("ho", "manual"):
                if base in by:
                    b = by[base]
                    cells += [_ratio(pol["completion_time_s"], b["completion_time_s"]),
                              _p(comp.get((scene, task, user, base, "completion_time_s"))),
                              _ratio(pol["joystick_input"], b["joystick_input"]),
                              _p(comp.get((scene, task, user, base, "joystick_input")))]
            cells += [f"{pol['questions']:.2f}"]
            if s is not None and s.paper_questions and task in s.paper_questions:
                cells += [f"{s.paper_questions[task]:.2f}"]
            lines.append("| " + " | ".join(cells) + " |")
        out += lines + [""]
    out += verdicts(comps)
    out += asking(data["trials"])
    return "\n".join(out)


def verdicts(comps: list[dict], alpha: float = 0.05) -> list[str]:
    """Per (scene, task) and baseline: the users for whom policy is significantly faster / slower and needs
    significantly less / more joystick input (paired Wilcoxon, Holm per task and user, ``p < alpha``), of
    the users tested."""
    keys = dict.fromkeys((c["scene"], c["task"], c["baseline"]) for c in comps)
    if not keys:
        return []
    lines = [f"Policy against each baseline, users with Holm p < {alpha} (of the users tested):", "",
             "| scene | task | baseline | users | faster | slower | less input | more input |", "|" + "---|" * 8]
    for scene, task, base in keys:
        mine = [c for c in comps if (c["scene"], c["task"], c["baseline"]) == (scene, task, base)]
        cells = [scene, f"`{task}`", base, str(len({c["user"] for c in mine}))]
        for metric in ("completion_time_s", "joystick_input"):
            sig = [c for c in mine if c["metric"] == metric and c["p_holm"] is not None and c["p_holm"] < alpha]
            cells += [str(sum(c["median_diff"] < 0 for c in sig)), str(sum(c["median_diff"] > 0 for c in sig))]
        lines.append("| " + " | ".join(cells) + " |")
    return lines + [""]


def _mean(xs: list) -> str:
    xs = [x for x in xs if x is not None]
    return f"{sum(xs) / len(xs):.2f}" if xs else "-"


def _mean_ci(xs: list) -> str:
    """The mean with its 95 % percentile-bootstrap interval (``sim.stats.bootstrap_ci``)."""
    ci = bootstrap_ci(xs)
    return "-" if ci is None else f"{_mean(xs)} [{ci[0]:.2f}, {ci[1]:.2f}]"


def asking(trials: list[dict]) -> list[str]:
    """Issue 16's measures of policy's questions per user over the suite's tasks: questions a task (mean
    with its 95 % bootstrap interval, largest in one trial), share asked with the belief within 10 % of
    uniform, share about one of the two most likely objects, time of the first question, share of HO or
    no-assist plans in the first 2 s."""
    pol = [t for t in trials if t["method"] == "policy" and t.get("asked") is not None]
    if not pol:
        return []
    out = []
    for by in ("user", "task"):
        pooled = "all tasks" if by == "user" else "all users"
        out += [f"Policy's questions per {by} (issue 16's measures; {pooled} pooled):", ""]
        out += _asking_table(pol, by) + [""]
    return out


def _asking_table(pol: list[dict], by: str) -> list[str]:
    head = (f"| {by} | trials | questions a task | most in a trial | near uniform | about a top-2 object | "
            "about the likeliest target | first question (s) | early plans HO or none |")
    lines = [head, "|" + "---|" * 9]
    for key in dict.fromkeys(t[by] for t in pol):
        mine = [t for t in pol if t[by] == key]
        asked = [q for t in mine for q in t["asked"]]
        early = [t["early_plans"] for t in mine if t.get("early_plans")]
        passive = [sum(n for a, n in e.items() if a in ("ho", "none")) / max(1, sum(e.values())) for e in early]
        lines.append("| " + " | ".join([
            f"`{key}`" if by == "task" else key, str(len(mine)), _mean_ci([len(t["asked"]) for t in mine]), str(max(len(t["asked"]) for t in mine)),
            _mean([q["over_uniform"] < 1.1 for q in asked]), _mean([q["object_rank"] <= 2 for q in asked]),
            _mean([q["target_rank"] == 1 if "target_rank" in q else None for q in asked]),
            _mean([t["asked"][0]["t"] if t["asked"] else None for t in mine]), _mean(passive)]) + " |")
    return lines


if __name__ == "__main__":
    for f in sys.argv[1:]:
        print(report(Path(f)))
