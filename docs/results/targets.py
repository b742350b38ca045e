"""Issue 16's targets, each checked on recorded suite files: what it asks, what the files measure, met or not.

    python docs/results/targets.py FILE [FILE ...]

``FILE`` are ``sa-daemon eval --json`` files (suites or plain runs) and ``sa-daemon bench planner --json``
files, told apart by their content. The evaluations' trials are pooled, a trial being
one (scene, task, user, method, seed); a trial recorded in two files (Table I's ``cup:top`` is also Fig. 7's
first task) is taken once, from the first file, and two records of it that disagree are an error, since
then the files come from different models. Paired tests are recomputed on the pooled trials with the
evaluation's own :func:`~sa_daemon.sim.evaluate.compare` (Wilcoxon by seed, Holm over every test of a
(scene, task, user)), so a manual run on the same seeds joins the HO comparison's correction. A target
whose trials are not in the files is reported as not measured, not as met. A target judged on a mean
(questions a task, the 22 goals, correct prediction) is judged on the mean and shows its 95 % bootstrap
interval, the seeds resampled within each user; a row not met is marked when its target lies within that
interval (at a band's edge, where another sample may meet it). Prints a Markdown table, then
the policy's questions a task per user on the tasks with a question-count target (and when the first came),
and per user its time and input over HO's and manual's on Table I and the simple study.

The targets (issue 16, "Targets"; the policy's trials unless named):

* questions a task 0.4-1.6 on Scene 1 ``cup:top``, ``cup:side``, ``bowl:top`` and the simple study's tasks;
  at most 0.2 on ``chips can:side``; at most 1.0 on average on the 22-goal scene, no trial above 3;
* no question while the belief is within 10 % of uniform; the asked target's object among the two most
  likely in at least 0.8 of the questions (task by task);
* in the first 2 s of the Scene 1 tasks, HO or no-assist in most plans;
* the policy beating HO on completion time and joystick input for every user on Table I and the simple
  study, "Holm-corrected p < 0.05 where the paper found it" (below); never significantly slower than
  manual; ``cup:side`` succeeding in at least 4 of 5 trials for every user; correct prediction at least 0.9
  on every task;
* ``bench planner`` on the new model: solve p50 <= 10 ms, p99 <= 100 ms, agreement at the 0.1 s budget
  >= 0.99 and above the pomdp_py POUCT peer planning the same model (a ``bench planner --json`` file among
  the arguments; the issue's "22 actions" is the 22-goal scene's).

"Where the paper found it": the paper's simple study found the policy significantly better than HO on the
cup (its Task 3: time p = 0.019, joystick input p = 0.003, section VI-D.1) and nowhere else; Table I is one
trial a method, without a test. So on the simple cup every user must be significantly better (Holm p < 0.05)
on both measures; on the other tasks "beats" is read as every user's paired median difference favouring the
policy with no user significantly worse. Sessions before 38 asked significance everywhere; the row still
prints how many users are significantly better, so that stricter reading can be read off it.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path

from sa_daemon.sim.evaluate import compare, question_measures, trial_key
from sa_daemon.sim.stats import bootstrap_ci

POLICY = "policy"
ALPHA = 0.05
# The (scene, task)s and measures on which the paper found the policy significantly better than HO (above).
PAPER_SIGNIFICANT = {("study-simple", "cup:top"): ("completion_time_s", "joystick_input")}
SCENE1_ASKING = (("scene1", "cup:top"), ("scene1", "cup:side"), ("scene1", "bowl:top"))
EASY = ("scene1", "chips can:side")
Key = tuple[str, str]


@dataclass(frozen=True)
class Row:
    """One line of the report: the target, where it is measured, the figure, and the verdict (``None``:
    not measured in the files). ``within`` is, for a row judged on a mean, whether the target is met
    anywhere in the mean's 95 % interval (:func:`_judged`): a row not met but within it is at the
    band's edge, one not met and outside it is not a matter of the sample."""

    target: str
    where: str
    measured: str
    met: bool | None
    within: bool | None = None


def load_trials(paths: Iterable[Path]) -> list[dict]:
    """The trials of every file, each (scene, task, user, method, seed) once (module doc)."""
    return pool_trials((Path(path), json.loads(Path(path).read_text())) for path in paths)


