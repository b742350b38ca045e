"""``sa-daemon bench loop``: the daemon's loop figures with the simulated user while the planner works.

The daemon runs in this process for ``--duration`` seconds (tasks back to back); the figures are
the control loop's rate and period error, overruns (periods > 1.5 x nominal), input-to-command latency
(a joystick sample's arrival to the arm command computed from it), and the resident memory of the
daemon and of its planner worker. With ``--subscribers N --stalled-subscribers M`` a separate process
holds N subscribers that read everything and M that never read (:mod:`.subscribers`); their figures
(messages received, state rate, longest gap, messages a stalled one held) join the daemon's, with the
daemon's ``pub_dropped`` (sends its PUB socket refused). With ``--foxglove`` the live view is on and one
Foxglove viewer in another process subscribes to all of it (:mod:`.viewer`; its figures join too).
:func:`run_daemon` and :func:`loop_figures` also serve ``bench soak``.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..config import Config
from ..runtime.launch import Launch, build_daemon


def rss_mb(pid: int | None = None) -> float:
    """Resident set size of ``pid`` (default: this process), MB, from ``/proc``; 0 if unknown."""
    try:
        for line in Path(f"/proc/{pid or os.getpid()}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    except (OSError, ValueError):
        pass
    return 0.0


@dataclass
class RssSample:
    """One memory sample of a bench run."""

    t_s: float  # since the daemon started, s
    daemon_mb: float  # RSS of the daemon's process, MB
    worker_mb: float  # RSS of the planner worker, MB (0 while there is none)
    worker_pid: int | None


@dataclass
class BenchRun:
    """What :func:`run_daemon` leaves: the stopped daemon, its wall time, RSS samples, subscriber figures."""

    daemon: Any
    duration_s: float
    rss: list[RssSample] = field(default_factory=list)
    subscribers: dict[str, Any] = field(default_factory=dict)
    viewer: dict[str, Any] | None = None  # the Foxglove viewer's figures, with the live view on


def run_daemon(cfg: Config, launch: Launch, subscribers: int = 0, stalled_subscribers: int = 0,
               sample_every_s: float = 1.0) -> BenchRun:
    """Run the daemon ``cfg`` and ``launch`` describe in this process for ``launch.duration_s`` s (give
    ``exit_when_done=False`` for tasks back to back), sampling RSS every ``sample_every_s`` s, with
    ``subscribers`` reading and ``stalled_subscribers`` never-reading subscribers in another process
    (see :mod:`.subscribers`)."""
    import asyncio

    from ..runtime.rate import new_event_loop
    from .subscribers import SubscriberSwarm
    from .viewer import FoxgloveViewer

    daemon = build_daemon(cfg, launch)
    run = BenchRun(daemon, 0.0)
    swarm = (SubscriberSwarm(daemon.opts.pub, subscribers, stalled_subscribers)
             if subscribers or stalled_subscribers else None)

    async def sample() -> None:
        while True:
            w = daemon.worker
            pid = w.pid if w is not None and w.pid else None
            run.rss.append(RssSample(round(daemon.now(), 3), rss_mb(), rss_mb(pid) if pid else 0.0, pid))
            await asyncio.sleep(sample_every_s)

    async def view() -> None:
        """With the live view on: one Foxglove viewer subscribed to everything, once the server is up."""
        while daemon.live is None:
            await asyncio.sleep(0.05)
        viewer = FoxgloveViewer(daemon.live.url)
        await asyncio.get_running_loop().run_in_executor(None, viewer.start)
        try:
            await asyncio.Event().wait()
        finally:
            run.viewer = viewer.stop()

    async def main() -> int:
        s = asyncio.create_task(sample())
        v = asyncio.create_task(view()) if cfg.foxglove.enabled else None
        try:
            return await daemon.run()
        finally:
            s.cancel()
            if v is not None:
                v.cancel()
                await asyncio.gather(v, return_exceptions=True)

    if swarm is not None:
        swarm.start()
    loop = new_event_loop()
    t0 = time.monotonic()
    try:
        loop.run_until_complete(main())
    finally:
        loop.close()
        run.duration_s = time.monotonic() - t0
        if swarm is not None:
            run.subscribers = swarm.stop()
    return run


def loop_figures(run: BenchRun) -> dict[str, Any]:
    """The figures of a finished :class:`BenchRun` (see module doc)."""
    daemon = run.daemon
    figs = daemon.loop_figures()
    control = daemon.rates["control"]
    publish = daemon.rates.get("publish")
    return {
        "duration_s": round(run.duration_s, 3),
        "arm": daemon.opts.arm,
        "method": daemon.method,
        "control_hz_nominal": 1.0 / control.dt,
        "rate_hz": figs.get("rate_hz", 0.0),
        "period_err_ms_p50": figs.get("period_err_ms_p50", 0.0),
        "period_err_ms_p99": figs.get("period_err_ms_p99", 0.0),
        "period_err_ms_max": figs.get("period_err_ms_max", 0.0),
        "overrun_fraction": figs.get("overrun_fraction", 0.0),
        "overruns": control.stats.overruns,
        "control_ticks": control.stats.ticks,
        "input_to_command_ms_p50": figs["input_to_command_ms_p50"],
        "input_to_command_ms_p99": figs["input_to_command_ms_p99"],
        "control_work_ms_p50": figs["control_work_ms_p50"],
        "control_work_ms_p99": figs["control_work_ms_p99"],
        "rss_mb": rss_mb(),
        "worker_rss_mb": max((s.worker_mb for s in run.rss), default=0.0),
        "plans": figs["plans"],
        "planner_restarts": figs["planner_restarts"],
        "tasks_done": len(figs["tasks_done"]),
        "tasks_succeeded": sum(1 for d in figs["tasks_done"] if d["success"]),
        # One state message per publish tick once running (the tick count starts at READY).
        "state_messages_published": publish.stats.ticks if publish is not None else 0,
        "pub_dropped": daemon.server.dropped if daemon.server is not None else 0,
        "subscribers": run.subscribers,
        "foxglove": run.viewer,
        "loops": figs["loops"],
    }


def run_loop_bench(cfg: Config, launch: Launch, subscribers: int = 0, stalled_subscribers: int = 0
                   ) -> dict[str, Any]:
    """Run the daemon for ``launch.duration_s`` s and return the figures (see module doc)."""
    return loop_figures(run_daemon(cfg, launch, subscribers, stalled_subscribers))


def format_loop(f: dict[str, Any]) -> str:
    """The figures as a short table, with the issue's targets."""
    rows = [
        ("control rate", f"{f['rate_hz']:.2f} Hz", f"{f['control_hz_nominal']:.0f} Hz"),
        ("period error p50", f"{f['period_err_ms_p50']:.3f} ms", ""),
        ("period error p99", f"{f['period_err_ms_p99']:.3f} ms", "<= 1 ms"),
        ("overruns (> 1.5 T)", f"{100 * f['overrun_fraction']:.3f} %", "< 0.1 %"),
        ("input -> command p50", f"{f['input_to_command_ms_p50']:.2f} ms", ""),
        ("input -> command p99", f"{f['input_to_command_ms_p99']:.2f} ms", "<= 12 ms"),
        ("control tick work p99", f"{f['control_work_ms_p99']:.3f} ms", ""),
        ("daemon RSS", f"{f['rss_mb']:.0f} MB", "<= 300 MB"),
        ("planner worker RSS", f"{f['worker_rss_mb']:.0f} MB", "<= 300 MB"),
        ("plans / restarts", f"{f['plans']} / {f['planner_restarts']}", ""),
        ("tasks done / succeeded", f"{f['tasks_done']} / {f['tasks_succeeded']}", ""),
        ("states published / PUB sends refused", f"{f['state_messages_published']} / {f['pub_dropped']}", ""),
        *subscriber_rows(f["subscribers"]),
        *viewer_rows(f.get("foxglove")),
    ]
    w = max(len(r[0]) for r in rows)
    head = f"bench loop: {f['arm']} arm, {f['method']}, {f['duration_s']:.1f} s"
    return "\n".join([head] + [f"  {a:<{w}}  {b:>14}  {c}" for a, b, c in rows])


