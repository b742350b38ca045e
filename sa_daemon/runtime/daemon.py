"""``sa-daemon run``: one asyncio process with fixed-rate loops around the shared-autonomy model.

Loops (rates in ``[runtime]``), all on one event loop, none of them waiting on another:

* **input** (``belief_hz``) - the simulated user moves its stick, or the evdev reader's state is
  sampled; either way the sample is stamped ``t_input`` (fresh for ``safety.stale_command_s``);
* **belief** (``belief_hz``, right after the input sample) - MaxEnt IOC update and resampling;
* **planner** (``planner.period_s``) - sends a :class:`~..planner.snapshot.Snapshot` to the worker
  process and supervises it (late, hung, dead: restart); rule-based methods need no worker;
* **control** (``control_hz``) - recomputes the chosen action's twist from the current pose and
  joystick, blends, runs the safety pipeline, commands the arm, records, and feeds the watchdog;
* **publish** (``publish_hz``) - the ``state`` message on the PUB socket;
* **commands** - the command socket, answered as requests arrive, at most ``zmq.max_requests_per_tick``
  per control period (a flood waits in ZeroMQ's queue instead of taking the event loop).

CPU-heavy work (planning) runs in the worker process; blocking calls (speech, SDK, disk) run in
threads owned by their modules. A tick's own work is small (a belief update is ~0.1 ms, a control
tick ~0.2 ms) and is measured by ``sa-daemon bench loop``.
"""

from __future__ import annotations

import asyncio
import gc
import logging
import math
import signal
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..arm.base import Arm, ArmState
from ..arm.factory import make_arm
from ..arm.safety import SafetyPipeline, SafetyResult
from ..config import Config
from ..io.notify import Notifier
from ..io.protocol import TOPIC_EVENT, TOPIC_STATE, Request, RequestError
from ..io.recorder import Recorder
from ..io.security import server_curve
from ..io.server import ZmqServer
from ..planner.actions import NO_ASSIST, Action, ActionKind, Mode, axes_to_twist
from ..planner.belief import Belief
from ..planner.methods import method_spec
from ..planner.model import Command, SharedAutonomyModel
from ..planner.scene import Scene
from ..planner.snapshot import Snapshot
from ..planner.worker import PlannerWorker, PlanReply, WorkerStatus
from ..speech.speaker import (
    PLAYER,
    PLAYER_PACKAGE,
    Speaker,
    Spoken,
    echo_text,
    question_text,
)
from . import messages
from .console import Console
from .rate import FixedRate, Ring
from .realtime import make_realtime, set_switch_interval
from .siminput import SimInput

log = logging.getLogger("sa_daemon")

STATS_KEEP = 20000
"""Latency and tick-work samples kept for percentiles (200 s at 100 Hz)."""



@dataclass
class RunOptions:
    """What ``sa-daemon run`` was asked to do (CLI flags over config)."""

    scene: Scene
    arm: str = "kinematic"
    input: str = "sim"
    tasks: list[str] = field(default_factory=list)
    method: str = "policy"
    pub: str = "tcp://127.0.0.1:5555"
    cmd: str = "tcp://127.0.0.1:5556"
    duration_s: float | None = None
    record: str | None = None
    seed: int = 0
    progress: bool = False
    #: With the simulated user and no duration: stop once every task has been done once.
    exit_when_done: bool = True


@dataclass
class PendingQuestion:
    target: str
    text: str
    asked_at: float  # time.monotonic() s
    qid: int = 0  # numbers the questions, so that a late voice answer cannot answer the next one


