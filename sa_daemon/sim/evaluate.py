"""``sa-daemon eval``: every scene x task x user x method x seed, in parallel, summarised like the paper.

Results depend only on the seeds, the users and the configuration (the planner stops at a node budget,
never at a clock), so serial, process-pool and Ray runs give the same numbers. Summaries follow section
IV: completion time, mode changes, joystick input and opposing time over successful trials; success,
correct prediction and questions over all trials; each with a 95 % bootstrap interval (``ci95``). Policy
is compared with every other method of the same (scene, task, user) over matched seeds (Wilcoxon
signed-rank, Holm-corrected per (scene, task, user): ``sim/stats.py``).
"""

from __future__ import annotations

import json
import multiprocessing as mp
import sys
import time
from collections.abc import Iterable
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np
from tqdm import tqdm

from ..config import Config, ConfigError
from ..cores import cores
from ..world.scene import load_scene
from . import stats
from .episode import arm_factory, run_trial
from .users import CALIBRATED, UserProfile, load_user

SUCCESS_METRICS = ("completion_time_s", "mode_changes", "joystick_input", "opposing_pct")
"""Means over successful trials (section IV)."""
RATE_METRICS = ("success", "correct_prediction", "questions")
"""Means over all trials."""
COMPARED = (*SUCCESS_METRICS, "success", "questions")
"""Metrics on which policy is compared with every other method."""
BACKENDS = ("local", "ray")


@dataclass(frozen=True)
class TrialSpec:
    scene: str  # built-in name or path
    task: str
    method: str
    seed: int
    user: str = CALIBRATED  # built-in profile name or path (sim/users.py)


@lru_cache(maxsize=64)
def _profile(user: str) -> UserProfile:
    return load_user(user)


def timeline_path(plots: Path, spec: TrialSpec, scene_name: str) -> Path:
    """Where the Fig. 4 timeline of one trial goes."""
    user = "" if spec.user == CALIBRATED else f"_{Path(spec.user).stem}"
    safe = f"{scene_name}_{spec.task}_{spec.method}{user}_seed{spec.seed}".replace(" ", "-").replace(":", "-")
    return plots / f"{safe.replace('+', '_')}.png"


def _run(args: tuple[TrialSpec, Config, Path | None, str]) -> dict:
    """One trial (a picklable top-level function: pool and Ray workers call it). The record carries
    ``wall_s``, the trial's own wall time, which :func:`run_trials` takes out for the speed figures."""
    spec, cfg, plots, arm = args
    t0 = time.perf_counter()
    profile = _profile(spec.user)
    scene = load_scene(spec.scene)
    result = run_trial(
        scene, spec.task, spec.method, spec.seed, profile.apply(cfg), arm_factory=arm_factory(arm),
        record=plots is not None, user_name=profile.name,
    )
    if plots is not None:
        from .plots import plot_timeline

        plot_timeline(result, timeline_path(plots, spec, scene.name))
    return {**result.metrics(), "wall_s": time.perf_counter() - t0}


@dataclass(frozen=True)
class Speed:
    """How fast the trials ran: simulated seconds per wall second of one worker, per trial (median and
    worst), and the sweep's wall time."""

    trials: int
    realtime_factor_median: float
    realtime_factor_min: float
    wall_s: float

    def line(self) -> str:
        return (f"{self.trials} trials in {self.wall_s:.1f} s; one trial runs at {self.realtime_factor_median:.0f}x "
                f"real time (median; slowest {self.realtime_factor_min:.0f}x)")


