"""``sa-daemon`` with fakes at its hardware boundaries, driven over stdin by the fault-injection tests.

    python tests/faultd.py [--speech-init fail] -- [sa-daemon arguments: run ...]

runs the real command line (:func:`sa_daemon.cli.main`) in this process after installing:

* **a joystick without /dev/input** - ``evdev.list_devices`` and ``evdev.InputDevice`` are replaced by a
  bus of fake device nodes. Each node is a non-blocking pipe carrying the kernel's ``struct input_event``
  records, so evdev's own reader (``_input.device_read_many`` under ``async_read_loop``) decodes them
  on the daemon's event loop. A device has ``capabilities()``/``absinfo()`` like a 3-axis stick; after
  an unplug it is gone from ``list_devices``, its open handles poll readable and every read fails with
  ``OSError(ENODEV)``, as the kernel's evdev does. One stick is plugged at start.
* **access to the fake xArm** - the ``FakeXArmAPI`` the daemon builds for ``[arm.xarm] sdk = "fake"`` is
  recorded (a subclass that can also report a NaN pose, as a corrupt report would).
* **the speech engine boundary** - making the espeak-ng engine (``speech.engine.engine``) can be made
  to raise (``--speech-init fail``), and the engine it returns can be made to fail or hang on command. The sound-card boundary needs no patch:
  the tests put a fake ``aplay`` on ``PATH``.

Commands, one per line on stdin; each is answered by one line ``FAULTD {json}`` on stdout with ``ok``
and ``t`` (the daemon's clock, s since its start, when the command took effect)::

    axes X Y Z          stick position of the configured axes, each in [-1, 1] (EV_ABS + SYN_REPORT)
    button NAME         press and release the button of intent NAME (mode, gripper, yes, no, assist, stop)
    sample X Y Z        hand floats (nan, inf allowed) straight to the daemon's input callback
    unplug | replug     the stick leaves / comes back (a new node, as after a real replug)
    arm_error CODE | arm_warn CODE | arm_drop | arm_restore | arm_hang S
    arm_pose_nan | arm_pose_ok      get_position reports NaN / real values
    calls NAME [SINCE]  the fake SDK's calls of NAME (daemon clock t >= SINCE)
    speed               the fake controller's velocity in force now
    loop_hang S         block the daemon's event loop S seconds; report the fake's speed meanwhile
    loop_stuck W        block the daemon's event loop for good; report the fake's speed over W seconds
    speech_fail | speech_hang | speech_ok   the engine's utterances from now on raise / block / work
    now                 the daemon's clock

The planner worker is spawned and re-imports this file as ``__mp_main__``: nothing happens at import.
"""

from __future__ import annotations

import argparse
import asyncio
import errno
import faulthandler
import json
import math
import os
import resource
import signal
import struct
import sys
import threading
import time
from typing import Any

#: ``struct input_event`` on 64-bit Linux: ``struct timeval`` (two longs), ``__u16`` type and code, ``__s32`` value.
INPUT_EVENT = struct.Struct("llHHi")
STICK_NAME = "Faultd Stick"
AXIS_MIN, AXIS_MAX = -32767, 32767


class Faultd:
    """The state shared by the patches and the command thread."""

    def __init__(self) -> None:
        self.daemon: Any = None
        self.daemon_ready = threading.Event()
        self.arms: list[Any] = []
        self.bus: FakeBus | None = None
        self.speech_mode = "ok"
        self.speech_release = threading.Event()
        self.speech_init_fail = False
        self.out = os.fdopen(os.dup(1), "w", buffering=1)  # sys.stdout is redirected during speech
        self.out_lock = threading.Lock()

    def reply(self, **fields: Any) -> None:
        line = "FAULTD " + json.dumps(fields, default=str)
        with self.out_lock:
            self.out.write(line + "\n")
            self.out.flush()

    def now(self) -> float | None:
        d = self.daemon
        return None if d is None else round(time.monotonic() - d.t0, 6)

    @property
    def arm(self) -> Any:
        if not self.arms:
            raise RuntimeError("no fake xArm (run with --arm xarm and [arm.xarm] sdk = \"fake\")")
        return self.arms[-1]


