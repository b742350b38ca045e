"""A read-only view of a running daemon: what its outgoing messages (``messages.py``) may read.

The view has no setters and hands out values, dictionaries and the controller's read-only state, never
the daemon's components; the messages cannot change what they describe.
"""

from __future__ import annotations

import os
import sys
import time
from typing import TYPE_CHECKING, Any

import numpy as np

from ..arm.base import ArmState
from ..control.outputs import Question, Tick
from ..model.actions import Action, Mode
from ..model.belief import Belief
from ..speech.speaker import question_text

if TYPE_CHECKING:
    from .daemon import Daemon


class View:
    """Read-only state of daemon ``d`` (times in s since the daemon started unless named)."""

    __slots__ = ("_d",)

    def __init__(self, d: Daemon) -> None:
        self._d = d

    # -- the controller ----------------------------------------------------------------------------------

    @property
    def t(self) -> float:
        return self._d.now()

    @property
    def belief(self) -> Belief:
        return self._d.ctl.belief

    @property
    def mode(self) -> Mode:
        return self._d.ctl.mode

    @property
    def action(self) -> Action:
        """The action applied now."""
        return self._d.ctl.current_action(time.monotonic())

    @property
    def question(self) -> Question | None:
        return self._d.ctl.question

    def question_text(self) -> str | None:
        q = self._d.ctl.question
        return question_text(q.target) if q is not None else None

    @property
    def tick(self) -> Tick:
        """The last control tick's command and safety result."""
        return self._d.ctl.last

    @property
    def user_twist(self) -> Any:
        """The user's twist (m/s, rad/s) of the last sample."""
        return self._d.ctl.user_twist

    @property
    def input_fresh(self) -> bool:
        return self._d.ctl.input_fresh(time.monotonic())

    @property
    def method(self) -> str:
        return self._d.ctl.method

    @property
    def assist(self) -> bool:
        return self._d.ctl.assist

    @property
    def stopped(self) -> bool:
        return self._d.ctl.stopped

    @property
    def stop_tested(self) -> bool:
        return self._d.ctl.stop_tested

    @property
    def third_answer(self) -> bool:
        return self._d.cfg.asking.third_answer

    @property
    def yielding(self) -> str | None:
        return self._d.ctl.yielding

    @property
    def profile(self) -> str | None:
        """The person's profile in force (its name), or ``None``."""
        p = self._d.opts.profile
        return None if p is None else p["name"]

    def profiles(self) -> list[str]:
        """The profiles ``set_profile`` can switch to: the names in ``profiles.dir``."""
        from pathlib import Path

        try:
            return sorted(p.stem for p in Path(self._d.cfg.profiles.dir).glob("*.toml"))
        except OSError:
            return []

    # -- the daemon --------------------------------------------------------------------------------------

    @property
    def scene(self) -> str:
        return self._d.opts.scene.name

    @property
    def scene_data(self) -> Any:
        """The running scene (objects, goals with their grasp poses): what the ``scene`` reply describes."""
        return self._d.opts.scene

    @property
    def input_backend(self) -> str:
        return self._d.opts.input

    @property
    def input_connected(self) -> bool:
        return self._d.input_connected

    @property
    def task(self) -> str | None:
        return self._d.sim.task if self._d.sim is not None else None

    @property
    def arm_name(self) -> str:
        d = self._d
        return d.arm.name if d.arm is not None else d.opts.arm

    @property
    def arm_state(self) -> ArmState | None:
        return self._d.arm_state

    def arm_status(self) -> dict[str, Any]:
        return self._d.arm.status() if self._d.arm is not None else {}

    def planner(self) -> dict[str, Any]:
        d = self._d
        w = d.worker
        return {
            "pid": w.pid if w is not None else None,
            "status": d.planner_status.value,
            "last_plan_ms": round(d.last_plan_ms, 3),
            "restarts": w.restarts if w is not None else 0,
            "plans": d.plans,
        }

    def control(self) -> dict[str, Any]:
        """The control loop's own timing counters since READY."""
        d = self._d
        r = d.rates.get("control")
        st = r.stats if r is not None else None
        return {
            "ticks": st.ticks if st is not None else 0,
            "overruns": st.overruns if st is not None else 0,
            "skipped": st.skipped if st is not None else 0,
            "realtime_priority": 0 if d.realtime_refused is not None else d.cfg.runtime.realtime_priority,
            "switch_interval_s": sys.getswitchinterval(),
        }

    def commands(self) -> dict[str, Any]:
        d = self._d
        s = d.server
        return {
            "requests": s.requests if s is not None else 0,
            "refused": s.refused if s is not None else 0,
            "deferred": s.deferred if s is not None else 0,
            "per_tick": d.cfg.zmq.max_requests_per_tick,
        }

    def record(self) -> dict[str, Any] | None:
        r = self._d.recorder
        if r is None:
            return None
        return {"path": str(r.path), "written": r.written, "flushed": r.flushed, "dropped": r.dropped,
                "error": r.error}

    def foxglove(self) -> dict[str, Any] | None:
        live = self._d.live
        if live is None:
            return None
        viz = self._d.viz
        return {"url": live.url, "sent": viz.sent if viz is not None else 0}

    def speech(self) -> dict[str, Any] | None:
        s = self._d.asker.speaker
        return s.status() if s is not None else None

    def answer_times(self) -> dict[str, Any]:
        return self._d.ctl.answer_time.summary()

    def voice(self) -> dict[str, Any] | None:
        v = self._d.asker.voice
        return v.status() if v is not None else None

    @property
    def pid(self) -> int:
        return os.getpid()

    def loop_figures(self) -> dict[str, Any]:
        """Loop statistics for ``bench loop`` and the closing log line."""
        d = self._d
        ctl = d.rates["control"].stats.summary() if "control" in d.rates else {}
        lat = d.latency_ms.values() if len(d.latency_ms) else np.zeros(1)
        work = d.tick_work_ms.values() if len(d.tick_work_ms) else np.zeros(1)
        return {
            **ctl,
            "input_to_command_ms_p50": float(np.percentile(lat, 50)),
            "input_to_command_ms_p99": float(np.percentile(lat, 99)),
            "control_work_ms_p50": float(np.percentile(work, 50)),
            "control_work_ms_p99": float(np.percentile(work, 99)),
            "loops": {k: r.stats.summary() for k, r in d.rates.items()},
            "plans": d.plans,
            "planner_restarts": d.worker.restarts if d.worker is not None else 0,
            "tasks_done": d.tasks_done,
        }
