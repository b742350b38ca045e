"""Session 19's rule for adopting a model or tracker option as the default, checked on suite files.

    python docs/results/adopt.py TAG [--dir DIR] [--default marginal] [--default-dir DIR] [--rule s19|s28|...|s39b]

reads ``DIR/suite-{table1,study-simple,fig7}-TAG.json`` (the option's runs, ``DIR`` defaults to this folder)
and ``DEFAULT_DIR/suite-{...}-marginal.json`` (the default's, this folder unless told), paired by (scene,
task, method, user), and prints the verdict of the rule written down before session 19's run
(``docs/model.md``, "A goal's grasps read together"): adopt if, on Table I, the simple study and Fig. 7,
HO and policy,

(a) the policy's correct prediction rises on Scene 2 and falls below 0.9 on no task that was at or above it;
(b) no (task, method) loses more than 2 successes;
(c) for each method, the (task, user) cells whose mean completion time (s, successful trials) rises by more
    than 5 % are no more than those whose mean time falls by more than 5 %.

``--rule s28`` is session 28's rule for options that leave the tracker as it is (``docs/model.md``, "A
confirmatory run on fresh seeds"): (b) and (c) as above, and in place of (a)

(a') on every task the policy's end-of-trial log p(true target) is shown not to be lower by more than 0.1
     (a non-inferiority test): the paired mean difference (option minus default, same user and seed, p
     floored at 1e-6) has the lower end of its 95 % interval (mean - 1.96 standard errors) above -0.1.

``--rule s28b`` is the same with (a') replaced, after (a') proved unpassable at 80 trials a task:

(a'') on no task has the policy fewer correct predictions (the paper's measure) than the default by an
      exact one-sided McNemar test at p < 0.05 (pairs: same user and seed), no correction for the tasks.

``--rule s29`` is s28b with (b) replaced, after (b) rejected a candidate on noise (``docs/model.md``, "Session
29's form"):

(b') no (task, method) has fewer successes than the default by an exact one-sided McNemar test at p < 0.05
     (pairs: same user and seed), and neither have all the (task, method) pairs of the three suites pooled.

``--rule s32`` is s29 with (c) replaced, written in session 32 before any run of the candidate it is for
(``asking.withdraw_yes_s``, whose gain is trials that no longer time out; ``docs/results.md``, "Session 32:
the default on fresh seeds"): (c) compared a cell's mean time over its successful trials, so a mended
time-out (a new, slow success) counted as slower and a new failure could count as faster:

(c'') for each method, the (task, user) cells whose mean completion time over the seeds both
      configurations succeed on (same user and seed) rises by more than 5 % are no more than those whose
      paired mean time falls by more than 5 %.

``--rule s37`` is s32 with (a'') replaced, written in session 37 for candidates whose gain is issue 16's
targets (``docs/results.md``, "Session 37"); the manual runs on the same seeds (``--manual TAG``) join
both sides' files:

(t) ``targets.py`` on the option's files (the 22-goal suite's included) meets more of issue 16's target
    rows than on the default's: a correct prediction lost below 0.9 on a task is a row lost, weighed with
    the rest, not a veto.

``--rule s39`` is s32 with (h) added, written in session 39 for ``asking.learn_answer_time``, a candidate
that changes only the trials of a person whose answers are not within a rollout step of the charged time
(of the simulated users the hesitant one; ``docs/results.md``, "Session 39"), judged on that person's
policy trials alone:

(h) over the rule suites' policy trials paired by (scene, task, user, seed) that both configurations
    succeed on, the option is faster: the median of the paired time differences below zero and the
    two-sided Wilcoxon signed-rank p-value (``sim.stats.paired_wilcoxon``) below 0.05.

``--rule s39b`` is s39 with (h) replaced, written after s39 turned the candidate down on its first run
for a flaw of its own: the unchanged trials (zero differences, most of them) put the median at zero
whatever the changed ones did, though the Wilcoxon test discards them (``docs/results.md``, "Session 39"):

(h') the mean of the paired time differences below zero (the changed trials' sum: an unchanged trial adds
     nothing) and the two-sided Wilcoxon signed-rank p-value below 0.05.

Also printed, for every suite present (the 22-goal one included, which the rule does not count): successes,
mean time, the policy's prediction and questions per task, old -> new, and the policy-against-HO verdicts.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

from report import verdicts
from targets import load_trials, report

from sa_daemon.sim.evaluate import summarise, trial_key
from sa_daemon.sim.stats import paired_wilcoxon

HERE = Path(__file__).resolve().parent
RULE_SUITES = ("table1", "study-simple", "fig7")
ALL_SUITES = (*RULE_SUITES, "study-complex")
MAX_LOST = 2          # (b): successes a (task, method) may lose
P_FLOOR = 1e-6        # (a'): the floor of p(true target) before its log
Z95 = 1.96            # (a'): the normal interval's half-width in standard errors
MARGIN = 0.1          # (a'): the non-inferiority margin of the mean log p (nats)
ALPHA = 0.05          # (a''), (b'): the one-sided McNemar tests' level
PREDICTION = 0.9      # (a): the prediction floor
CELL_CHANGE = 0.05    # (c): a cell is faster / slower beyond this fraction of its old time


def _mean(xs: list) -> float | None:
    xs = [x for x in xs if x is not None]
    return sum(xs) / len(xs) if xs else None


ROW_FIELDS = (("successes", "n_success"), ("time_s", "completion_time_s"),
              ("prediction", "correct_prediction_rate"), ("questions", "questions"))
"""The row's names and the fields of ``sim.evaluate.summarise`` they are read from."""


