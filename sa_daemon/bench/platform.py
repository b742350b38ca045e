"""The machine's own stalls during a bench run, with their times: was an overrun the daemon's?

A control period that overruns has two possible causes: the daemon (work on the event loop, a lock, a
blocking call) or the machine (a virtual CPU paused by the hypervisor, a long interrupt). Only the
first is the daemon's to fix. The probe tells them apart. Beside the daemon it runs one process per CPU,
pinned to that CPU, under ``SCHED_FIFO``. Each process does nothing but sleep to an absolute 1 ms grid
and note every wake-up later than ``threshold_s``: a *stall*, with the ``time.monotonic`` instant it
ended. An overrun whose delay overlaps a stall happened while the machine itself was not running
threads on time.

Why not ``cyclictest`` (rt-tests, the standard latency probe, recommended in the README to qualify a
computer): it reports counts and maxima, not when the late wake-ups happened, and the attribution needs
the instants. The probe is Python, so each wake-up also costs an interpreter's few tens of us; the
threshold is milliseconds (half a control period by default).
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

#: The probe's real-time priority: above every normal thread (it must see the machine, not the load),
#: the lowest real-time level, so a real-time daemon loop (``runtime.realtime_priority``) comes first.
PRIORITY = 1
#: Stalls each probe process keeps (the first ones; later ones are only counted).
MAX_STALLS = 10000


@dataclass(frozen=True)
class Stall:
    """A wake-up on ``cpu`` that came ``late_s`` late and happened at ``end`` (``time.monotonic`` s):
    the machine ran nothing of the probe's from ``end - late_s`` to ``end``."""

    cpu: int
    end: float
    late_s: float

    def overlaps(self, start: float, stop: float) -> bool:
        return self.end - self.late_s <= stop and self.end >= start

    def as_row(self) -> list[float]:
        """``[cpu, end (s), late (ms)]``, for JSON."""
        return [self.cpu, round(self.end, 4), round(self.late_s * 1e3, 2)]


@dataclass(frozen=True)
class PlatformLatency:
    """What the probe measured: per CPU, wake-ups, the worst lateness (ms) and the number of stalls."""

    threshold_ms: float
    cpus: list[int]
    wakeups: list[int]
    max_ms: list[float]
    late: list[int]
    stalls: list[Stall] = field(repr=False)

    @property
    def late_total(self) -> int:
        return sum(self.late)

    def during_stall(self, overrun_end: float, lateness_s: float, slack_s: float = 0.002) -> Stall | None:
        """The stall that overlaps an overrun: a tick that ended at ``overrun_end`` more than
        ``lateness_s`` late was held up somewhere in ``[overrun_end - lateness_s, overrun_end]``
        (``slack_s`` covers the probe's 1 ms grid and the tick's own work)."""
        hits = [s for s in self.stalls if s.overlaps(overrun_end - lateness_s - slack_s, overrun_end + slack_s)]
        return max(hits, key=lambda s: s.late_s) if hits else None

    def as_dict(self) -> dict[str, Any]:
        return {"probe": "pinned SCHED_FIFO sleeper per CPU, 1 ms grid", "threshold_ms": self.threshold_ms,
                "cpus": self.cpus, "wakeups": self.wakeups, "max_ms": self.max_ms, "late": self.late,
                "late_total": self.late_total,
                "stalls": [s.as_row() for s in self.stalls]}


