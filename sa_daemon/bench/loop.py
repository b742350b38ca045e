"""``sa-daemon bench loop``: the daemon's loop figures with the simulated user while the planner works.

The daemon runs in this process for ``--duration`` seconds (tasks back to back); the figures are
the control loop's rate and period error, overruns (periods > 1.5 x nominal), input-to-command latency
(a joystick sample's arrival to the arm command computed from it), and the resident memory of the
daemon and of its planner worker.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path
from typing import Any


def rss_mb(pid: int | None = None) -> float:
    """Resident set size of ``pid`` (default: this process), MB, from ``/proc``; 0 if unknown."""
    try:
        for line in Path(f"/proc/{pid or os.getpid()}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    except (OSError, ValueError):
        pass
    return 0.0


def run_loop_bench(args: argparse.Namespace) -> dict[str, Any]:
    """Run the daemon for ``args.duration`` s and return the figures (see module doc)."""
    from ..runtime.rate import new_event_loop
    from ..runtime.verbs import build_daemon

    daemon = build_daemon(args)
    daemon.opts.exit_when_done = False
    worker_rss: list[float] = []

    async def main() -> int:
        import asyncio

        async def sample() -> None:
            while True:
                await asyncio.sleep(1.0)
                if daemon.worker is not None and daemon.worker.pid:
                    worker_rss.append(rss_mb(daemon.worker.pid))

        s = asyncio.create_task(sample())
        try:
            return await daemon.run()
        finally:
            s.cancel()

    loop = new_event_loop()
    t0 = time.monotonic()
    try:
        loop.run_until_complete(main())
    finally:
        loop.close()
    figs = daemon.loop_figures()
    nominal = daemon.rates["control"].dt
    return {
        "duration_s": round(time.monotonic() - t0, 3),
        "arm": daemon.opts.arm,
        "method": daemon.method,
        "control_hz_nominal": 1.0 / nominal,
        "rate_hz": figs.get("rate_hz", 0.0),
        "period_err_ms_p50": figs.get("period_err_ms_p50", 0.0),
        "period_err_ms_p99": figs.get("period_err_ms_p99", 0.0),
        "period_err_ms_max": figs.get("period_err_ms_max", 0.0),
        "overrun_fraction": figs.get("overrun_fraction", 0.0),
        "input_to_command_ms_p50": figs["input_to_command_ms_p50"],
        "input_to_command_ms_p99": figs["input_to_command_ms_p99"],
        "control_work_ms_p50": figs["control_work_ms_p50"],
        "control_work_ms_p99": figs["control_work_ms_p99"],
        "rss_mb": rss_mb(),
        "worker_rss_mb": max(worker_rss) if worker_rss else 0.0,
        "plans": figs["plans"],
        "planner_restarts": figs["planner_restarts"],
        "tasks_done": len(figs["tasks_done"]),
        "tasks_succeeded": sum(1 for d in figs["tasks_done"] if d["success"]),
        "loops": figs["loops"],
    }


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
    ]
    w = max(len(r[0]) for r in rows)
    head = f"bench loop: {f['arm']} arm, {f['method']}, {f['duration_s']:.1f} s"
    return "\n".join([head] + [f"  {a:<{w}}  {b:>14}  {c}" for a, b, c in rows])