def _pooled(suite: dict) -> dict[tuple[str, str, str], dict]:
    """``summarise``'s row per (scene, task, method), the users pooled."""
    rows = summarise([{**t, "user": "all"} for t in suite["trials"]])
    return {(r["scene"], r["task"], r["method"]): r for r in rows}


def task_rows(new: dict, old: dict) -> list[dict]:
    """Per (scene, task, method), the users pooled: successes, mean time of the successful trials (s), the
    correct-prediction rate and questions a task, each as ``(old, new)`` (old ``None`` where the default's
    file lacks the task)."""
    before = _pooled(old)
    return [{"scene": key[0], "task": key[1], "method": key[2],
             **{name: (before.get(key, {}).get(field), row[field]) for name, field in ROW_FIELDS}}
            for key, row in _pooled(new).items()]


def cell_changes(new: dict, old: dict) -> dict[str, list[int]]:
    """Per method, ``[faster, slower]``: the (task, user) cells whose mean time moved by more than
    ``CELL_CHANGE`` of the default's."""
    before = {(r["scene"], r["task"], r["method"], r["user"]): r["completion_time_s"] for r in old["summary"]}
    out: dict[str, list[int]] = {}
    for r in new["summary"]:
        o = before.get((r["scene"], r["task"], r["method"], r["user"]))
        n = r["completion_time_s"]
        counts = out.setdefault(r["method"], [0, 0])
        if o is None or n is None or o == 0:
            continue
        counts[0] += n < (1 - CELL_CHANGE) * o
        counts[1] += n > (1 + CELL_CHANGE) * o
    return out


def _time_pairs(new: dict, old: dict):
    """Each trial of ``new`` with its completion times ``(option's, default's)`` (s) where the default's
    trial of the same scene, task, method, user and seed exists and both succeeded, else ``None``."""
    before = {trial_key(t): t for t in old["trials"]}
    for t in new["trials"]:
        o = before.get(trial_key(t))
        both = o is not None and t["success"] and o["success"]
        yield t, ((t["completion_time_s"], o["completion_time_s"]) if both else None)


def paired_cell_changes(new: dict, old: dict) -> dict[str, list[int]]:
    """Rule s32's (c''): per method, ``[faster, slower]``: the (task, user) cells whose mean time over the
    seeds both succeed on moved by more than ``CELL_CHANGE`` of the default's (cells with no such seed are
    not counted)."""
    times: dict[tuple, list[tuple[float, float]]] = {}
    for t, pair in _time_pairs(new, old):
        cell = times.setdefault((t["scene"], t["task"], t["method"], t["user"]), [])
        if pair is not None:
            cell.append(pair)
    out: dict[str, list[int]] = {}
    for (_, _, method, _), pairs in times.items():
        counts = out.setdefault(method, [0, 0])
        if pairs:
            n, o = (sum(p[i] for p in pairs) / len(pairs) for i in (0, 1))
            counts[0] += n < (1 - CELL_CHANGE) * o
            counts[1] += n > (1 + CELL_CHANGE) * o
    return out


def _pairs(new: dict, old: dict, field: str):
    """The trials of ``new`` paired with ``old``'s of the same scene, task, method, user and seed: yields
    ``((scene, task, method), new value, old value)`` of ``field``."""
    before = {trial_key(t): t[field] for t in old["trials"]}
    for t in new["trials"]:
        o = before.get(trial_key(t))
        if o is not None:
            yield (t["scene"], t["task"], t["method"]), t[field], o


