"""``sa-daemon run``: one asyncio process of fixed-rate loops around the shared-autonomy controller.

The :class:`~..control.controller.Controller` computes; this module does the I/O and keeps time. Loops
(rates in ``[runtime]``), all on one event loop, none of them waiting on another:

* **input** (``belief_hz``) - the simulated user moves its stick (``simtasks.py``), or the evdev reader's
  held state is current; then the controller's belief update and the question timeout;
* **planner** (``planner.period_s``) - sends the controller's snapshot to the worker process and
  supervises it (late, hung, dead: restart); rule-based methods need no worker;
* **control** (``control_hz``) - reads the arm, runs the controller's tick (blend and safety pipeline),
  commands the arm, records, and feeds the watchdog;
* **publish** (``publish_hz``) - the ``state`` message on the PUB socket;
* **commands** - the command socket (``commands.py``), at most ``zmq.max_requests_per_tick`` per control
  period (a flood waits in ZeroMQ's queue instead of taking the event loop).

CPU-heavy work (planning) runs in the worker process; blocking calls (speech, SDK, disk) run in threads
owned by their modules. A tick's own work is small (a belief update is ~0.1 ms, a control tick ~0.2 ms)
and is measured by ``sa-daemon bench loop``. The daemon's clock is ``time.monotonic()``.
"""

from __future__ import annotations

import asyncio
import gc
import logging
import signal
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from ..arm.base import Arm, ArmState
from ..arm.factory import make_arm
from ..config import Config
from ..control.controller import Controller
from ..io.notify import Notifier
from ..io.protocol import TOPIC_EVENT, TOPIC_STATE
from ..io.recorder import Recorder
from ..io.security import server_curve
from ..io.server import ZmqServer
from ..model.actions import Mode
from ..model.methods import method_spec
from ..planner.worker import PlannerWorker, PlanReply, WorkerStatus
from . import commands, lifecycle, messages
from .asking import Asker
from .console import Console
from .options import RunOptions
from .rate import FixedRate, Ring
from .realtime import make_realtime, set_switch_interval
from .simtasks import SimTasks
from .view import View

if TYPE_CHECKING:
    from ..viz.feed import VizFeed
    from ..viz.live import LiveView

log = logging.getLogger("sa_daemon")

STATS_KEEP = 20000
"""Latency and tick-work samples kept for percentiles (200 s at 100 Hz)."""
STOP_WAIT_S = 0.1
"""How long a stop waits for a velocity command already in the arm driver's hands to be answered (s)."""