FD = Faultd()


# -- the evdev boundary ----------------------------------------------------------------------------------


class FakeNode:
    """One ``/dev/input/eventN`` while plugged: a pipe the "kernel" writes events into."""

    def __init__(self, path: str, name: str) -> None:
        from evdev import AbsInfo, ecodes

        self.path, self.name = path, name
        self.read_fd, self.write_fd = os.pipe2(os.O_NONBLOCK | os.O_CLOEXEC)
        self.present = True
        axes = (ecodes.ABS_X, ecodes.ABS_Y, ecodes.ABS_Z, ecodes.ABS_RX, ecodes.ABS_RY, ecodes.ABS_RZ,
                ecodes.ABS_THROTTLE)
        self.abs = {c: AbsInfo(value=0, min=AXIS_MIN, max=AXIS_MAX, fuzz=0, flat=0, resolution=0) for c in axes}
        self.abs[ecodes.ABS_HAT0X] = AbsInfo(value=0, min=-1, max=1, fuzz=0, flat=0, resolution=0)
        self.keys = [ecodes.BTN_TRIGGER, ecodes.BTN_THUMB, ecodes.BTN_THUMB2, ecodes.BTN_TOP, ecodes.BTN_TOP2,
                     ecodes.BTN_PINKIE, ecodes.BTN_BASE, ecodes.BTN_BASE2]
        self.lock = threading.Lock()

    def emit(self, events: list[tuple[int, int, int]]) -> None:
        """Queue ``(type, code, value)`` events, each stamped now, closed by a SYN_REPORT."""
        from evdev import ecodes

        now = time.time()
        sec, usec = int(now), int((now % 1) * 1e6)
        data = b"".join(INPUT_EVENT.pack(sec, usec, t, c, v)
                        for t, c, v in [*events, (ecodes.EV_SYN, ecodes.SYN_REPORT, 0)])
        with self.lock:
            if not self.present:
                raise OSError(errno.ENODEV, "the device is unplugged")
            os.write(self.write_fd, data)
            for t, c, v in events:
                if t == ecodes.EV_ABS and c in self.abs:
                    self.abs[c] = self.abs[c]._replace(value=v)

    def remove(self) -> None:
        """Unplug: readers wake up (the write end closes) and every later read fails with ENODEV."""
        with self.lock:
            self.present = False
            os.close(self.write_fd)


def _device_class() -> type:
    from evdev import _input
    from evdev.eventio_async import EventIO

    class FakeInputDevice(EventIO):
        """The part of ``evdev.InputDevice`` a reader uses, over a :class:`FakeNode`."""

        def __init__(self, node: FakeNode) -> None:
            self._node = node
            self.path, self.name, self.phys, self.uniq = node.path, node.name, "faultd/input0", ""
            self.fd = os.dup(node.read_fd)
            self.grabbed = False

        def capabilities(self, verbose: bool = False, absinfo: bool = True) -> dict:
            from evdev import ecodes

            if verbose:
                raise NotImplementedError("verbose capabilities are not modelled")
            with self._node.lock:
                abs_caps = sorted(self._node.abs.items())
            return {
                ecodes.EV_SYN: [ecodes.SYN_REPORT, ecodes.SYN_DROPPED],
                ecodes.EV_KEY: list(self._node.keys),
                ecodes.EV_ABS: abs_caps if absinfo else [c for c, _ in abs_caps],
            }

        def absinfo(self, axis_num: int) -> Any:
            self._check()
            with self._node.lock:
                return self._node.abs[axis_num]

        def _check(self) -> None:
            if not self._node.present:
                raise OSError(errno.ENODEV, os.strerror(errno.ENODEV))

        def read(self):
            self._check()
            from evdev import InputEvent

            events = _input.device_read_many(self.fd)  # evdev's own decoder; BlockingIOError when empty
            return (InputEvent(*e) for e in events)

        def read_one(self) -> Any:
            self._check()
            from evdev import InputEvent

            e = _input.device_read(self.fd)
            return InputEvent(*e) if e else None

        def grab(self) -> None:
            self._check()
            self.grabbed = True

        def ungrab(self) -> None:
            self._check()
            self.grabbed = False

        def close(self) -> None:
            if self.fd > -1:
                try:
                    super().close()  # removes the event loop's reader
                    os.close(self.fd)
                finally:
                    self.fd = -1

        def __repr__(self) -> str:
            return f"FakeInputDevice({self.path!r})"

    return FakeInputDevice