def _policy_pairs(new: dict, old: dict, field: str):
    """:func:`_pairs` of the policy's trials, keyed ``(scene, task)``."""
    for (scene, task, method), n, o in _pairs(new, old, field):
        if method == "policy":
            yield (scene, task), n, o


def mcnemar_lost(lost: int, gained: int) -> float:
    """The exact one-sided McNemar p-value of ``lost`` or more losses among ``lost + gained`` discordant
    pairs (1 with none)."""
    n = lost + gained
    return sum(math.comb(n, i) for i in range(lost, n + 1)) / 2 ** n if n else 1.0


def _flip_counts(pairs) -> dict:
    """Per key, ``[lost, gained]``: pairs right (true) under the default and wrong under the option, and the
    reverse."""
    flips: dict = {}
    for key, right_new, right_old in pairs:
        f = flips.setdefault(key, [0, 0])
        f[0] += bool(right_old) and not right_new
        f[1] += (not right_old) and bool(right_new)
    return flips


def success_flips(new: dict, old: dict) -> dict[tuple[str, str, str], tuple[int, int, float]]:
    """Per (scene, task, method), the discordant pairs of success (same user and seed): ``(lost, gained,
    p)``, p the exact one-sided McNemar p-value (:func:`mcnemar_lost`); rule s29's (b')."""
    return {k: (lost, gained, mcnemar_lost(lost, gained))
            for k, (lost, gained) in _flip_counts(_pairs(new, old, "success")).items()}


def logp_changes(new: dict, old: dict) -> dict[tuple[str, str], tuple[float, float, float]]:
    """Per (scene, task), the policy's paired change of the end-of-trial log p(true target): ``(mean, low,
    high)`` of option minus default over the trials of the same user and seed, the 95 % normal interval."""
    diffs: dict[tuple[str, str], list[float]] = {}
    for task, p_new, p_old in _policy_pairs(new, old, "final_target_p"):
        diffs.setdefault(task, []).append(math.log(max(p_new, P_FLOOR)) - math.log(max(p_old, P_FLOOR)))
    out = {}
    for k, d in diffs.items():
        m = sum(d) / len(d)
        se = (sum((x - m) ** 2 for x in d) / (len(d) - 1) / len(d)) ** 0.5 if len(d) > 1 else math.inf
        out[k] = (m, m - Z95 * se, m + Z95 * se)
    return out


def prediction_flips(new: dict, old: dict) -> dict[tuple[str, str], tuple[int, int, float]]:
    """Per (scene, task), the policy's discordant pairs of correct prediction (same user and seed): ``(lost,
    gained, p)``, lost = right under the default and wrong under the option, p the exact one-sided
    McNemar p-value of that many losses or more among the discordant pairs."""
    return {k: (lost, gained, mcnemar_lost(lost, gained))
            for k, (lost, gained) in _flip_counts(_policy_pairs(new, old, "correct_prediction")).items()}


def paired_times(new: dict, old: dict) -> tuple[list[float], list[float]]:
    """Rule s39's (h): the policy's completion times (s) of the trials both configurations succeed on,
    ``(option's, default's)`` paired by scene, task, user and seed."""
    pairs = [pair for t, pair in _time_pairs(new, old) if pair is not None and t["method"] == "policy"]
    return [p[0] for p in pairs], [p[1] for p in pairs]


def judge_times(option_s: list[float], default_s: list[float], centre: str = "median") -> list[str]:
    """(h), or with ``centre = "mean"`` (h'): a failure line unless the option is significantly faster over
    the pairs, the ``centre`` of the paired differences below zero."""
    test = paired_wilcoxon(option_s, default_s)
    diffs = [a - b for a, b in zip(option_s, default_s, strict=True)]
    mid = test.median_diff if centre == "median" else (sum(diffs) / len(diffs) if diffs else None)
    if mid is not None and mid < 0 and test.p_value is not None and test.p_value < ALPHA:
        return []
    part = "(h)" if centre == "median" else "(h')"
    return [f"{part} paired time over {test.n_pairs} trials: {centre} difference {_f(mid, 3)} s, "
            + f"p = {_f(test.p_value, 3)}"]