def pool_trials(files: Iterable[tuple[Path, dict]]) -> list[dict]:
    """:func:`load_trials` on files already read: (path, its JSON) pairs."""
    seen: dict[tuple, dict] = {}
    for path, data in files:
        for t in data["trials"]:
            key = trial_key(t)
            old = seen.setdefault(key, t)
            if old is not t and (old["completion_time_s"], old["questions"]) != (t["completion_time_s"], t["questions"]):
                raise ValueError(f"{key} recorded twice with different outcomes ({path}): not one model's files")
    return list(seen.values())


def _tasks(trials: list[dict], scene: str | None = None, method: str = POLICY) -> list[Key]:
    return list(dict.fromkeys((t["scene"], t["task"]) for t in trials
                              if t["method"] == method and (scene is None or t["scene"] == scene)))


def _of(trials: list[dict], key: Key, method: str = POLICY) -> list[dict]:
    return [t for t in trials if (t["scene"], t["task"]) == key and t["method"] == method]


def _compared(trials: list[dict]) -> list[Key]:
    """The tasks the policy is compared with HO and manual on: Table I and the simple study's."""
    return [k for k in _tasks(trials) if k == ("scene1", "cup:top") or k[0] == "study-simple"]


def _users(trials: list[dict]) -> list[str]:
    """The users of the policy's trials, in the order they first appear."""
    return list(dict.fromkeys(t["user"] for t in trials if t["method"] == POLICY))


def _mean(values: list[float]) -> float:
    return sum(values) / len(values)


def _where(key: Key) -> str:
    return f"{key[0]} `{key[1]}`"


def _judged(ts: list[dict], value: Callable[[dict], float], ok: Callable[[float, float], bool]) -> tuple[str, bool, bool]:
    """The mean of ``value`` over ``ts`` with its 95 % bootstrap interval, the seeds resampled within each
    user (the population's mix of users is fixed by design; only its seeds are a sample), as text; whether
    ``ok`` holds on the mean; and whether it holds anywhere in the interval (``ok(lo, hi)`` is given the
    interval's ends)."""
    values = [float(value(t)) for t in ts]
    mean = _mean(values)
    lo, hi = bootstrap_ci(values, strata=[t["user"] for t in ts])
    return f"{mean:.2f} [{lo:.2f}, {hi:.2f}]", ok(mean, mean), ok(lo, hi)


def _questions(trials: list[dict], key: Key, target: str, ok: Callable[[float, float], bool]) -> Row:
    """The policy's questions a task on ``key``, judged by ``ok`` (module doc, :func:`_judged`)."""
    ts = _of(trials, key)
    if not ts:
        return Row(target, _where(key), "-", None)
    text, met, within = _judged(ts, lambda t: t["questions"], ok)
    return Row(target, _where(key), f"{text} ({len(ts)} trials)", met, within)


def question_band(trials: list[dict]) -> list[Row]:
    """Questions a task in 0.4-1.6 where the paper's asked, at most 0.2 on the easy task."""
    rows = [_questions(trials, key, "questions a task 0.4-1.6", lambda lo, hi: hi >= 0.4 and lo <= 1.6)
            for key in [*SCENE1_ASKING, *_tasks(trials, "study-simple")]]
    return rows + [_questions(trials, EASY, "questions a task <= 0.2", lambda lo, hi: lo <= 0.2)]


def many_goals(trials: list[dict]) -> list[Row]:
    """The 22-goal scene: at most 1.0 questions a task on average, no trial above 3."""
    ts = [t for t in trials if t["scene"] == "study-complex" and t["method"] == POLICY]
    if not ts:
        return [Row("22 goals: questions <= 1.0 a task, no trial above 3", "study-complex", "-", None)]
    text, mean_ok, mean_within = _judged(ts, lambda t: t["questions"], lambda lo, hi: lo <= 1.0)
    over = sum(t["questions"] > 3 for t in ts)
    _, _, over_within = _judged(ts, lambda t: t["questions"] > 3, lambda lo, hi: lo == 0.0)
    return [Row("22 goals: questions <= 1.0 a task, no trial above 3", "study-complex",
                f"{text} a task; {over} of {len(ts)} trials above 3", mean_ok and over == 0,
                mean_within and over_within)]


def what_is_asked(trials: list[dict]) -> list[Row]:
    """No question near a uniform belief; the asked object among the two likeliest, task by task."""
    ts = [t for t in trials if t["method"] == POLICY and "asked" in t]
    asked = [q for t in ts for q in t["asked"]]
    near = sum(q["over_uniform"] < 1.1 for q in asked)
    rows = [Row("no question within 10 % of uniform", "every task", f"{near} of {len(asked)} questions",
                None if not ts else near == 0)]
    for key in _tasks(ts):
        share = question_measures(_of(ts, key))["questions_top2"]
        if share is not None:
            rows.append(Row("asked object among the two likeliest >= 0.8", _where(key), f"{share:.2f}", share >= 0.8))
    return rows