class FakeBus:
    """``evdev.list_devices`` / ``evdev.InputDevice`` over the plugged fake nodes."""

    def __init__(self) -> None:
        self.nodes: dict[str, FakeNode] = {}
        self.next_minor = 7
        self.stick: FakeNode | None = None
        self.lock = threading.Lock()
        self.device_class = _device_class()

    def plug(self) -> FakeNode:
        with self.lock:
            node = FakeNode(f"/dev/input/event{self.next_minor}", STICK_NAME)
            self.next_minor += 1
            self.nodes[node.path] = node
            self.stick = node
            return node

    def unplug(self) -> None:
        with self.lock:
            node = self.stick
            if node is None:
                raise RuntimeError("no stick is plugged")
            self.stick = None
            del self.nodes[node.path]
        node.remove()

    def list_devices(self, input_device_dir: str = "/dev/input", writable: bool = True) -> list[str]:
        with self.lock:
            return sorted(self.nodes)

    def open(self, dev: Any, readonly: bool = False) -> Any:
        path = os.fspath(dev)
        with self.lock:
            node = self.nodes.get(path)
        if node is None:
            raise FileNotFoundError(errno.ENOENT, os.strerror(errno.ENOENT), path)
        return self.device_class(node)


def install_evdev() -> None:
    import evdev

    FD.bus = FakeBus()
    FD.bus.plug()
    evdev.list_devices = FD.bus.list_devices
    evdev.InputDevice = FD.bus.open


# -- the xArm and speech boundaries, and the daemon itself ------------------------------------------------


def install_xarm() -> None:
    from sa_daemon.testing import fake_xarm

    base = fake_xarm.FakeXArmAPI

    class RecordedFakeXArmAPI(base):  # type: ignore[misc, valid-type]
        """The fake SDK, kept where faultd can reach it; ``pose_nan`` makes ``get_position`` report NaN."""

        pose_nan = False

        def __init__(self, *args: Any, **kwargs: Any) -> None:
            super().__init__(*args, **kwargs)
            FD.arms.append(self)

        def get_position(self, is_radian: bool | None = None) -> tuple[int, Any]:
            code, pos = super().get_position(is_radian=is_radian)
            if self.pose_nan and code == 0:
                return code, [math.nan] * 6
            return code, pos

    fake_xarm.FakeXArmAPI = RecordedFakeXArmAPI


class EngineProxy:
    """The real espeak-ng engine whose utterances can be made to fail or hang (``FD.speech_mode``)."""

    def __init__(self, engine: Any) -> None:
        self._engine = engine

    def __getattr__(self, name: str) -> Any:
        return getattr(self._engine, name)

    def save_wav(self, text: str, path: str) -> Any:
        if FD.speech_mode == "fail":
            raise RuntimeError("injected: the speech driver failed")
        if FD.speech_mode == "hang":
            FD.speech_release.wait()  # until speech_ok, or forever
        return self._engine.save_wav(text, path)


def install_speech() -> None:
    from sa_daemon.speech import engine as engine_mod

    real = engine_mod.engine

    def engine(*args: Any, **kwargs: Any) -> Any:
        if FD.speech_init_fail:
            raise RuntimeError("injected: no speech driver")
        return EngineProxy(real(*args, **kwargs))

    engine_mod.engine = engine


def install_daemon_hook() -> None:
    from sa_daemon.runtime import daemon as daemon_mod

    cls = daemon_mod.Daemon
    orig = cls._start_components

    def start_components(self: Any) -> None:
        FD.daemon = self
        orig(self)
        FD.daemon_ready.set()

    cls._start_components = start_components