def judge(rows: list[dict], cells: dict[str, list[int]],
          logp: dict[tuple[str, str], tuple[float, float, float]] | None = None,
          flips: dict[tuple[str, str], tuple[int, int, float]] | None = None,
          successes: dict[tuple[str, str, str], tuple[int, int, float]] | None = None) -> list[str]:
    """The rule's failures, one line each (an empty list: adopt). With ``logp`` (session 28's rule) or
    ``flips`` (its second form) part (a) is that paired test instead of the prediction rates; with
    ``successes`` (session 29's form) part (b) is the paired test of :func:`success_flips`, per (task,
    method) and pooled, instead of the count."""
    fails = []
    if successes is not None:
        for (scene, task, method), (lost, gained, p) in successes.items():
            if p < ALPHA:
                fails.append(f"(b') {scene} {task} {method}: successes lost {lost}, gained {gained} (p = {p:.3f})")
        lost, gained = (sum(v[i] for v in successes.values()) for i in (0, 1))
        if (p_pooled := mcnemar_lost(lost, gained)) < ALPHA:
            fails.append(f"(b') pooled: successes lost {lost}, gained {gained} (p = {p_pooled:.3f})")
    for r in rows:
        (so, sn), (po, pn) = r["successes"], r["prediction"]
        if successes is None and so is not None and sn < so - MAX_LOST:
            fails.append(f"(b) {r['task']} {r['method']}: {so} -> {sn} successes")
        if logp is None and flips is None and r["method"] == "policy" and po is not None and pn is not None and po >= PREDICTION > pn:
            fails.append(f"(a) {r['task']}: prediction {po:.2f} -> {pn:.2f}")
    for (scene, task), (lost, gained, p) in (flips or {}).items():
        if p < ALPHA:
            fails.append(f"(a'') {scene} {task}: correct predictions lost {lost}, gained {gained} (p = {p:.3f})")
    for (scene, task), (m, lo, hi) in (logp or {}).items():
        if lo < -MARGIN:
            fails.append(f"(a') {scene} {task}: log p {m:+.3f} [{lo:+.3f}, {hi:+.3f}]")
    scene2 = [r for r in rows if r["scene"] == "scene2" and r["method"] == "policy"]
    if scene2 and logp is None and flips is None:
        po = _mean([r["prediction"][0] for r in scene2])
        pn = _mean([r["prediction"][1] for r in scene2])
        if pn <= po:
            fails.append(f"(a) Scene 2's prediction does not rise: {po:.3f} -> {pn:.3f}")
    for method, (faster, slower) in cells.items():
        if slower > faster:
            fails.append(f"(c) {method}: {slower} cells slower, {faster} faster")
    return fails


def targets_met(paths: list[Path]) -> dict[tuple[str, str], bool | None]:
    """Rule s37's (t): each of issue 16's target rows (``targets.py``) on the trials of ``paths``, its verdict
    by (target, where)."""
    return {(r.target, r.where): r.met for r in report(load_trials(paths))}


def judge_targets(new: dict[tuple[str, str], bool | None], old: dict[tuple[str, str], bool | None]) -> list[str]:
    """(t): a failure line unless the option meets more target rows than the default."""
    n_new, n_old = (sum(v is True for v in d.values()) for d in (new, old))
    return [] if n_new > n_old else [f"(t) issue 16's targets met {n_old} -> {n_new}"]