class Daemon:
    """The running daemon. ``await run()`` returns the exit code (0 on a clean stop)."""

    def __init__(self, cfg: Config, opts: RunOptions, arm_factory: Callable[[], Arm] | None = None) -> None:
        self.cfg, self.opts = cfg, opts
        # Before anything starts: a non-loopback command endpoint without CURVE, or a missing key file,
        # is a ConfigError naming the key (exit 2), never a half-started daemon.
        self.curve = server_curve(cfg.zmq, opts.cmd)
        self.model = SharedAutonomyModel(cfg)
        self.method = opts.method
        self._arm_factory = arm_factory or (lambda: make_arm(opts.arm, opts.scene, cfg))
        self.arm: Arm | None = None
        self.arm_state: ArmState | None = None
        self.belief: Belief = self.model.initial_belief(opts.scene.goals)
        self.action: Action = NO_ASSIST
        self.action_goals = self.belief.goals
        self.action_until = 0.0  # a planned action expires then (time.monotonic s)
        self.asked: set[str] = set()
        self.question: PendingQuestion | None = None
        self.mode = Mode.TRANSLATION
        self.axes = np.zeros(3)
        self.t_input = -math.inf  # when the input backend last delivered a sample (monotonic s)
        self.input_seq = 0
        self._commanded_seq = 0
        self.input_connected = opts.input == "sim"
        self.assist = True
        self.gripper_closed = False
        self.command = Command(NO_ASSIST, np.zeros(6), np.zeros(6), False)
        self.safety_result = SafetyResult(np.zeros(6), ())
        self.planner_status = WorkerStatus.IDLE
        self.last_plan_ms = 0.0
        self.plans = 0
        self.fault_reported: str | None = None
        self.t0 = time.monotonic()
        self.rates: dict[str, FixedRate] = {}
        self.latency_ms = Ring(STATS_KEEP)  # input sample -> arm command (ms)
        self.tick_work_ms = Ring(STATS_KEEP)  # control tick's own work (ms)
        self.tasks_done: list[dict[str, Any]] = []
        self.events_sent = 0
        self._stop_event: asyncio.Event | None = None
        self._exit_code = 0
        self._last_watchdog = 0.0
        self._ready_sent = False  # WATCHDOG=1 only after READY=1
        self._heartbeat: dict[str, float] = {}
        self._record_error_reported = False
        self.console = Console()  # event and progress lines (stderr), written off the event loop
        self.realtime_refused: str | None = None  # why runtime.realtime_priority could not be applied
        self.sim: SimInput | None = None
        self.joystick: Any = None
        self.server: ZmqServer | None = None
        self.worker: PlannerWorker | None = None
        self.speaker: Speaker | None = None
        self.voice: Any = None  # speech.listener.VoiceListener when voice.enabled
        self._questions_asked = 0
        self.recorder: Recorder | None = None
        self.notifier = Notifier()
        self.safety: SafetyPipeline | None = None
        self._task_reset_at: float | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._plan_goals = self.belief.goals

    # -- helpers -----------------------------------------------------------------------------------------

    def now(self) -> float:
        """Seconds since the daemon started."""
        return time.monotonic() - self.t0

    @property
    def user_twist(self) -> np.ndarray:
        return axes_to_twist(self.axes, self.mode, self.cfg.input)

    def input_fresh(self, mono: float | None = None) -> bool:
        mono = time.monotonic() if mono is None else mono
        return mono - self.t_input <= self.cfg.safety.stale_command_s

    def event(self, kind: str, **fields: Any) -> None:
        """Publish and record an event (``docs/protocol.md`` lists the kinds)."""
        msg = {"t": round(self.now(), 4), "type": kind, **fields}
        if self.server is not None:
            self.server.publish(TOPIC_EVENT, msg)
        if self.recorder is not None:
            self.recorder.add("/event", msg)
        self.events_sent += 1
        if self.opts.progress and kind not in ("plan",):
            detail = " ".join(f"{k}={v}" for k, v in fields.items())
            self.console.write(f"[{msg['t']:7.2f}] {kind} {detail}")

    # -- input -------------------------------------------------------------------------------------------

    def set_axes(self, axes: np.ndarray, mono: float | None = None) -> None:
        """A new joystick sample (normalised axes); NaN/inf or a wrong shape is refused."""
        a = np.asarray(axes, dtype=float)
        if a.shape != (3,) or not np.all(np.isfinite(a)):
            self.event("input_refused", reason="joystick axes must be 3 finite numbers")
            return
        self.axes = np.clip(a, -1.0, 1.0)
        self.t_input = time.monotonic() if mono is None else mono
        self.input_seq += 1

    def set_mode(self, mode: Mode) -> None:
        if mode is not self.mode:
            self.mode = mode
            self.event("mode", mode=mode.value)

    def on_button(self, button: Any) -> None:
        """A joystick button press (see :class:`~..io.joystick.Button`)."""
        name = getattr(button, "value", str(button))
        if name == "mode":
            self.set_mode(Mode.ROTATION if self.mode is Mode.TRANSLATION else Mode.TRANSLATION)
        elif name == "gripper":
            self.set_gripper(not self.gripper_closed)
        elif name in ("yes", "no"):
            try:
                self.answer(name == "yes", source="button")
            except RequestError:
                pass
        elif name == "assist":
            self.assist = not self.assist
            self.event("assist", on=self.assist)
        elif name == "stop":
            self.stop_arm("button")

    def on_joystick_link(self, up: bool, text: str) -> None:
        self.input_connected = up
        if not up:
            # Stale at once (not a fresh zero sample): the safety pipeline zeroes the whole command at the
            # next control tick, assistance included, instead of ramping down or waiting for the timeout.
            self.axes = np.zeros(3)
            self.t_input = -math.inf
        self.event("input_back" if up else "input_lost", detail=text)

    def set_gripper(self, closed: bool) -> None:
        if self.arm is None:
            return
        self.arm.command_gripper(closed)
        self.gripper_closed = closed
        self.event("gripper", closed=closed)

    # -- questions ---------------------------------------------------------------------------------------

    def ask(self, target: str) -> None:
        text = question_text(target)
        self._questions_asked += 1
        self.question = PendingQuestion(target, text, time.monotonic(), self._questions_asked)
        self.asked.add(target)
        queued = self.speaker is not None and self.speaker.say(text)
        spoken = self.speaker.mode if queued else "unavailable"  # type: ignore[union-attr]
        self.event("question", goal=target, text=text, spoken=spoken)
        if not queued:
            self._listen(self.question)  # nothing will be said: listen at once

    def _clear_question(self) -> None:
        """The pending question is gone (answered, timed out, dropped): stop listening for it."""
        self.question = None
        if self.voice is not None:
            self.voice.mute()

    def answer(self, yes: bool, source: str, **detail: Any) -> None:
        """Apply a yes/no answer to the pending question; :class:`RequestError` if there is none.
        ``detail`` (a voice answer's ``confidence``) goes into the ``answer`` event."""
        q = self.question
        if q is None:
            raise RequestError("no question is pending")
        self.belief = self.model.update_answer(self.belief, q.target, yes)
        self._clear_question()
        self.action, self.action_until = NO_ASSIST, 0.0  # re-plan at once
        self.event("answer", goal=q.target, value="yes" if yes else "no", source=source,
                   after_s=round(time.monotonic() - q.asked_at, 3), **detail)

    def _on_spoken(self, s: Spoken) -> None:
        """(The speech thread.) An utterance finished."""
        loop = self._loop
        if loop is not None and not loop.is_closed():
            loop.call_soon_threadsafe(self._spoken, s)

    def _spoken(self, s: Spoken) -> None:
        self.event("spoken", text=s.text, outcome=s.outcome, wav=s.wav, played=s.played,
                   seconds=round(s.seconds, 3), error=s.error)
        q = self.question
        if q is not None and s.text == q.text and not (self.speaker and self.speaker.speaking):
            self._listen(q)  # the question has been said: its answer may come now

    # -- answers by voice (speech/listener.py) -----------------------------------------------------------

    def _listen(self, q: PendingQuestion) -> None:
        if self.voice is None or not self.voice.ready:
            return
        vc = self.cfg.voice
        t_open = time.monotonic() + vc.after_speech_s
        self.voice.listen(q.qid, t_open, t_open + vc.listen_s)
        self.event("listening", goal=q.target, for_s=vc.listen_s)

    def _on_heard(self, qid: int, heard: dict[str, Any], t_start: float, t_end: float) -> None:
        """The voice process recognised an utterance inside a listening window."""
        q = self.question
        value = heard.get("answer", "none")
        if q is None or q.qid != qid:
            reason = "no question pending"
        elif value not in ("yes", "no"):
            reason = heard.get("reason", "not a yes or no")
        elif heard["confidence"] < self.cfg.voice.min_confidence:
            reason = f"confidence below voice.min_confidence {self.cfg.voice.min_confidence:g}"
        else:
            reason = None
        self.event("heard", **heard, accepted=reason is None, reason=reason,
                   latency_s=round(time.monotonic() - t_end, 3))
        if reason is not None or q is None:
            return
        self.answer(value == "yes", source="voice", confidence=heard["confidence"])
        if self.cfg.voice.echo and self.speaker is not None:
            self.speaker.say(echo_text(value == "yes", q.target))

    def _on_voice_error(self, text: str) -> None:
        log.error("voice: %s", text)
        self.event("voice_unavailable", error=text)

    def _on_record_error(self, text: str) -> None:
        """(The recorder's writer thread.) A write failed, e.g. the disk is full: the recording has
        stopped; the daemon goes on controlling the arm and says so."""
        loop = self._loop
        if loop is not None and not loop.is_closed():
            loop.call_soon_threadsafe(self._record_failed, text)

    def _record_failed(self, text: str) -> None:
        if self._record_error_reported:
            return
        self._record_error_reported = True
        log.error("%s", text)
        self.event("fault", source="recorder", detail=text)

    # -- commands ----------------------------------------------------------------------------------------

    def stop_arm(self, source: str) -> None:
        assert self.safety is not None
        self.safety.stop()
        if self.arm is not None:
            self.arm.command_twist(np.zeros(6))
        self.event("stop", source=source)

    def handle(self, req: Request) -> dict[str, Any]:
        """Answer one validated command (``docs/protocol.md``)."""
        if req.cmd == "status":
            return messages.status(self)
        if req.cmd == "answer":
            self.answer(req.args["value"] == "yes", source="command")
            return {}
        if req.cmd == "stop":
            self.stop_arm("command")
            return {}
        if req.cmd == "resume":
            assert self.safety is not None
            if self.arm is not None:
                self.arm.reset_fault()
            self.safety.resume()
            self.fault_reported = None
            self.event("resume")
            return {}
        if req.cmd == "set_method":
            self.set_method(req.args["method"])
            return {"method": self.method}
        raise RequestError(f"unknown command {req.cmd!r}")

    def set_method(self, method: str) -> None:
        spec = method_spec(method)  # raises on an unknown name
        self.method = method
        self.action, self.action_until = NO_ASSIST, 0.0
        self._clear_question()
        if not spec.planned:
            self.planner_status = WorkerStatus.IDLE
        self.event("method", method=method)

    # -- planner -----------------------------------------------------------------------------------------

    def _on_plan(self, reply: PlanReply | str) -> None:
        mono = time.monotonic()
        if isinstance(reply, str):
            self.planner_status = WorkerStatus.FAILED
            self.action, self.action_until = NO_ASSIST, 0.0
            self.event("planner_error", error=reply)
            return
        self.plans += 1
        self.last_plan_ms = reply.round_trip_ms
        self.planner_status = WorkerStatus.OK
        if self.question is not None or not method_spec(self.method).planned:
            return  # a question arrived meanwhile, or the method changed: this plan is moot
        action = reply.result.action
        goals = self._plan_goals
        if action.kind is ActionKind.QUESTION:
            self.ask(str(action.target))
            return
        if goals is not self.belief.goals and self.arm_state is not None:
            action = self.model.remap_action(action, goals, self.belief.goals, self.arm_state.pose)
        self.action, self.action_goals = action, self.belief.goals
        # Valid until the next plan is due plus one period of grace (then no-assist).
        self.action_until = mono + 2 * self.cfg.planner.period_s

    def _on_worker_exit(self) -> None:
        self.event("planner_exit", pid=self.worker.pid if self.worker else None)

    async def _planner_loop(self) -> None:
        rate = self.rates["planner"]
        cfg = self.cfg
        while True:
            await rate.tick()
            self._heartbeat["planner"] = time.monotonic()
            spec = method_spec(self.method)
            if not spec.planned:
                self.planner_status = WorkerStatus.IDLE
                self.action = self.model.fixed_action(self.method, self.belief.goals, self.belief.probs)
                self.action_goals = self.belief.goals
                self.action_until = math.inf
                continue
            w = self.worker
            assert w is not None
            mono = time.monotonic()
            if not w.alive:
                self._restart_worker("worker died")
                continue
            if not w.ready:
                if mono - w.started_at > cfg.runtime.worker_start_timeout_s:
                    self._restart_worker("worker did not start")
                continue
            if w.in_flight is not None:
                age = mono - w.in_flight[1]
                if age > cfg.planner.budget_s + cfg.runtime.worker_hang_s:
                    self._restart_worker(f"no plan for {age:.2f} s")
                elif age > cfg.planner.period_s and self.planner_status is not WorkerStatus.LATE:
                    self.planner_status = WorkerStatus.LATE
                    self.event("planner_late", waited_s=round(age, 3))
                continue
            if self.question is not None or self.arm_state is None or self.gripper_closed:
                continue
            snap = Snapshot(
                self.belief.goals, self.belief.probs, self.arm_state.pose, self.user_twist, self.mode,
                frozenset(self.asked), self.method, budget_s=cfg.planner.budget_s,
            )
            self._plan_goals = self.belief.goals
            w.request(snap)

    def _restart_worker(self, reason: str) -> None:
        assert self.worker is not None
        old = self.worker.pid
        self.planner_status = WorkerStatus.RESTARTING
        self.action, self.action_until = NO_ASSIST, 0.0
        self.worker.restart()
        self.event("planner_restart", reason=reason, old_pid=old, pid=self.worker.pid)

    def current_action(self, mono: float) -> Action:
        """The action the control loop applies now: a pending question holds the arm; an expired plan
        (late or dead worker) falls back to no-assist; assistance can be switched off."""
        if self.question is not None:
            return Action(ActionKind.QUESTION, None, self.question.target)
        if not self.assist:
            return NO_ASSIST
        if mono > self.action_until:
            return NO_ASSIST
        return self.action

    # -- input and belief --------------------------------------------------------------------------------

    async def _input_loop(self) -> None:
        rate = self.rates["belief"]
        while True:
            await rate.tick()
            mono = time.monotonic()
            self._heartbeat["belief"] = mono
            if self.arm_state is None:
                continue
            if self.sim is not None:
                self._sim_tick(mono)
            elif self.joystick is not None and self.input_connected:
                # The kernel reports changes only: while the device is open its held state is current.
                self.t_input = mono
            self._belief_tick(mono)
            self._question_timeout(mono)

    def _sim_tick(self, mono: float) -> None:
        sim = self.sim
        assert sim is not None and self.arm_state is not None
        if self._task_reset_at is not None:
            if mono >= self._task_reset_at:
                self._start_next_task()
            return
        pose = self.arm_state.pose
        if self.question is not None and mono - self.question.asked_at >= self.cfg.sim_user.answer_delay_s:
            self.answer(sim.answer(self.question.target), source="sim")
        s = sim.sample(pose, listening=self.question is not None,
                       blocked=self.safety_result.refuses(self.command.total_twist))
        timed_out = self.now() - sim.task_started > self.cfg.sim_user.timeout_s
        if s.close or timed_out:
            self.set_axes(np.zeros(3), mono)
            if s.close:
                self.set_gripper(True)
            done = {"task": sim.task, "success": bool(s.close and sim.at_goal(pose)),
                    "time_s": round(self.now() - sim.task_started, 3), "questions": len(self.asked),
                    "timed_out": timed_out and not s.close}
            self.tasks_done.append(done)
            self.event("task_done", **done)
            self._task_reset_at = mono + 1.0
            return
        self.set_mode(s.mode)
        self.set_axes(s.axes, mono)

    def _start_next_task(self) -> None:
        """Reset the scene (a fresh arm at the start pose) and give the sim user its next task."""
        sim = self.sim
        assert sim is not None
        self._task_reset_at = None
        if self.opts.exit_when_done and self.opts.duration_s is None and len(self.tasks_done) >= len(sim.tasks):
            self.request_stop("all tasks done")
            return
        if self.arm is None or not self.arm.reset():  # a rebuild only for an arm that cannot reset
            if self.arm is not None:
                self.arm.close()
            self.arm = self._arm_factory()
        assert self.safety is not None
        self.safety.kinematics = self.arm.kinematics
        self.safety.resume()
        self.arm_state = self.arm.read()
        self.gripper_closed = False
        self.belief = self.model.initial_belief(self.opts.scene.goals)
        self.asked.clear()
        self._clear_question()
        self.action, self.action_until = NO_ASSIST, 0.0
        task = sim.next_task(self.arm_state.pose, self.now())
        self.set_mode(Mode.TRANSLATION)
        self.event("task", task=task)

    def _belief_tick(self, mono: float) -> None:
        if not self.input_fresh(mono) or self.arm_state is None:
            return
        old = self.belief.goals
        self.belief = self.model.update_input(self.belief, self.arm_state.pose, self.user_twist)
        if self.belief.goals is not old and self.action.kind is ActionKind.MOVE and self.action_goals is old:
            self.action = self.model.remap_action(self.action, old, self.belief.goals, self.arm_state.pose)
            self.action_goals = self.belief.goals

    def _question_timeout(self, mono: float) -> None:
        q = self.question
        if q is not None and mono - q.asked_at > self.cfg.runtime.question_timeout_s:
            self._clear_question()
            self.action, self.action_until = NO_ASSIST, 0.0
            self.event("question_timeout", goal=q.target)

    # -- control -----------------------------------------------------------------------------------------

    async def _control_loop(self) -> None:
        rate = self.rates["control"]
        dt = rate.dt
        while True:
            mono = await rate.tick()
            self._heartbeat["control"] = mono
            self._control_tick(mono, dt)
            self.tick_work_ms.append((time.monotonic() - mono) * 1e3)

    def _control_tick(self, mono: float, dt: float) -> None:
        arm, safety = self.arm, self.safety
        assert arm is not None and safety is not None
        state = arm.read()
        self.arm_state = state
        if state.fault and state.fault != self.fault_reported:
            self.fault_reported = state.fault
            self.event("fault", source="arm", detail=state.fault)
        fresh = self.input_fresh(mono)
        u = self.user_twist if fresh else np.zeros(6)
        action = self.current_action(mono)
        if action.kind is ActionKind.MOVE and self.action_goals is not self.belief.goals:
            action = NO_ASSIST  # (remapped by the belief loop; never index a stale goal set)
        try:
            cmd = self.model.command(action, self.belief.goals, self.belief.probs, state.pose, u, self.method)
        except (ValueError, FloatingPointError) as e:
            cmd = Command(NO_ASSIST, np.zeros(6), u, False)
            self.event("fault", source="command", detail=str(e))
        result = safety.filter(
            cmd.total_twist, state.pose, input_fresh=fresh, fault=state.fault is not None, joints=state.joints,
            gripper_closed=state.gripper_closed or self.gripper_closed,  # closed, or closing (not yet reported)
        )
        arm.command_twist(result.twist)
        sent = time.monotonic()
        if fresh and self.input_seq != self._commanded_seq:
            self._commanded_seq = self.input_seq
            self.latency_ms.append((sent - self.t_input) * 1e3)
        if not arm.realtime:
            arm.step(dt)
        self.command, self.safety_result = cmd, result
        if self.recorder is not None:
            self.recorder.add("/state", messages.record_state(self, cmd, result, state))
        self._watchdog(sent)

    def _watchdog(self, mono: float) -> None:
        n = self.notifier
        if not self._ready_sent or n.watchdog_interval_s is None or mono - self._last_watchdog < min(n.watchdog_interval_s, 1.0):
            return
        # Healthy: every loop ticked within the last second (a stuck loop starves the watchdog).
        if all(mono - self._heartbeat.get(k, 0.0) < 1.0 for k in ("control", "belief", "planner", "publish")):
            n.notify("WATCHDOG=1")
            self._last_watchdog = mono

    # -- publishing (messages.py builds the messages) ---------------------------------------------------

    async def _publish_loop(self) -> None:
        rate = self.rates["publish"]
        last_progress = 0.0
        while True:
            mono = await rate.tick()
            self._heartbeat["publish"] = mono
            if self.server is not None and self.arm_state is not None:
                self.server.publish(TOPIC_STATE, messages.state_message(self))
            if self.opts.progress and mono - last_progress >= 1.0 and self.arm_state is not None:
                last_progress = mono
                messages.print_progress(self)

    # -- lifecycle ---------------------------------------------------------------------------------------

    def request_stop(self, reason: str) -> None:
        if self._stop_event is not None and not self._stop_event.is_set():
            if self.safety is not None:  # from now on every control tick commands zero, until the arm closes
                self.safety.stop()
            self.event("shutdown", reason=reason)
            self._stop_event.set()

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
            await self._wait_ready()
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
                       pub=self.server.pub_endpoint, cmd=self.server.cmd_endpoint)  # type: ignore[union-attr]
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
            await self._shutdown(tasks)
            set_switch_interval(switch_interval)
        return self._exit_code

    def _start_components(self) -> None:
        cfg, opts = self.cfg, self.opts
        # The joystick's codes first: a config no device could match is refused before anything starts.
        if opts.input == "evdev":
            from ..io.joystick import EvdevJoystick

            self.joystick = EvdevJoystick(cfg.joystick, self.set_axes, self.on_button, self.on_joystick_link)
        elif opts.input != "sim":
            raise ValueError(f"unknown input backend {opts.input!r} (sim or evdev)")
        self.arm = self._arm_factory()
        self.arm_state = self.arm.read()
        # One epoch for every loop; the others are phased between control ticks (a quarter and a half
        # period after one) so their work does not delay a control tick.
        t0 = time.monotonic() + 0.05
        ctl = 1.0 / cfg.runtime.control_hz
        control = FixedRate(cfg.runtime.control_hz, spin_s=5e-4, start=t0)
        self.rates = {
            "control": control,
            "belief": FixedRate(cfg.runtime.belief_hz, spin_s=0.0, start=t0 + 0.25 * ctl),
            "planner": FixedRate(1.0 / cfg.planner.period_s, spin_s=0.0, start=t0 + 0.5 * ctl),
            "publish": FixedRate(cfg.runtime.publish_hz, spin_s=0.0, start=t0 + 0.6 * ctl),
        }
        self.safety = SafetyPipeline(cfg.safety, cfg.limits, control.dt, self.arm.kinematics)
        try:
            self.server = ZmqServer(opts.pub, opts.cmd, cfg.zmq.max_request_bytes, cfg.zmq.max_json_depth,
                                    curve=self.curve)
        except OSError as e:
            raise OSError(f"zmq.pub / zmq.cmd (--pub / --cmd): {e}") from None
        if opts.record:
            path = opts.record.replace("{time}", time.strftime("%Y%m%d-%H%M%S"))
            try:
                self.recorder = Recorder(path, cfg.record.flush_s, on_error=self._on_record_error)
            except OSError as e:
                raise OSError(f"record.path (--record) {path}: cannot write: {e.strerror or e}") from None
        if cfg.speech.enabled:
            self.speaker = Speaker(cfg.speech, on_done=self._on_spoken)
        if cfg.voice.enabled:
            from ..speech.listener import VoiceListener

            self.voice = VoiceListener(cfg.voice, self._on_heard, self._on_voice_error)
            self.voice.start()
        self.worker = PlannerWorker(cfg.model_dump(mode="json"), self._on_plan, self._on_worker_exit)
        self._plan_goals = self.belief.goals
        self.worker.start()
        self.planner_status = WorkerStatus.STARTING
        if opts.input == "sim":
            self.sim = SimInput(opts.scene, opts.tasks, cfg, 1.0 / cfg.runtime.belief_hz, opts.seed)
            task = self.sim.next_task(self.arm_state.pose, self.now())
            self.event("task", task=task)

    async def _wait_ready(self) -> None:
        """Wait (without blocking the loops) for the planner worker and the speech engine."""
        deadline = time.monotonic() + self.cfg.runtime.worker_start_timeout_s
        while self.worker is not None and not self.worker.ready and time.monotonic() < deadline:
            await asyncio.sleep(0.02)
        if self.worker is not None and self.worker.ready:
            self.planner_status = WorkerStatus.OK if method_spec(self.method).planned else WorkerStatus.IDLE
            self.event("planner_ready", pid=self.worker.pid)
        if self.speaker is not None:
            await asyncio.get_running_loop().run_in_executor(None, self.speaker.wait_ready, 5.0)
            if not self.speaker.available:
                self.event("speech_unavailable", error=self.speaker.error)
            elif self.speaker.player_missing is not None:
                log.warning("%s", self.speaker.player_missing)
                self.event("speech_player_missing", player=PLAYER, package=PLAYER_PACKAGE,
                           detail=self.speaker.player_missing)
        deadline = time.monotonic() + self.cfg.runtime.worker_start_timeout_s
        while self.voice is not None and not self.voice.ready and self.voice.error is None \
                and time.monotonic() < deadline:
            await asyncio.sleep(0.02)
        if self.voice is not None and self.voice.ready:
            self.event("voice_ready", source=self.voice.source, pid=self.voice.pid)

    async def _shutdown(self, tasks: list[asyncio.Task]) -> None:
        """Arm first: zero command and close; then the rest. Never raises."""
        self.notifier.notify("STOPPING=1")
        if self.arm is not None:
            try:
                self.arm.command_twist(np.zeros(6))
                self.arm.close()
            except Exception as e:  # noqa: BLE001 - keep shutting down
                log.error("arm stop failed: %s", e)
        self.event("stopped", code=self._exit_code)
        for t in tasks:
            t.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
        if self.worker is not None:
            self.worker.stop()
        if self.voice is not None:
            self.voice.stop()
        if self.speaker is not None:
            self.speaker.close(timeout_s=1.0)
        if self.recorder is not None:
            self.recorder.close()
            if self.recorder.error is not None:  # (finishing the file failed: the loop may not run again)
                self._record_failed(self.recorder.error)
        if self.server is not None:
            self.server.close()
            self.server = None  # a late callback (an utterance ended by the speaker's close) publishes nothing
        self.notifier.close()
        self.console.close()

    # -- figures -----------------------------------------------------------------------------------------

    def loop_figures(self) -> dict[str, Any]:
        """Loop statistics for ``bench loop`` and the closing log line."""
        ctl = self.rates["control"].stats.summary() if "control" in self.rates else {}
        lat = self.latency_ms.values() if len(self.latency_ms) else np.zeros(1)
        work = self.tick_work_ms.values() if len(self.tick_work_ms) else np.zeros(1)
        return {
            **ctl,
            "input_to_command_ms_p50": float(np.percentile(lat, 50)),
            "input_to_command_ms_p99": float(np.percentile(lat, 99)),
            "control_work_ms_p50": float(np.percentile(work, 50)),
            "control_work_ms_p99": float(np.percentile(work, 99)),
            "loops": {k: r.stats.summary() for k, r in self.rates.items()},
            "plans": self.plans,
            "planner_restarts": self.worker.restarts if self.worker is not None else 0,
            "tasks_done": self.tasks_done,
        }