def early_plans(trials: list[dict]) -> list[Row]:
    """In the first 2 s of the Scene 1 tasks, HO or no-assist in most plans."""
    rows = []
    for key in _tasks(trials, "scene1"):
        share = question_measures(_of(trials, key))["early_passive"]
        rows.append(Row("first 2 s: HO or no-assist in most plans", _where(key),
                        "-" if share is None else f"{share:.2f}", None if share is None else share > 0.5))
    return rows


def against(trials: list[dict], comparisons: list[dict], baseline: str) -> list[Row]:
    """Per Table I and simple-study task: the users for whom the policy is significantly faster (and uses
    less input) than ``baseline``, and those for whom it is significantly slower (more input). Against
    manual the target is no user significantly worse; against HO, every user's paired median better, none
    significantly worse, and every user significantly better where the paper found it (module doc)."""
    rows = []
    for key in _compared(trials):
        users = sorted({t["user"] for t in _of(trials, key)})
        tests = {(c["user"], c["metric"]): c for c in comparisons
                 if (c["scene"], c["task"]) == key and c["baseline"] == baseline and c["p_holm"] is not None}
        if not tests:
            rows.append(Row(f"policy against {baseline}", _where(key), f"no {baseline} trials", None))
            continue
        figures, ok = [], True
        for metric, name in (("completion_time_s", "time"), ("joystick_input", "input")):
            sig = [tests[(u, metric)] for u in users if (u, metric) in tests and tests[(u, metric)]["p_holm"] < ALPHA]
            better = sum(c["median_diff"] < 0 for c in sig)
            worse = sum(c["median_diff"] > 0 for c in sig)
            figures.append(f"{name}: better for {better}, worse for {worse} of {len(users)}")
            if baseline == "manual":
                ok = ok and worse == 0
                continue
            leaning = sum((u, metric) in tests and tests[(u, metric)]["median_diff"] < 0 for u in users)
            figures[-1] += f" (median better for {leaning})"
            asked = better if metric in PAPER_SIGNIFICANT.get(key, ()) else leaning
            ok = ok and worse == 0 and asked == len(users)
        target = ("policy never significantly slower than manual" if baseline == "manual"
                  else "policy beats HO on time and input for every user (significantly on the simple cup)")
        rows.append(Row(target, _where(key), "; ".join(figures), ok))
    return rows


def cup_side_success(trials: list[dict]) -> list[Row]:
    """``cup:side`` succeeds in at least 4 of 5 trials for every user."""
    ts = _of(trials, ("scene1", "cup:side"))
    if not ts:
        return [Row("`cup:side` succeeds >= 0.8 for every user", "scene1 `cup:side`", "-", None)]
    rates = {u: _mean([t["success"] for t in ts if t["user"] == u]) for u in sorted({t["user"] for t in ts})}
    low = {u: r for u, r in rates.items() if r < 0.8}
    return [Row("`cup:side` succeeds >= 0.8 for every user", "scene1 `cup:side`",
                f"lowest {min(rates.values()):.2f}" + (f" ({', '.join(low)})" if low else ""), not low)]


def prediction(trials: list[dict]) -> list[Row]:
    """Correct prediction (the true target above 0.7 at the end) at least 0.9, task by task."""
    rows = []
    for key in _tasks(trials):
        text, met, within = _judged(_of(trials, key), lambda t: t["correct_prediction"], lambda lo, hi: hi >= 0.9)
        rows.append(Row("correct prediction >= 0.9", _where(key), text, met, within))
    return rows


def planner_bench(bench: dict) -> Row:
    """``bench planner`` on the new model (``planner.model = "watch"``): solve p50 <= 10 ms and p99 <= 100 ms,
    agreement with the optimum at the budget >= 0.99 and above pomdp_py's POUCT planning the same model."""
    peer = bench.get("peer_agreement_at_budget")
    agree = bench["agreement_at_budget"]
    measured = (f"{bench.get('model', '?')} model: p50 {bench['solve_ms_p50']:.2f} ms, p99 {bench['solve_ms_p99']:.2f} ms, "
                f"agreement {agree:.3f}, POUCT " + ("not run" if peer is None else f"{peer:.3f}"))
    met = (bench.get("model") == "watch" and bench["solve_ms_p50"] <= 10.0 and bench["solve_ms_p99"] <= 100.0
           and agree >= 0.99 and peer is not None and agree > peer)
    return Row("bench planner: p50 <= 10 ms, p99 <= 100 ms, agreement >= 0.99 and above the peer",
               f"{bench['scene']} ({bench['goals']} goals, bench)", measured, met)