def run_trials(
    specs: list[TrialSpec], cfg: Config, jobs: int = 1, progress: bool = True, plots: Path | None = None,
    arm: str = "kinematic", backend: str = "local", address: str | None = None,
) -> Trials:
    """Run ``specs`` and return their records in the order of ``specs``.

    ``backend``: ``local`` (serial when ``jobs`` <= 1, else ``jobs`` spawned processes) or ``ray`` (the
    ``ray`` extra: a local Ray cluster, or the one at ``address``). With ``plots`` every trial also writes
    its Fig. 4 timeline there. ``arm`` names the arm backend (``kinematic`` or ``mujoco``; a name, so the
    work items pickle). The records come with the sweep's speed (:class:`Trials`).
    """
    if backend not in BACKENDS:
        raise ValueError(f"unknown backend {backend!r} ({', '.join(BACKENDS)})")
    for user in {s.user for s in specs}:
        _profile(user)  # a bad profile fails here, before any worker starts
    if cfg.planner.threads == 0:  # each job its share of the cores for the planner's rollouts
        share = 1 if backend == "ray" else max(1, cores() // max(jobs, 1))
        cfg = cfg.model_copy(update={"planner": cfg.planner.model_copy(update={"threads": share})})
    work = [(s, cfg, plots, arm) for s in specs]
    bar = tqdm(total=len(work), desc="trials", unit="trial", file=sys.stderr, disable=not progress,
               smoothing=0.05)
    t0 = time.perf_counter()
    if backend == "ray":
        from .ray_pool import ray_map

        out = ray_map(_run, work, address=address, num_cpus=jobs if address is None else None,
                      on_result=bar.update)
    elif jobs <= 1:
        out = []
        for w in work:
            out.append(_run(w))
            bar.update()
    else:
        out = []
        with mp.get_context("spawn").Pool(jobs) as pool:
            for r in pool.imap(_run, work):
                out.append(r)
                bar.update()
    bar.close()
    factors = [r["completion_time_s"] / r["wall_s"] for r in out if r["wall_s"] > 0]
    speed = Speed(len(out), float(np.median(factors)) if factors else 0.0,
                  float(np.min(factors)) if factors else 0.0, time.perf_counter() - t0)
    return Trials(({k: v for k, v in r.items() if k != "wall_s"} for r in out), speed)


class Trials(list):
    """The trial records of a sweep, in the order of its specs, and how fast it ran (``speed``)."""

    def __init__(self, records: Iterable[dict] = (), speed: Speed | None = None) -> None:
        super().__init__(records)
        self.speed = speed


def _group_key(t: dict) -> tuple[str, str, str]:
    return t["scene"], t["task"], t.get("user", CALIBRATED)


def summarise(trials: list[dict]) -> list[dict]:
    """One summary per (scene, task, user, method), in first-seen order, with 95 % bootstrap intervals
    (``ci95``: metric -> [low, high], None without data) and the count of successes and of each failure
    reason."""
    groups: dict[tuple[str, str, str, str], list[dict]] = {}
    for t in trials:
        groups.setdefault((*_group_key(t), t["method"]), []).append(t)
    out = []
    for (scene, task, user, method), ts in groups.items():
        ok = [t for t in ts if t["success"]]
        row = {"scene": scene, "task": task, "user": user, "method": method, "n": len(ts), "n_success": len(ok)}
        ci: dict[str, list[float] | None] = {}
        for k in SUCCESS_METRICS:
            vals = [float(t[k]) for t in ok]
            row[k] = float(np.mean(vals)) if vals else None
            row[k + "_std"] = float(np.std(vals)) if vals else None
            ci[k] = _ci(vals)
        for k, name in (("success", "success_rate"), ("correct_prediction", "correct_prediction_rate"),
                        ("questions", "questions")):
            vals = [float(t[k]) for t in ts]
            row[name] = float(np.mean(vals))
            ci[name] = _ci(vals)
        failures: dict[str, int] = {}
        for t in ts:
            if not t["success"]:
                kind = t.get("failure_kind") or "unknown"  # (records from before issue 15 have none)
                failures[kind] = failures.get(kind, 0) + 1
        row["failures"] = failures
        row.update(rule_against_lift(ts))
        row.update(question_measures(ts))
        row["ci95"] = ci
        out.append(row)
    return out


def rule_against_lift(ts: list[dict]) -> dict:
    """On a physics arm (records with ``rule_held``), how the geometric holding rule that decides success
    on the kinematic arm fares against the lift on the same closes: ``rule_held_not_lifted`` (the rule
    would have counted a success the lift did not give) and ``rule_failed_lifted``. ``{}`` for records
    without it (the kinematic arm, files from before session 47), so their summaries are unchanged."""
    judged = [t for t in ts if t.get("rule_held") is not None]
    if not judged:
        return {}
    return {"rule_judged": len(judged),
            "rule_held_not_lifted": sum(t["rule_held"] and not t["success"] for t in judged),
            "rule_failed_lifted": sum(t["success"] and not t["rule_held"] for t in judged)}


def rule_line(summary: list[dict]) -> str | None:
    """One line on :func:`rule_against_lift` over a whole run, or ``None`` if no lift decided a trial."""
    rows = [r for r in summary if "rule_judged" in r]
    if not rows:
        return None
    n, held, failed = (sum(r[k] for r in rows) for k in ("rule_judged", "rule_held_not_lifted", "rule_failed_lifted"))
    return (f"holding rule against the lift, on the {n} closes a lift decided: the rule holds {held} that did not "
            f"lift and fails {failed} that did (the kinematic arm's success is the rule)")


def question_measures(ts: list[dict]) -> dict:
    """When and what a cell's trials asked, and what they chose first (issue 16's targets), from the
    records' ``asked`` and ``early_plans`` (``None`` where there is nothing to measure, e.g. records from
    before these fields):

    * ``questions_near_uniform``: questions a trial asked while the largest target probability was below
      1.1 / number of targets, mean over trials;
    * ``questions_top2``: the share of questions whose target's object was one of the two most likely;
    * ``questions_top_target``: the share of questions about the likeliest target itself (records since
      session 33; ``None`` before);
    * ``first_question_s``: when the first question came, mean over the trials that asked;
    * ``early_passive``: the share of the plans of the first ``EARLY_S`` that chose HO or no-assist.
    """
    recs = [t for t in ts if "asked" in t]
    if not recs:
        return {"questions_near_uniform": None, "questions_top2": None, "questions_top_target": None,
                "first_question_s": None, "early_passive": None}
    qs = [q for t in recs for q in t["asked"]]
    firsts = [t["asked"][0]["t"] for t in recs if t["asked"]]
    early = [t.get("early_plans", {}) for t in recs]
    n_early = sum(sum(e.values()) for e in early)
    return {
        "questions_near_uniform": float(np.mean([sum(q["over_uniform"] < 1.1 for q in t["asked"]) for t in recs])),
        "questions_top2": float(np.mean([q["object_rank"] <= 2 for q in qs])) if qs else None,
        "questions_top_target": (float(np.mean([q["target_rank"] == 1 for q in qs]))
                                 if qs and all("target_rank" in q for q in qs) else None),
        "first_question_s": float(np.mean(firsts)) if firsts else None,
        "early_passive": (sum(e.get("ho", 0) + e.get("none", 0) for e in early) / n_early) if n_early else None,
    }


def _ci(vals: list[float]) -> list[float] | None:
    ci = stats.bootstrap_ci(vals)
    return None if ci is None else [ci[0], ci[1]]


def compare(trials: list[dict], method: str = "policy", metrics: tuple[str, ...] = COMPARED) -> list[dict]:
    """``method`` against every other method of each (scene, task, user), paired by seed: Wilcoxon
    signed-rank per metric (success-only metrics over pairs where both succeeded; ``success`` and
    ``questions`` over all pairs), Holm-corrected over every test of the (scene, task, user)."""
    by_group: dict[tuple[str, str, str], list[dict]] = {}
    for t in trials:
        by_group.setdefault(_group_key(t), []).append(t)
    out: list[dict] = []
    for (scene, task, user), ts in by_group.items():
        methods = list(dict.fromkeys(t["method"] for t in ts))
        if method not in methods:
            continue
        rows = []
        for baseline in (m for m in methods if m != method):
            for metric in metrics:
                test = stats.compare_paired(ts, metric, method, baseline, success_only=metric in SUCCESS_METRICS)
                rows.append({"scene": scene, "task": task, "user": user, "metric": metric, "method": method,
                             "baseline": baseline, "n_pairs": test.n_pairs, "median_diff": test.median_diff,
                             "p_value": test.p_value})
        for r, p in zip(rows, stats.holm([r["p_value"] for r in rows])):
            r["p_holm"] = p
            r["stars"] = stats.stars(p)
        out.extend(rows)
    return out


def format_summary(rows: list[dict], markdown: bool = False, comparisons: list[dict] | None = None,
                   intervals: bool = False) -> str:
    """A table of summaries: aligned plain text, or a Markdown table.

    With ``comparisons`` (from :func:`compare`), a method's value carries the stars of policy's
    difference from it on that metric (Holm-corrected p: ``*`` < 0.05 ... ``****`` < 0.0001). With
    ``intervals``, time and input carry their 95 % interval. A ``user`` column appears when any row is
    not the calibrated user.
    """
    star = {(c["scene"], c["task"], c["user"], c["baseline"], c["metric"]): c["stars"] for c in comparisons or []}
    cols = [
        ("task", "task", "{}", None), ("method", "method", "{}", None), ("n", "n", "{}", None),
        ("success", "success_rate", "{:.2f}", "success"), ("time s", "completion_time_s", "{:.2f}", "completion_time_s"),
        ("modes", "mode_changes", "{:.1f}", "mode_changes"), ("input", "joystick_input", "{:.1f}", "joystick_input"),
        ("oppose %", "opposing_pct", "{:.1f}", "opposing_pct"), ("pred", "correct_prediction_rate", "{:.2f}", None),
        ("qns", "questions", "{:.2f}", "questions"),
    ]
    if any(r.get("user", CALIBRATED) != CALIBRATED for r in rows):
        cols.insert(1, ("user", "user", "{}", None))

    def cell(r: dict, key: str, fmt: str, metric: str | None) -> str:
        if r.get(key) is None:
            return "-"
        text = fmt.format(r[key])
        ci = (r.get("ci95") or {}).get(key)
        if intervals and ci is not None and key in ("completion_time_s", "joystick_input"):
            text += " [" + fmt.format(ci[0]) + ", " + fmt.format(ci[1]) + "]"
        if metric is not None:
            text += star.get((r["scene"], r["task"], r.get("user", CALIBRATED), r["method"], metric), "")
        return text

    table = [[h for h, _, _, _ in cols]]
    for r in rows:
        table.append([cell(r, k, f, m) for _, k, f, m in cols])
    if markdown:
        lines = ["| " + " | ".join(row) + " |" for row in table]
        return "\n".join([lines[0], "|" + "---|" * len(cols)] + lines[1:])
    left = 3 if cols[1][0] == "user" else 2
    widths = [max(len(row[i]) for row in table) for i in range(len(cols))]
    lines = ["  ".join(c.ljust(w) if i < left else c.rjust(w) for i, (c, w) in enumerate(zip(row, widths)))
             for row in table]
    return "\n".join([lines[0], "-" * len(lines[0])] + lines[1:])


def write_results(path: str | Path, trials: list[dict], summary: list[dict], meta: dict,
                  comparisons: list[dict] | None = None) -> None:
    """The JSON of an evaluation: ``meta``, every trial, the summary rows, the comparisons."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    data = {"meta": meta, "trials": trials, "summary": summary, "comparisons": comparisons or []}
    p.write_text(json.dumps(data, indent=2) + "\n")


def trial_key(t: dict) -> tuple[str, str, str, str, int]:
    """What identifies a trial across files: (scene, task, user, method, seed)."""
    return (t["scene"], t["task"], t["user"], t["method"], int(t["seed"]))


def _first_difference(a: object, b: object, path: str = "") -> str | None:
    """The dotted path of the first key where two config dumps differ (``None`` if equal)."""
    if isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b)):
            d = _first_difference(a.get(k), b.get(k), f"{path}{k}.")
            if d is not None:
                return d
        return None
    return None if a == b else path.rstrip(".")


@lru_cache(maxsize=64)
def _scene_name(scene: str) -> str:
    return load_scene(scene).name


def spec_key(spec: TrialSpec) -> tuple[str, str, str, str, int]:
    """The ``trial_key`` the trial of ``spec`` will have once run."""
    return (_scene_name(spec.scene), spec.task, _profile(spec.user).name, spec.method, spec.seed)


def _trials_of(path: str | Path, cfg: Config, arm: str) -> list[dict]:
    """The trials of one earlier ``--json`` run, refused with a ``ConfigError`` naming the first config key
    that differs, or a different arm backend: a merged evaluation must measure one thing. Wall times are not
    kept."""
    try:
        data = json.loads(Path(path).read_text())
        meta, trials = data["meta"], data["trials"]
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise ConfigError(f"eval --merge {path}: not an evaluation's JSON ({e})") from None
    diff = _first_difference(meta.get("config"), cfg.model_dump(mode="json"))
    if diff is not None:
        raise ConfigError(f"eval --merge {path}: measured with another config (first difference: {diff})")
    if meta.get("arm") != arm:
        raise ConfigError(f"eval --merge {path}: measured on the {meta.get('arm')} arm, this run on {arm}")
    return [{k: v for k, v in t.items() if k != "wall_s"} for t in trials]


def earlier_trials(paths: Iterable[str | Path], cfg: Config, arm: str, specs: Iterable[TrialSpec]) -> list[dict]:
    """The trials of earlier ``--json`` runs to merge with the run of ``specs`` (``eval --merge``), checked
    before anything runs: each file measured with ``cfg`` on ``arm`` (see ``_trials_of``), and no trial
    measured twice, across the files or by ``specs``."""
    earlier = [t for path in paths for t in _trials_of(path, cfg, arm)]
    if not earlier:
        return earlier
    seen = {spec_key(s) for s in specs}
    twice = []
    for key in map(trial_key, earlier):
        if key in seen:
            twice.append(key)
        seen.add(key)
    if twice:
        raise ConfigError(f"eval --merge: {len(twice)} trials measured twice, e.g. {min(twice)}")
    return earlier
