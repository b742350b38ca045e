"""``sa-daemon bench soak``: the daemon with the simulated user running tasks back to back for a long
time, watched for memory growth and control-loop overruns.

The run is :func:`~.loop.run_daemon` (the ``bench loop`` machinery, subscriber load included) with RSS
of the daemon's process and of the planner worker sampled every ``--sample-every`` s.

* **Warm-up**: the first ``min(60 s, 10 % of --duration)`` of the run, start-up included. Memory is
  judged on the samples after it: "start" is the first of them, "end" the last, growth is
  ``(end - start) / start`` in %, and the slope is a least-squares fit over all of them (MB/min).
  The worker is judged on the samples of the worker alive at the end (a restarted worker starts anew).
* **Overruns**: control periods longer than 1.5 x nominal, counted from READY to the end.
* **The machine's own stalls** (:mod:`.platform`): unless ``--no-platform-probe``, a pinned
  real-time sleeper per CPU notes every wake-up later than half a control period, with its time. Such
  a stall delays any thread on that CPU, the daemon's loop included, and alone makes an overrun. Each
  overrun is matched against them: ``overruns_during_stall`` counts those that overlap one. Reported,
  never a criterion: the criterion stays the issue's, every overrun counts.
* **Criteria** (flags, the issue's values by default): daemon and worker growth <= ``--max-growth-pct``
  (5 %), overruns <= ``--max-overruns`` (0). Each is printed PASS or FAIL; the exit code is 0 when all
  pass and 1 otherwise, so that CI can run a soak as a check. Timing criteria depend on the machine: on a
  loaded 2-core one a single overrun can happen, and a short soak's growth is mostly still warm-up.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace
from typing import Any

import numpy as np

from ..config import Config
from ..runtime.launch import Launch
from .loop import RssSample, loop_figures, run_daemon, subscriber_rows
from .platform import PlatformProbe

#: Warm-up is this fraction of the duration, but never longer than WARMUP_MAX_S.
WARMUP_FRACTION = 0.1
WARMUP_MAX_S = 60.0


def warmup_s(duration_s: float) -> float:
    """The warm-up (s from the daemon's start) excluded from the memory criteria."""
    return min(WARMUP_MAX_S, WARMUP_FRACTION * duration_s)


def growth(points: list[tuple[float, float]]) -> dict[str, Any]:
    """Start, end (MB), growth (%) and least-squares slope (MB/min) of ``(t_s, MB)`` points; ``None``
    figures when there are fewer than two."""
    if len(points) < 2 or points[0][1] <= 0:
        return {"start_mb": None, "end_mb": None, "growth_pct": None, "slope_mb_per_min": None,
                "samples": len(points)}
    t = np.array([p[0] for p in points]) / 60.0
    mb = np.array([p[1] for p in points])
    return {
        "start_mb": float(mb[0]),
        "end_mb": float(mb[-1]),
        "growth_pct": float(100.0 * (mb[-1] - mb[0]) / mb[0]),
        "slope_mb_per_min": float(np.polyfit(t, mb, 1)[0]),
        "samples": len(points),
    }


def memory_figures(rss: list[RssSample], warmup: float) -> tuple[dict[str, Any], dict[str, Any]]:
    """Growth of the daemon and of the last planner worker over the samples after ``warmup`` s."""
    after = [s for s in rss if s.t_s >= warmup]
    last_pid = rss[-1].worker_pid if rss else None
    daemon = growth([(s.t_s, s.daemon_mb) for s in after])
    worker = growth([(s.t_s, s.worker_mb) for s in after if last_pid and s.worker_pid == last_pid])
    return daemon, worker


def overrun_times(run: Any) -> list[float]:
    """The control loop's latest overruns (``time.monotonic`` s), oldest first."""
    return sorted(float(t) for t in run.daemon.rates["control"].stats.overrun_at.values())


def _criterion(name: str, value: float | None, limit: float) -> dict[str, Any]:
    """One criterion; a figure that could not be measured fails."""
    return {"name": name, "value": value, "limit": limit, "pass": value is not None and value <= limit}


@dataclass(frozen=True)
class SoakSpec:
    """A soak: its length (s), the RSS sampling period (s), the criteria (RSS growth after warm-up, %;
    control overruns allowed), and whether the machine's stalls are probed beside it."""

    duration_s: float = 600.0
    sample_every_s: float = 5.0
    max_growth_pct: float = 5.0
    max_overruns: int = 0
    platform_probe: bool = True


def run_soak(cfg: Config, launch: Launch, spec: SoakSpec, subscribers: int = 0, stalled_subscribers: int = 0
             ) -> dict[str, Any]:
    """Run the soak ``spec`` of the daemon ``cfg`` and ``launch`` describe (its duration is the spec's)
    and return its figures and verdicts (see module doc)."""
    warm = warmup_s(spec.duration_s)
    if spec.sample_every_s <= 0 or spec.duration_s - warm < 2 * spec.sample_every_s:
        raise ValueError(f"--sample-every {spec.sample_every_s} s leaves fewer than 3 samples after the "
                         f"{warm:.1f} s warm-up of a {spec.duration_s} s soak")
    probe = None
    half_period = 0.5 / cfg.runtime.control_hz
    if spec.platform_probe:
        probe = PlatformProbe(half_period)
        probe.start()
    try:
        run = run_daemon(cfg, replace(launch, duration_s=spec.duration_s, exit_when_done=False),
                         subscribers, stalled_subscribers, sample_every_s=spec.sample_every_s)
    finally:
        latency = probe.stop() if probe is not None else None
    platform: dict[str, Any] = (
        latency.as_dict() if latency is not None
        else {"unavailable": probe.unavailable if probe is not None else "--no-platform-probe"}
    )
    loop = loop_figures(run)
    overruns_at = overrun_times(run)
    if latency is not None:
        matched = [latency.during_stall(t, half_period) for t in overruns_at]
        platform["overruns_during_stall"] = sum(m is not None for m in matched)
        platform["overrun_stalls"] = [None if m is None else m.as_row() for m in matched]
    daemon_rss, worker_rss = memory_figures(run.rss, warm)
    criteria = [
        _criterion("daemon RSS growth %", daemon_rss["growth_pct"], spec.max_growth_pct),
        _criterion("worker RSS growth %", worker_rss["growth_pct"], spec.max_growth_pct),
        _criterion("control overruns", loop["overruns"], spec.max_overruns),
    ]
    return {
        "duration_s": loop["duration_s"],
        "soak_s": spec.duration_s,
        "arm": loop["arm"],
        "method": loop["method"],
        "warmup_s": warm,
        "sample_every_s": spec.sample_every_s,
        "daemon_rss": daemon_rss,
        "worker_rss": worker_rss,
        "overruns": loop["overruns"],
        "overrun_pct": 100.0 * loop["overrun_fraction"],
        # When they ended: s since the daemon started, and time.monotonic() to match other processes' logs.
        "overrun_at_s": [round(t - run.daemon.t0, 3) for t in overruns_at],
        "overrun_at_monotonic_s": [round(t, 4) for t in overruns_at],
        "control_ticks": loop["control_ticks"],
        "period_err_ms_p99": loop["period_err_ms_p99"],
        "period_err_ms_max": loop["period_err_ms_max"],
        "platform": platform,
        "planner_restarts": loop["planner_restarts"],
        "questions_asked": sum(d["questions"] for d in run.daemon.tasks_done),  # in finished tasks
        "tasks_done": loop["tasks_done"],
        "tasks_succeeded": loop["tasks_succeeded"],
        "state_messages_published": loop["state_messages_published"],
        "pub_dropped": loop["pub_dropped"],
        "subscribers": loop["subscribers"],
        "criteria": criteria,
        "pass": all(c["pass"] for c in criteria),
        "rss_series": [asdict(s) for s in run.rss],
        "loop": loop,
    }


def _mb(x: float | None) -> str:
    return "n/a" if x is None else f"{x:.1f} MB"


def _pct(x: float | None) -> str:
    return "n/a" if x is None else f"{x:+.2f} %"


def _platform(p: dict[str, Any]) -> str:
    if "late" not in p:
        return f"not measured: {p.get('unavailable', 'no probe')}"
    worst = " / ".join(f"{m:.1f}" for m in p["max_ms"])
    return f"{p['late_total']} in {sum(p['wakeups'])} wake-ups (worst per CPU {worst} ms)"


def _during(p: dict[str, Any]) -> str:
    if "overruns_during_stall" not in p:
        return ""
    return f", {p['overruns_during_stall']} during a machine stall"


def format_soak(f: dict[str, Any]) -> str:
    """The figures as a table, then one PASS/FAIL line per criterion."""
    d, w = f["daemon_rss"], f["worker_rss"]
    slope = "n/a" if d["slope_mb_per_min"] is None else f"{d['slope_mb_per_min']:+.3f} MB/min"
    wslope = "n/a" if w["slope_mb_per_min"] is None else f"{w['slope_mb_per_min']:+.3f} MB/min"
    rows = [
        ("daemon RSS start -> end", f"{_mb(d['start_mb'])} -> {_mb(d['end_mb'])}"),
        ("daemon RSS growth / slope", f"{_pct(d['growth_pct'])} / {slope}"),
        ("worker RSS start -> end", f"{_mb(w['start_mb'])} -> {_mb(w['end_mb'])}"),
        ("worker RSS growth / slope", f"{_pct(w['growth_pct'])} / {wslope}"),
        ("overruns (> 1.5 T)", f"{f['overruns']} of {f['control_ticks']} ({f['overrun_pct']:.3f} %)"
         + _during(f.get("platform") or {})),
        ("period error p99 / max", f"{f['period_err_ms_p99']:.3f} / {f['period_err_ms_max']:.3f} ms"),
        ("machine stalls > T/2 (probe, all CPUs)", _platform(f.get("platform") or {})),
        ("planner restarts", str(f["planner_restarts"])),
        ("questions asked", str(f["questions_asked"])),
        ("tasks done / succeeded", f"{f['tasks_done']} / {f['tasks_succeeded']}"),
        ("states published / PUB sends refused", f"{f['state_messages_published']} / {f['pub_dropped']}"),
        *((a, b) for a, b, _ in subscriber_rows(f["subscribers"])),
    ]
    width = max(len(r[0]) for r in rows)
    head = (f"bench soak: {f['arm']} arm, {f['method']}, {f['duration_s']:.1f} s "
            f"(warm-up {f['warmup_s']:.1f} s, RSS every {f['sample_every_s']:g} s)")
    verdicts = [f"  {'PASS' if c['pass'] else 'FAIL'}  {c['name']} "
                f"{'n/a' if c['value'] is None else format(c['value'], '.3g')} <= {c['limit']:g}"
                for c in f["criteria"]]
    return "\n".join([head, *(f"  {a:<{width}}  {b}" for a, b in rows), *verdicts,
                      f"soak {'PASS' if f['pass'] else 'FAIL'}"])
