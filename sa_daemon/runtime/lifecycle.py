"""Starting and stopping a daemon's components: input, arm, loop clocks, sockets, recorder, live view,
speech, voice, planner worker and the simulated user's tasks; and, at the end, the arm first.

Functions of a :class:`~.daemon.Daemon`; its :meth:`~.daemon.Daemon.run` calls them in order.
"""

from __future__ import annotations

import asyncio
import logging
import time
from typing import TYPE_CHECKING

import numpy as np

from ..io.recorder import Recorder
from ..io.server import ZmqServer
from ..model.methods import method_spec
from ..planner.worker import PlannerWorker, WorkerStatus
from ..speech.speaker import PLAYER, PLAYER_PACKAGE, Speaker
from . import messages
from .rate import FixedRate
from .siminput import SimInput
from .simtasks import SimTasks

if TYPE_CHECKING:
    from .daemon import Daemon

log = logging.getLogger("sa_daemon")


def start_components(d: Daemon) -> None:
    """Build and start everything the loops need (raises before anything moves on a config error)."""
    cfg, opts = d.cfg, d.opts
    # The joystick's codes first: a config no device could match is refused before anything starts.
    if opts.input == "evdev":
        from ..io.joystick import EvdevJoystick

        d.joystick = EvdevJoystick(cfg.joystick, d.set_axes, d.on_button, d.on_joystick_link)
    elif opts.input != "sim":
        raise ValueError(f"unknown input backend {opts.input!r} (sim or evdev)")
    d.reset_arm()
    assert d.arm is not None
    d.ctl.use_arm(d.arm.kinematics)
    test = cfg.safety.stop_self_test
    if test == "on" or (test == "auto" and d.arm.realtime):
        d.ctl.require_stop_test()  # nothing moves until a stop is latched and resumed once
    # One epoch for every loop; the others are phased between control ticks (a quarter and a half
    # period after one) so their work does not delay a control tick.
    t0 = time.monotonic() + 0.05
    ctl = 1.0 / cfg.runtime.control_hz
    d.rates = {
        "control": FixedRate(cfg.runtime.control_hz, spin_s=5e-4, start=t0),
        "belief": FixedRate(cfg.runtime.belief_hz, spin_s=0.0, start=t0 + 0.25 * ctl),
        "planner": FixedRate(1.0 / cfg.planner.period_s, spin_s=0.0, start=t0 + 0.5 * ctl),
        "publish": FixedRate(cfg.runtime.publish_hz, spin_s=0.0, start=t0 + 0.6 * ctl),
    }
    try:
        d.server = ZmqServer(opts.pub, opts.cmd, cfg.zmq.max_request_bytes, cfg.zmq.max_json_depth, curve=d.curve)
    except OSError as e:
        raise OSError(f"zmq.pub / zmq.cmd (--pub / --cmd): {e}") from None
    if opts.record:
        path = opts.record.replace("{time}", time.strftime("%Y%m%d-%H%M%S"))
        try:
            d.recorder = Recorder(path, cfg.record.flush_s, on_error=lambda text: record_error(d, text),
                                  json_topics=_viz_json_topics())
        except OSError as e:
            raise OSError(f"record.path (--record) {path}: cannot write: {e.strerror or e}") from None
    start_viz(d)
    d.asker.bind(asyncio.get_running_loop())
    if cfg.speech.enabled:
        d.asker.speaker = Speaker(cfg.speech, on_done=d.asker.on_spoken)
    if cfg.voice.enabled:
        from ..speech.listener import VoiceListener

        d.asker.voice = VoiceListener(cfg.voice, d.asker.on_heard, d.asker.on_voice_error)
        d.asker.voice.start()
    d.worker = PlannerWorker(cfg.model_dump(mode="json"), d._on_plan, d._on_worker_exit)
    d.worker.start()
    d.planner_status = WorkerStatus.STARTING
    if opts.input == "sim":
        d.sim = SimTasks(d, SimInput(opts.scene, opts.tasks, cfg, 1.0 / cfg.runtime.belief_hz, opts.seed))