class Daemon:
    """The running daemon. ``await run()`` returns the exit code (0 on a clean stop)."""

    def __init__(self, cfg: Config, opts: RunOptions, arm_factory: Callable[[], Arm] | None = None) -> None:
        self.cfg, self.opts = cfg, opts
        # Before anything starts: a non-loopback command endpoint without CURVE, or a missing key file,
        # is a ConfigError naming the key (exit 2), never a half-started daemon.
        self.curve = server_curve(cfg.zmq, opts.cmd)
        self.ctl = Controller(cfg, opts.scene.goals, opts.method, 1.0 / cfg.runtime.control_hz)
        self.view = View(self)
        self.asker = Asker(cfg, self.ctl, self.event)
        self._arm_factory = arm_factory or (lambda: make_arm(opts.arm, opts.scene, cfg))
        self.arm: Arm | None = None
        self.arm_state: ArmState | None = None
        self.input_connected = opts.input == "sim"
        #: A scene sent with ``when = "next_task"`` (and the goals it dropped), applied at the next task.
        self.pending_scene: tuple[Any, list[dict[str, str]]] | None = None
        self.planner_status = WorkerStatus.IDLE
        self.last_plan_ms = 0.0
        self.plans = 0
        self.fault_reported: str | None = None
        self.t0 = time.monotonic()
        self.rates: dict[str, FixedRate] = {}
        self.latency_ms = Ring(STATS_KEEP)  # input sample -> arm command (ms)
        self.tick_work_ms = Ring(STATS_KEEP)  # control tick's own work (ms)
        self.events_sent = 0
        self.console = Console()  # event and progress lines (stderr), written off the event loop
        self.notifier = Notifier()
        self.realtime_refused: str | None = None  # why runtime.realtime_priority could not be applied
        self.sim: SimTasks | None = None
        self.joystick: Any = None
        self.server: ZmqServer | None = None
        self.worker: PlannerWorker | None = None
        self.recorder: Recorder | None = None
        self.live: LiveView | None = None  # the Foxglove live view (foxglove.enabled)
        self.viz: VizFeed | None = None  # Foxglove messages for the live view and the recording
        self._commanded_seq = 0
        self._heartbeat: dict[str, float] = {}
        self._stop_event: asyncio.Event | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._exit_code = 0
        self.record_error_reported = False
        self._last_watchdog = 0.0
        self._ready_sent = False  # WATCHDOG=1 only after READY=1

    # -- helpers -----------------------------------------------------------------------------------------

    def now(self) -> float:
        """Seconds since the daemon started."""
        return time.monotonic() - self.t0

    @property
    def method(self) -> str:
        return self.ctl.method

    @property
    def tasks_done(self) -> list[dict[str, Any]]:
        return self.sim.done if self.sim is not None else []

    @property
    def ready(self) -> bool:
        """READY has been announced: the planner worker, speech and voice are up and the loops run."""
        return self._ready_sent

    def event(self, kind: str, **fields: Any) -> None:
        """Publish and record an event (``docs/protocol.md`` lists the kinds)."""
        msg = {"t": round(self.now(), 4), "type": kind, **fields}
        if self.server is not None:
            self.server.publish(TOPIC_EVENT, msg)
        if self.recorder is not None:
            self.recorder.add("/event", msg)
        if self.viz is not None:
            self.viz.event(msg)
        self.events_sent += 1
        if self.opts.progress and kind not in ("plan",):
            detail = " ".join(f"{k}={v}" for k, v in fields.items())
            self.console.write(f"[{msg['t']:7.2f}] {kind} {detail}")

    # -- input (the joystick's callbacks; the simulated user calls them too) -----------------------------

    def set_axes(self, axes: np.ndarray, mono: float | None = None) -> None:
        """A new joystick sample (normalised axes); NaN/inf or a wrong shape is refused."""
        if not self.ctl.on_input(axes, time.monotonic() if mono is None else mono):
            self.event("input_refused", reason="joystick axes must be 3 finite numbers")

    def set_mode(self, mode: Mode) -> None:
        if self.ctl.set_mode(mode):
            self.event("mode", mode=self.ctl.mode.value)

    def on_button(self, button: Any) -> None:
        commands.on_button(self, button)

    def on_joystick_link(self, up: bool, text: str) -> None:
        self.input_connected = up
        if not up:
            self.ctl.lose_input()
        self.event("input_back" if up else "input_lost", detail=text)
        if not up and not self.ctl.stopped:
            # The person's stop button went with the joystick: a fault, and the stop latches (resume once
            # it is back).
            self.event("fault", source="joystick", detail=f"{text}: the stop button is not available")
            commands.stop(self, "joystick_lost")

    def apply_scene(self, scene: Any, dropped: list[dict[str, str]]) -> None:
        """Run on ``scene`` from now on (``commands.set_scene``): belief, questions and plans start over on
        its goals; a simulated arm is rebuilt with its objects (the real arm stays where it is)."""
        self.opts.scene = scene
        self.pending_scene = None
        if self.arm is not None and not self.arm.realtime:
            self.arm.close()
            self.arm = self._arm_factory()
            self.arm_state = self.arm.read()
            self.ctl.use_arm(self.arm.kinematics)
        if self.sim is not None:
            self.sim.sim.scene = scene
        had_question = self.ctl.question is not None
        self.ctl.new_goals(scene.goals)
        if had_question:
            self.asker.cleared()
        if self.viz is not None:
            self.viz.new_scene(messages.scene(self.view))
        self.event("scene", name=scene.name, objects=[o.name for o in scene.objects], targets=list(scene.targets),
                   dropped=dropped)

    def reconfigure(self, cfg: Config) -> None:
        """A person's profile from now on (``commands.set_profile``): the controller, the questions and
        answers, the speech, and a planner worker planning with the new assistance level."""
        log.info("reconfigured: %s", self.opts.profile)
        self.cfg = cfg
        self.ctl.reconfigure(cfg)
        self.asker.reconfigure(cfg)
        if self.worker is not None:
            old = self.worker.pid
            self.worker.reconfigure(cfg.model_dump(mode="json"))
            self.event("planner_restart", reason="profile switched", old_pid=old, pid=self.worker.pid)

    def set_gripper(self, closed: bool) -> None:
        if self.arm is None:
            return
        self.arm.command_gripper(closed)
        self.ctl.set_gripper(closed)
        self.event("gripper", closed=closed)

    def reset_arm(self) -> None:
        """Back to the start pose for a new task: reset the arm, or rebuild one that cannot reset."""
        if self.arm is None or not self.arm.reset():
            if self.arm is not None:
                self.arm.close()
            self.arm = self._arm_factory()
        self.arm_state = self.arm.read()

    def handle(self, req: Any) -> dict[str, Any]:
        return commands.handle(self, req)

    # -- loops -------------------------------------------------------------------------------------------

    async def _input_loop(self) -> None:
        rate = self.rates["belief"]
        while True:
            await rate.tick()
            mono = time.monotonic()
            self._heartbeat["belief"] = mono
            if self.arm_state is None:
                continue
            if self.sim is not None:
                self.sim.tick(mono)
            elif self.joystick is not None and self.input_connected:
                self.ctl.hold_input(mono)  # the kernel reports changes only: the held state is current
            self.ctl.update_belief(self.arm_state.pose, mono)
            self.asker.expire(mono)

    async def _planner_loop(self) -> None:
        rate, cfg, ctl = self.rates["planner"], self.cfg, self.ctl
        while True:
            await rate.tick()
            mono = time.monotonic()
            self._heartbeat["planner"] = mono
            if not method_spec(ctl.method).planned:
                self.planner_status = WorkerStatus.IDLE
                ctl.adopt_fixed()
                continue
            w = self.worker
            assert w is not None
            if not w.alive:
                self._restart_worker("worker died")
            elif not w.ready:
                if mono - w.started_at > cfg.runtime.worker_start_timeout_s:
                    self._restart_worker("worker did not start")
            elif w.in_flight is not None:
                age = mono - w.in_flight[1]
                if age > cfg.planner.budget_s + cfg.runtime.worker_hang_s:
                    self._restart_worker(f"no plan for {age:.2f} s")
                elif age > cfg.planner.period_s and self.planner_status is not WorkerStatus.LATE:
                    self.planner_status = WorkerStatus.LATE
                    self.event("planner_late", waited_s=round(age, 3))
            elif self.arm_state is not None:
                snap = ctl.snapshot(self.arm_state.pose, cfg.planner.budget_s)
                if snap is not None:
                    w.request(snap)

    def _on_plan(self, reply: PlanReply | str) -> None:
        if isinstance(reply, str):
            self.planner_status = WorkerStatus.FAILED
            self.ctl.drop_plan()
            self.event("planner_error", error=reply)
            return
        self.plans += 1
        self.last_plan_ms = reply.round_trip_ms
        self.planner_status = WorkerStatus.OK
        q = self.ctl.accept_plan(reply.snapshot, reply.result, time.monotonic())
        if q is not None:
            self.asker.asked(q)

    def _restart_worker(self, reason: str) -> None:
        assert self.worker is not None
        old = self.worker.pid
        self.planner_status = WorkerStatus.RESTARTING
        self.ctl.drop_plan()
        self.worker.restart()
        self.event("planner_restart", reason=reason, old_pid=old, pid=self.worker.pid)

    async def _control_loop(self) -> None:
        rate = self.rates["control"]
        while True:
            mono = await rate.tick()
            self._heartbeat["control"] = mono
            self._control_tick(mono, rate.dt)
            self.tick_work_ms.append((time.monotonic() - mono) * 1e3)

    def _control_tick(self, mono: float, dt: float) -> None:
        arm, ctl = self.arm, self.ctl
        assert arm is not None
        state = arm.read()
        self.arm_state = state
        if state.fault and state.fault != self.fault_reported:
            self.fault_reported = state.fault
            self.event("fault", source="arm", detail=state.fault)
        b, withdrawn = ctl.belief, (ctl.yes_withdrawn, ctl.no_withdrawn)
        tick = ctl.tick(state, mono)
        if ctl.yes_withdrawn > withdrawn[0]:
            self.event("yes_withdrawn", goal=b.confirmed)
        if ctl.no_withdrawn > withdrawn[1]:
            self.event("no_withdrawn", goals=sorted(b.ruled_out))
        if tick.error is not None:
            self.event("fault", source="command", detail=tick.error)
        arm.command_twist(tick.safety.twist)
        sent = time.monotonic()
        if tick.fresh and ctl.input_seq != self._commanded_seq:
            self._commanded_seq = ctl.input_seq
            self.latency_ms.append((sent - ctl.t_input) * 1e3)
        if not arm.realtime:
            arm.step(dt)
        if self.recorder is not None:
            self.recorder.add("/state", messages.record_state(self.view))
        self._watchdog(sent)

    def _watchdog(self, mono: float) -> None:
        n = self.notifier
        if not self._ready_sent or n.watchdog_interval_s is None or mono - self._last_watchdog < min(n.watchdog_interval_s, 1.0):
            return
        # Healthy: every loop ticked within the last second (a stuck loop starves the watchdog).
        if all(mono - self._heartbeat.get(k, 0.0) < 1.0 for k in ("control", "belief", "planner", "publish")):
            n.notify("WATCHDOG=1")
            self._last_watchdog = mono

    async def _publish_loop(self) -> None:
        rate = self.rates["publish"]
        last_progress = 0.0
        while True:
            mono = await rate.tick()
            self._heartbeat["publish"] = mono
            if self.arm_state is not None and (self.server is not None or self.viz is not None):
                state = messages.state_message(self.view)
                if self.server is not None:
                    self.server.publish(TOPIC_STATE, state)
                if self.viz is not None:
                    self.viz.state(state)
            if self.opts.progress and mono - last_progress >= 1.0 and self.arm_state is not None:
                last_progress = mono
                self.console.write(messages.progress_line(self.view))

    # -- lifecycle (lifecycle.py starts and stops the components) ----------------------------------------

    def request_stop(self, reason: str) -> None:
        if self._stop_event is not None and not self._stop_event.is_set():
            self.ctl.stop()  # from now on every control tick commands zero, until the arm closes
            # A moving command not yet sent is dropped, one in flight waited for.
            if self.arm is not None and not self.arm.halt(STOP_WAIT_S):
                log.warning("stopping: a velocity command was still in flight to the arm after %.2f s; "
                            "the zero follows it", STOP_WAIT_S)
            self.event("shutdown", reason=reason)
            self._stop_event.set()

    def _on_worker_exit(self) -> None:
        self.event("planner_exit", pid=self.worker.pid if self.worker else None)

    def _start_components(self) -> None:
        lifecycle.start_components(self)

    async def run(self) -> int:
        """Start everything, run until stopped (signal, ``--duration``, tasks done), stop safely."""
        self._loop = asyncio.get_running_loop()
        self._stop_event = asyncio.Event()
        opts = self.opts
        tasks: list[asyncio.Task] = []
        # Before any helper thread starts: the speech engine's start-up imports alone hold the lock for
        # 5 ms at a time under the default interval.
        switch_interval = set_switch_interval(self.cfg.runtime.gil_switch_interval_s)
        try:
            self._start_components()
            for sig in (signal.SIGTERM, signal.SIGINT):
                self._loop.add_signal_handler(sig, self.request_stop, signal.Signals(sig).name)
            tasks = [
                asyncio.create_task(self._control_loop(), name="control"),
                asyncio.create_task(self._input_loop(), name="input"),
                asyncio.create_task(self._planner_loop(), name="planner"),
                asyncio.create_task(self._publish_loop(), name="publish"),
                asyncio.create_task(self.server.serve(  # type: ignore[union-attr]
                    self.handle, self.cfg.zmq.max_requests_per_tick, 1.0 / self.cfg.runtime.control_hz),
                    name="commands"),
            ]
            if self.joystick is not None:
                tasks.append(asyncio.create_task(self.joystick.run(), name="joystick"))
            await lifecycle.wait_ready(self)
            # Everything long-lived now exists: move it out of the collector's sight so that a full
            # collection never has to walk it during a control tick.
            gc.collect()
            gc.freeze()
            self.realtime_refused = make_realtime(self.cfg.runtime.realtime_priority)
            if self.realtime_refused is not None:
                log.warning("%s", self.realtime_refused)
            for r in self.rates.values():  # loop figures are of the running daemon, not its start-up
                r.reset_stats()
            self.latency_ms.clear()
            self.tick_work_ms.clear()
            self._ready_sent = True
            self.notifier.notify("READY=1", f"STATUS=running {opts.arm} arm, {opts.input} input, {self.method}")
            self.event("ready", arm=self.arm.name if self.arm else opts.arm, input=opts.input, method=self.method,
                       scene=opts.scene.name,
                       pub=self.server.pub_endpoint, cmd=self.server.cmd_endpoint,  # type: ignore[union-attr]
                       foxglove=self.live.url if self.live is not None else None)
            if opts.profile is not None:
                log.info("profile %s (%s): %s", opts.profile["name"], opts.profile["path"], ", ".join(opts.profile["keys"]))
                self.event("profile", **opts.profile)
            if self.sim is not None and self.arm_state is not None:
                self.sim.begin()  # the simulated user's first task starts with the ready daemon (else at its first tick)
            waiters = [asyncio.create_task(self._stop_event.wait())] + tasks
            timeout = opts.duration_s
            done, _ = await asyncio.wait(waiters, timeout=timeout, return_when=asyncio.FIRST_COMPLETED)
            for t in done:
                if t is not waiters[0] and t.exception() is not None:
                    log.error("loop %s failed: %r", t.get_name(), t.exception())
                    self.event("fault", source=t.get_name(), detail=repr(t.exception()))
                    self._exit_code = 1
            waiters[0].cancel()
            if not done:
                self.event("shutdown", reason=f"duration {timeout} s reached")
        finally:
            await lifecycle.shutdown(self, tasks, self._exit_code)
            set_switch_interval(switch_interval)
        return self._exit_code

    def loop_figures(self) -> dict[str, Any]:
        """Loop statistics for ``bench loop`` and the closing log line."""
        return self.view.loop_figures()