class PlatformProbe:
    """The probe processes of one bench run: :meth:`start`, run the bench, :meth:`stop`.

    ``unavailable`` says why there is no result (a real-time priority needs root or ``LimitRTPRIO``);
    the bench then runs without one.
    """

    def __init__(self, threshold_s: float, interval_s: float = 1e-3) -> None:
        self.threshold_s = threshold_s
        self.interval_s = interval_s
        self.unavailable: str | None = None
        self._dir: tempfile.TemporaryDirectory[str] | None = None
        self._procs: list[tuple[int, subprocess.Popen[bytes], Path]] = []

    def start(self) -> None:
        self._dir = tempfile.TemporaryDirectory(prefix="sa-probe-")
        for cpu in sorted(os.sched_getaffinity(0)):
            out = Path(self._dir.name) / f"cpu{cpu}.json"
            cmd = [sys.executable, "-m", __name__, "--cpu", str(cpu), "--interval", str(self.interval_s),
                   "--threshold", str(self.threshold_s), "--out", str(out)]
            self._procs.append((cpu, subprocess.Popen(cmd, stderr=subprocess.PIPE), out))

    def stop(self, timeout_s: float = 10.0) -> PlatformLatency | None:
        """Stop the probes and gather what they measured (``None``, with ``unavailable`` set, on failure)."""
        results, errors = [], []
        for cpu, proc, out in self._procs:
            if proc.poll() is None:
                proc.send_signal(signal.SIGTERM)
            try:
                _, err = proc.communicate(timeout=timeout_s)
            except subprocess.TimeoutExpired:
                proc.kill()
                _, err = proc.communicate()
            if proc.returncode == 0 and out.exists():
                results.append(json.loads(out.read_text()))
            else:
                lines = err.decode(errors="replace").strip().splitlines()
                errors.append(f"cpu {cpu}: {lines[-1][:200] if lines else f'exit {proc.returncode}'}")
        self._procs = []
        if self._dir is not None:
            self._dir.cleanup()
            self._dir = None
        if errors or not results:
            self.unavailable = "probe failed: " + ("; ".join(errors) or "no probe ran")
            return None
        return PlatformLatency(
            threshold_ms=self.threshold_s * 1e3,
            cpus=[r["cpu"] for r in results],
            wakeups=[r["wakeups"] for r in results],
            max_ms=[r["max_ms"] for r in results],
            late=[r["late"] for r in results],
            stalls=sorted((Stall(r["cpu"], end, late) for r in results for end, late in r["stalls"]),
                          key=lambda s: s.end),
        )


def _probe(cpu: int, interval_s: float, threshold_s: float, out: Path) -> int:
    """One probe process: pinned to ``cpu`` under SCHED_FIFO, until SIGTERM; writes ``out`` (JSON)."""
    os.sched_setaffinity(0, {cpu})
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(PRIORITY))
    except OSError as e:  # a normal-priority probe would measure the load, not the machine
        print(f"SCHED_FIFO refused ({e.strerror or e}): needs root or LimitRTPRIO", file=sys.stderr)
        return 1
    stop = []
    signal.signal(signal.SIGTERM, lambda *_: stop.append(True))
    wakeups, late, worst, stalls = 0, 0, 0.0, []
    due = time.monotonic()
    while not stop:
        due += interval_s
        wait = due - time.monotonic()
        if wait > 0:
            time.sleep(wait)
        now = time.monotonic()
        lateness = now - due
        wakeups += 1
        worst = max(worst, lateness)
        if lateness > threshold_s:
            late += 1
            if len(stalls) < MAX_STALLS:
                stalls.append((now, lateness))
        if lateness > interval_s:
            due = now  # a stall is not made up for with a burst of wake-ups
    out.write_text(json.dumps({"cpu": cpu, "wakeups": wakeups, "max_ms": worst * 1e3, "late": late,
                               "stalls": stalls}))
    return 0


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=_probe.__doc__)
    p.add_argument("--cpu", type=int, required=True)
    p.add_argument("--interval", type=float, default=1e-3, help="wake-up grid (s)")
    p.add_argument("--threshold", type=float, required=True, help="a wake-up later than this is a stall (s)")
    p.add_argument("--out", type=Path, required=True)
    a = p.parse_args(argv)
    return _probe(a.cpu, a.interval, a.threshold, a.out)


if __name__ == "__main__":
    sys.exit(main())