# -- commands ----------------------------------------------------------------------------------------------


def on_loop(fn: Any, timeout_s: float = 10.0) -> Any:
    """Run ``fn()`` on the daemon's event loop and return its result."""
    d = FD.daemon
    if d is None or d._loop is None:
        raise RuntimeError("the daemon is not running yet")

    async def call() -> Any:
        return fn()

    return asyncio.run_coroutine_threadsafe(call(), d._loop).result(timeout_s)


def _axes(args: list[str]) -> dict:
    from evdev import ecodes

    values = [float(a) for a in args]
    if len(values) != 3 or not all(-1.0 <= v <= 1.0 for v in values):
        raise ValueError("axes needs 3 values in [-1, 1] (an evdev axis carries integers only)")
    if FD.bus is None or FD.bus.stick is None:
        raise RuntimeError("no stick is plugged")
    codes = [ecodes.ecodes[n] for n in FD.daemon.cfg.joystick.axes]
    raw = [round(v * AXIS_MAX) for v in values]
    FD.bus.stick.emit([(ecodes.EV_ABS, c, r) for c, r in zip(codes, raw)])
    return {"raw": raw}


def _button(args: list[str]) -> dict:
    from evdev import ecodes

    name = getattr(FD.daemon.cfg.joystick, f"button_{args[0]}")
    code = ecodes.ecodes[name]
    FD.bus.stick.emit([(ecodes.EV_KEY, code, 1)])  # type: ignore[union-attr]
    FD.bus.stick.emit([(ecodes.EV_KEY, code, 0)])  # type: ignore[union-attr]
    return {"code": name}


def _sample(args: list[str]) -> dict:
    import numpy as np

    values = np.array([float(a) for a in args])  # float() accepts nan, inf, -inf
    on_loop(lambda: FD.daemon.set_axes(values))
    return {}


def _calls(args: list[str]) -> dict:
    name = args[0]
    since = float(args[1]) if len(args) > 1 else -math.inf
    t0 = FD.daemon.t0
    out = []
    for c in FD.arm.calls_named(name):
        t = c.t - t0
        if t >= since:
            out.append({"t": round(t, 6), "args": c.args, "kwargs": c.kwargs, "result": c.result})
    return {"calls": out}


def _loop_hang(args: list[str]) -> dict:
    """Block the event loop (no control tick, so no new command) and watch the fake's speed."""
    return _block_loop(float(args[0]), float(args[0]))


def _loop_stuck(args: list[str]) -> dict:
    """Block the event loop for good (the process is stuck until something kills it); watch the fake's
    speed for ``args[0]`` s and reply while the loop stays blocked."""
    return _block_loop(math.inf, float(args[0]))


def _block_loop(seconds: float, watch_s: float) -> dict:
    d = FD.daemon
    arm = FD.arms[-1] if FD.arms else None
    blocked = threading.Event()

    def block() -> None:
        blocked.set()
        if math.isinf(seconds):
            threading.Event().wait()
        else:
            time.sleep(seconds)

    d._loop.call_soon_threadsafe(block)
    if not blocked.wait(10.0):
        raise RuntimeError("the event loop did not run the blocking call")
    t_block = time.monotonic()
    zero_at = None
    while time.monotonic() < t_block + watch_s:
        if zero_at is None and arm is not None and not any(arm.speed):
            zero_at = arm.stopped_since  # the fake's own instant: a late look (a busy CPU) does not move it
        time.sleep(0.0002)
    out: dict[str, Any] = {"blocked_at": round(t_block - d.t0, 6), "blocked_mono": t_block}
    if arm is None:
        return out
    vc = [c for c in arm.calls_named("vc_set_cartesian_velocity") if c.t <= t_block + watch_s]
    last_moving = next((c for c in reversed(vc) if any(c.args[0]) and c.result == 0), None)
    sent_during = [c for c in vc if c.t > t_block]
    return {
        **out,
        "zero_at": None if zero_at is None else round(zero_at - d.t0, 6),
        "last_moving_command": None if last_moving is None else {
            "t": round(last_moving.t - d.t0, 6), "speeds": last_moving.args[0],
            "duration": last_moving.kwargs.get("duration")},
        "commands_during": len(sent_during),
        "moving_commands_during": sum(1 for c in sent_during if any(c.args[0])),
    }