def subscriber_rows(sub: dict[str, Any]) -> list[tuple[str, str, str]]:
    """Table rows of the subscriber load's figures (none without a load)."""
    if not sub:
        return []
    if "error" in sub:
        return [("subscribers", sub["error"], "")]
    return [
        ("subscribers reading / stalled", f"{sub['subscribers']} / {sub['stalled_subscribers']}", ""),
        ("reader messages min / max", f"{sub['reader_messages_min']} / {sub['reader_messages_max']}", ""),
        ("reader state rate min", f"{sub['reader_state_hz_min']:.2f} Hz", ""),
        ("reader state gap max", f"{sub['reader_state_gap_ms_max']:.1f} ms", ""),
        ("stalled: messages held", " ".join(str(n) for n in sub["stalled_messages_held"]) or "-", ""),
    ]


def viewer_rows(v: dict[str, Any] | None) -> list[tuple[str, str, str]]:
    """Table rows of the Foxglove viewer's figures (none with the live view off)."""
    if v is None:
        return []
    if "error" in v:
        return [("foxglove viewer", v["error"], "")]
    msgs, size = v["messages"], v["bytes"]
    return [
        ("foxglove messages /scene /belief /log", " / ".join(str(msgs.get(t, 0)) for t in ("/scene", "/belief", "/log")), ""),
        ("foxglove kB received", f"{sum(size.values()) / 1e3:.0f} kB", ""),
        ("foxglove belief gap max", f"{v['belief_gap_ms_max']:.1f} ms", ""),
    ]