def _viz_json_topics() -> dict:
    """The live view's JSON topics, which a recording carries too (imported here: the module imports the
    Foxglove SDK, only when it is used)."""
    from ..viz.messages import JSON_TOPICS

    return JSON_TOPICS


def start_viz(d: Daemon) -> None:
    """The Foxglove live view (``foxglove.enabled``) and the feed that gives it and the recording the same
    topics (``docs/foxglove.md``); nothing when neither is on."""
    from ..viz.feed import VizFeed
    from ..viz.live import LiveView

    fx = d.cfg.foxglove
    if fx.enabled:
        d.live = LiveView(fx.port)  # (raises OSError naming foxglove.port)
    sinks = [s.log for s in (d.live,) if s is not None] + [s.add for s in (d.recorder,) if s is not None]
    if sinks:
        d.viz = VizFeed(messages.scene(d.view), sinks, fx.scene_period_s, fx.belief_step)


async def wait_ready(d: Daemon) -> None:
    """Wait (without blocking the loops) for the planner worker, the speech engine and the voice."""
    deadline = time.monotonic() + d.cfg.runtime.worker_start_timeout_s
    while d.worker is not None and not d.worker.ready and time.monotonic() < deadline:
        await asyncio.sleep(0.02)
    if d.worker is not None and d.worker.ready:
        d.planner_status = WorkerStatus.OK if method_spec(d.method).planned else WorkerStatus.IDLE
        d.event("planner_ready", pid=d.worker.pid)
    speaker, voice = d.asker.speaker, d.asker.voice
    if speaker is not None:
        await asyncio.get_running_loop().run_in_executor(None, speaker.wait_ready, 5.0)
        if not speaker.available:
            d.event("speech_unavailable", error=speaker.error)
        elif speaker.player_missing is not None:
            log.warning("%s", speaker.player_missing)
            d.event("speech_player_missing", player=PLAYER, package=PLAYER_PACKAGE, detail=speaker.player_missing)
    deadline = time.monotonic() + d.cfg.runtime.worker_start_timeout_s
    while voice is not None and not voice.ready and voice.error is None and time.monotonic() < deadline:
        await asyncio.sleep(0.02)
    if voice is not None and voice.ready:
        d.event("voice_ready", source=voice.source, pid=voice.pid)
        d.asker.voice_ready()


async def shutdown(d: Daemon, tasks: list[asyncio.Task], exit_code: int) -> None:
    """Arm first: zero command and close; then the rest. Never raises."""
    d.notifier.notify("STOPPING=1")
    if d.arm is not None:
        try:
            d.arm.command_twist(np.zeros(6))
            d.arm.close()
        except Exception as e:  # noqa: BLE001 - keep shutting down
            log.error("arm stop failed: %s", e)
    d.event("stopped", code=exit_code)
    for t in tasks:
        t.cancel()
    await asyncio.gather(*tasks, return_exceptions=True)
    if d.worker is not None:
        d.worker.stop()
    if d.asker.voice is not None:
        d.asker.voice.stop()
    if d.asker.speaker is not None:
        d.asker.speaker.close(timeout_s=1.0)
    if d.recorder is not None:
        d.recorder.close()
        if d.recorder.error is not None:  # (finishing the file failed: the loop may not run again)
            _record_failed(d, d.recorder.error)
    if d.live is not None:
        d.live.close()
    if d.server is not None:
        d.server.close()
        d.server = None  # a late callback (an utterance ended by the speaker's close) publishes nothing
    d.notifier.close()
    d.console.close()


def record_error(d: Daemon, text: str) -> None:
    """(The recorder's writer thread.) A write failed, e.g. the disk is full: the recording has stopped;
    the daemon goes on controlling the arm and says so, once."""
    loop = d._loop
    if loop is not None and not loop.is_closed():
        loop.call_soon_threadsafe(_record_failed, d, text)


def _record_failed(d: Daemon, text: str) -> None:
    if d.record_error_reported:
        return
    d.record_error_reported = True
    log.error("%s", text)
    d.event("fault", source="recorder", detail=text)