def _speech(mode: str) -> dict:
    FD.speech_mode = mode
    if mode == "ok":
        FD.speech_release.set()
    else:
        FD.speech_release.clear()
    return {"mode": mode}


def handle(line: str) -> dict:
    cmd, *args = line.split()
    if cmd != "now" and not FD.daemon_ready.wait(60.0):
        raise RuntimeError("the daemon did not start")
    if cmd == "now":
        return {}
    if cmd == "axes":
        return _axes(args)
    if cmd == "button":
        return _button(args)
    if cmd == "sample":
        return _sample(args)
    if cmd == "unplug":
        FD.bus.unplug()  # type: ignore[union-attr]
        return {}
    if cmd == "replug":
        return {"path": FD.bus.plug().path}  # type: ignore[union-attr]
    simple = {
        "arm_error": lambda: FD.arm.inject_error(int(args[0])),
        "arm_warn": lambda: FD.arm.inject_warn(int(args[0])),
        "arm_drop": lambda: FD.arm.drop_connection(),
        "arm_restore": lambda: FD.arm.restore_connection(),
        "arm_hang": lambda: FD.arm.hang(float(args[0])),
        "arm_pose_nan": lambda: setattr(FD.arm, "pose_nan", True),
        "arm_pose_ok": lambda: setattr(FD.arm, "pose_nan", False),
    }
    if cmd in simple:
        simple[cmd]()
        return {}
    if cmd == "calls":
        return _calls(args)
    if cmd == "speed":
        return {"speed": [float(v) for v in FD.arm.speed]}
    if cmd == "loop_hang":
        return _loop_hang(args)
    if cmd == "loop_stuck":
        return _loop_stuck(args)
    if cmd in ("speech_fail", "speech_hang", "speech_ok"):
        return _speech(cmd.removeprefix("speech_"))
    raise ValueError(f"unknown faultd command {cmd!r}")


def command_thread() -> None:
    for raw in sys.stdin:
        line = raw.strip()
        if not line:
            continue
        try:
            fields = handle(line)
            FD.reply(cmd=line, ok=True, t=FD.now(), **fields)
        except Exception as e:  # noqa: BLE001 - every command gets an answer
            FD.reply(cmd=line, ok=False, t=FD.now(), error=f"{type(e).__name__}: {e}")


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="faultd.py", usage="%(prog)s [--speech-init fail] -- run ...")
    parser.add_argument("--speech-init", choices=["ok", "fail"], default="ok", help="making the speech engine raises")
    split = argv.index("--") if "--" in argv else len(argv)
    own, cli_argv = parser.parse_args(argv[:split]), argv[split + 1:]
    FD.speech_init_fail = own.speech_init == "fail"
    faulthandler.register(signal.SIGUSR1, all_threads=True)  # the tests ask for stacks when a start hangs
    # A daemon the tests abort (SIGABRT, as systemd's watchdog does) leaves no core file behind.
    resource.setrlimit(resource.RLIMIT_CORE, (0, resource.getrlimit(resource.RLIMIT_CORE)[1]))
    install_evdev()
    install_xarm()
    install_speech()
    install_daemon_hook()
    threading.Thread(target=command_thread, name="faultd-stdin", daemon=True).start()
    from sa_daemon.cli import main as cli_main

    code = cli_main(cli_argv)
    arm = FD.arms[-1] if FD.arms else None
    final: dict[str, Any] = {"exit": code}
    if arm is not None and FD.daemon is not None:
        t0 = FD.daemon.t0
        final["vc_tail"] = [{"t": round(c.t - t0, 6), "speeds": c.args[0], "result": c.result}
                            for c in arm.calls_named("vc_set_cartesian_velocity")[-5:]]
        final["speed"] = [float(v) for v in arm.speed]
        final["connected"] = arm.connected
    FD.reply(**final)
    return code


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