def report(trials: list[dict]) -> list[Row]:
    """Every target's rows, in the issue's order."""
    comparisons = compare(trials, POLICY)
    checks: list[Callable[[list[dict]], list[Row]]] = [question_band, many_goals, what_is_asked, early_plans]
    rows = [r for check in checks for r in check(trials)]
    rows += against(trials, comparisons, "ho") + against(trials, comparisons, "manual")
    return rows + cup_side_success(trials) + prediction(trials)


def markdown(rows: list[Row]) -> str:
    verdict = {True: "met", False: "**not met**", None: "not measured"}
    lines = ["| target | where | measured | verdict |", "|---|---|---|---|"]
    lines += [f"| {r.target} | {r.where} | {r.measured} | {verdict[r.met]}"
              + (" (within its 95 % interval)" if r.met is False and r.within else "") + " |" for r in rows]
    met = sum(r.met is True for r in rows)
    unmet = sum(r.met is False for r in rows)
    edge = sum(r.met is False and bool(r.within) for r in rows)
    return ("\n".join(lines) + f"\n\n{met} met, {unmet} not met ({edge} of them within the 95 % interval of "
            f"their mean), {len(rows) - met - unmet} not measured. Intervals: the mean's 95 % bootstrap interval, "
            "the seeds resampled within each user.")


def questions_by_user(trials: list[dict]) -> str:
    """The policy's questions a task, per task with a question-count target and per user: which users the
    task means are made of (a Markdown table; empty when no such task is in the trials)."""
    keys = [k for k in _tasks(trials) if k in (*SCENE1_ASKING, EASY) or k[0] in ("study-simple", "study-complex")]
    users = _users(trials)
    if not keys:
        return ""
    lines = ["| questions a task | " + " | ".join(users) + " | all | first question (s, mean) |",
             "|---" * (len(users) + 3) + "|"]
    for key in keys:
        ts = _of(trials, key)
        cells = []
        for u in users:
            own = [t["questions"] for t in ts if t["user"] == u]
            cells.append(f"{_mean(own):.2f}" if own else "-")
        first = question_measures(ts)["first_question_s"]
        lines.append(f"| {_where(key)} | " + " | ".join(cells) + f" | {_mean([t['questions'] for t in ts]):.2f} | "
                     + ("-" if first is None else f"{first:.1f}") + " |")
    return "\n".join(lines)


def ratios_by_user(trials: list[dict], baseline: str) -> str:
    """The policy's mean completion time and joystick input over ``baseline``'s, successful trials only, per
    Table I and simple-study task and per user, as ``time / input`` (below 1: the policy better); a
    Markdown table, empty when ``baseline`` has no such trials."""
    keys = [k for k in _compared(trials) if _of(trials, k, baseline)]
    users = _users(trials)
    if not keys:
        return ""

    def ratio(key: Key, user: str, metric: str) -> str:
        means = []
        for method in (POLICY, baseline):
            done = [t[metric] for t in _of(trials, key, method) if t["user"] == user and t["success"]]
            means.append(_mean(done) if done else None)
        return "-" if None in means or not means[1] else f"{means[0] / means[1]:.2f}"

    lines = [f"| policy / {baseline}: time / input | " + " | ".join(users) + " |", "|---" * (len(users) + 1) + "|"]
    for key in keys:
        lines.append(f"| {_where(key)} | " + " | ".join(
            f"{ratio(key, u, 'completion_time_s')} / {ratio(key, u, 'joystick_input')}" for u in users) + " |")
    return "\n".join(lines)


if __name__ == "__main__":
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    data = {Path(p): json.loads(Path(p).read_text()) for p in sys.argv[1:]}
    unknown = [str(p) for p, d in data.items() if "trials" not in d and "solve_ms_p50" not in d]
    if unknown:
        sys.exit(f"neither an eval nor a bench planner --json file: {', '.join(unknown)}")
    benches = [d for d in data.values() if "solve_ms_p50" in d]  # bench planner --json files
    pooled = pool_trials((p, d) for p, d in data.items() if "trials" in d)
    print(markdown(report(pooled) + [planner_bench(b) for b in benches]))
    for table in (questions_by_user(pooled), ratios_by_user(pooled, "ho"), ratios_by_user(pooled, "manual")):
        if table:
            print("\n" + table)