def _f(x: float | None, digits: int) -> str:
    return "-" if x is None else f"{x:.{digits}f}"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("tag")
    ap.add_argument("--dir", type=Path, default=HERE, help="where the option's suite files are")
    ap.add_argument("--default", default="marginal", help="the default's file tag")
    ap.add_argument("--default-dir", type=Path, default=HERE, help="where the default's suite files are")
    ap.add_argument("--rule", choices=("s19", "s28", "s28b", "s29", "s32", "s37", "s39", "s39b"), default="s19",
                    help="s19: session 19's rule; s28, s28b, s29, s32: for options that leave the tracker; "
                    "s37: for options whose gain is issue 16's targets; s39, s39b: s32 and the paired time (h), (h')")
    ap.add_argument("--manual", help="rule s37: the tag of the manual runs on the same seeds (in --dir)")
    args = ap.parse_args(argv)
    judged_rows: list[dict] = []
    judged_logp: dict[tuple[str, str], tuple[float, float, float]] = {}
    judged_flips: dict[tuple[str, str], tuple[int, int, float]] = {}
    judged_successes: dict[tuple[str, str, str], tuple[int, int, float]] = {}
    judged_cells: dict[str, list[int]] = {}
    judged_times: tuple[list[float], list[float]] = ([], [])
    lines = ["| suite | task | method | successes | time s | prediction | questions |", "|" + "---|" * 7]
    for suite in ALL_SUITES:
        path = args.dir / f"suite-{suite}-{args.tag}.json"
        if not path.exists():
            continue
        new = json.loads(path.read_text())
        old_path = args.default_dir / f"suite-{suite}-{args.default}.json"
        if not old_path.exists():
            print(f"{suite}: no {old_path.name} to compare with; skipped", file=sys.stderr)
            continue
        old = json.loads(old_path.read_text())
        cells = paired_cell_changes(new, old) if args.rule in ("s32", "s37", "s39", "s39b") else cell_changes(new, old)
        rows, logp = task_rows(new, old), logp_changes(new, old)
        flips, successes = prediction_flips(new, old), success_flips(new, old)
        for (scene, task, method), (lost, gained, p) in successes.items():
            if lost or gained:
                print(f"{suite} {scene} {task} {method}: successes lost {lost}, gained {gained}, McNemar p {p:.3f}")
        for (scene, task), (lost, gained, p) in flips.items():
            print(f"{suite} {scene} {task}: policy correct predictions lost {lost}, gained {gained}, McNemar p {p:.3f}")
        for (scene, task), (m, lo, hi) in logp.items():
            print(f"{suite} {scene} {task}: policy log p(true target) at the end {m:+.3f} [{lo:+.3f}, {hi:+.3f}]")
        for r in rows:
            lines.append(f"| {suite} | `{r['task']}` | {r['method']} | {_f(r['successes'][0], 0)} -> {r['successes'][1]} | "
                         f"{_f(r['time_s'][0], 1)} -> {_f(r['time_s'][1], 1)} | "
                         f"{_f(r['prediction'][0], 2)} -> {_f(r['prediction'][1], 2)} | "
                         f"{_f(r['questions'][0], 2)} -> {_f(r['questions'][1], 2)} |")
        print(f"{suite}: cells more than {CELL_CHANGE:.0%} faster / slower "
              + ", ".join(f"{m} {f} / {s}" for m, (f, s) in cells.items()))
        print("policy against HO, the option then the default:")
        print("\n".join(v for v in verdicts(new["comparisons"]) + verdicts(old["comparisons"]) if "| ho |" in v))
        if suite in RULE_SUITES:
            judged_rows += rows
            judged_logp.update(logp)
            judged_flips.update(flips)
            judged_successes.update(successes)
            for mine, theirs in zip(judged_times, paired_times(new, old), strict=True):
                mine += theirs
            for m, (f, s) in cells.items():
                judged_cells.setdefault(m, [0, 0])
                judged_cells[m][0] += f
                judged_cells[m][1] += s
    if not judged_rows:
        print(f"no suite-*-{args.tag}.json of {', '.join(RULE_SUITES)} in {args.dir}", file=sys.stderr)
        return 2
    print("\n" + "\n".join(lines) + "\n")
    # s37 has no prediction part of its own ((t) weighs the predictions): no flips, and not None, which is (a)
    flips = {} if args.rule == "s37" else judged_flips if args.rule in ("s28b", "s29", "s32", "s39", "s39b") else None
    fails = judge(judged_rows, judged_cells, judged_logp if args.rule == "s28" else None, flips,
                  judged_successes if args.rule in ("s29", "s32", "s37", "s39", "s39b") else None)
    if args.rule in ("s39", "s39b"):
        fails += judge_times(*judged_times, centre="median" if args.rule == "s39" else "mean")
    if args.rule == "s37":
        manual = [args.dir / f"suite-{s}-{args.manual}.json" for s in ("table1", "study-simple")] if args.manual else []
        sides = [[d / f"suite-{s}-{t}.json" for s in ALL_SUITES if (d / f"suite-{s}-{t}.json").exists()] + manual
                 for d, t in ((args.dir, args.tag), (args.default_dir, args.default))]
        new_t, old_t = (targets_met(paths) for paths in sides)
        for key in sorted(new_t.keys() | old_t.keys()):
            if new_t.get(key) is not old_t.get(key):
                print(f"target {key[0]} ({key[1]}): {old_t.get(key)} -> {new_t.get(key)}")
        fails += judge_targets(new_t, old_t)
    print(f"Rule {args.rule}: " + ("adopt" if not fails else "off"))
    for f in fails:
        print("  " + f)
    return 0


if __name__ == "__main__":
    sys.exit(main())
