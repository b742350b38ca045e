"""Helpers shared by the tests that run real processes, sockets and audio (imported as ``helpers``:
pytest puts this folder on ``sys.path``)."""

from __future__ import annotations

import contextlib
import errno
import json
import os
import queue
import signal
import socket
import subprocess
import sys
import threading
import time
import wave
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import zmq

from sa_daemon.io.client import request

CLI = [sys.executable, "-m", "sa_daemon.cli"]
#: The real CLI with fakes at the hardware boundaries, driven over stdin (``tests/faultd.py``).
FAULTD = Path(__file__).with_name("faultd.py")
START_TIMEOUT_S = 60.0
#: The commit model with the paper's question cost: it asks early and often (about 3 questions on Scene 1
#: ``cup:top``), so tests of the question machinery (speech, answers, the protocol) and of the pomdp_py peer,
#: which plans this model, get what they need in good time; the default planner asks about once a task.
COMMIT_MODEL_TOML = '[planner]\nmodel = "commit"\n[reward]\nquestion_time_s = 0.0\n'
PAPER_REACH = {"reach_pose": "closest", "keep_pose_posterior": False}
"""``[intent]`` keys of the paper's reach (moves to ``k_c``, each copy's pose weights afresh after a
resampling; the default until session 43), for tests whose trials were traced under it."""
PAPER_REACH_TOML = "[intent]\n" + "".join(f"{k} = {json.dumps(v)}\n" for k, v in PAPER_REACH.items())
DEFAULT_RUN = ("--arm", "kinematic", "--input", "sim", "--scene", "scene1", "--task", "cup:top")



# The eval JSON's required keys (issue 3: one object per trial, one per (scene, task, method)).
TRIAL_KEYS = (
    "scene", "task", "method", "seed", "success", "completion_time_s", "mode_changes", "joystick_input",
    "opposing_pct", "correct_prediction", "questions",
)
SUMMARY_KEYS = (
    "scene", "task", "method", "n", "success_rate", "completion_time_s", "mode_changes", "joystick_input",
    "opposing_pct", "correct_prediction_rate", "questions",
)

def until(pred, timeout_s: float = 30.0, what: str = "condition", poll_s: float = 0.02):
    """Poll ``pred`` until it returns something true, and return that; ``AssertionError`` naming ``what``
    after ``timeout_s``."""
    end = time.monotonic() + timeout_s
    while True:
        v = pred()
        if v:
            return v
        assert time.monotonic() < end, f"{what}: not met within {timeout_s} s"
        time.sleep(poll_s)


def free_port() -> int:
    """A free loopback TCP port (bind to port 0, read it back, release it)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def free_ports(n: int) -> list[int]:
    """``n`` distinct free loopback TCP ports (all held bound while picking, so none repeats)."""
    socks = [socket.socket(socket.AF_INET, socket.SOCK_STREAM) for _ in range(n)]
    try:
        for s in socks:
            s.bind(("127.0.0.1", 0))
        return [s.getsockname()[1] for s in socks]
    finally:
        for s in socks:
            s.close()


def process_gone(pid: int) -> bool:
    """The process has exited (no such pid, or a zombie nobody reaped yet)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] in ("Z", "X")
    except FileNotFoundError:
        return True


def wav_stats(path: str | Path) -> tuple[int, int, int, float, float]:
    """(channels, sample width, rate, duration s, RMS of 16-bit samples)."""
    with wave.open(str(path), "rb") as w:
        ch, width, rate, n = w.getnchannels(), w.getsampwidth(), w.getframerate(), w.getnframes()
        frames = w.readframes(n)
    samples = np.frombuffer(frames, dtype="<i2").astype(float) if width == 2 else np.zeros(1)
    rms = float(np.sqrt(np.mean(samples**2))) if samples.size else 0.0
    return ch, width, rate, n / rate if rate else 0.0, rms


SYNTH = """
import json, sys
from sa_daemon.speech import espeak
from sa_daemon.speech.engine import engine
speaker = engine(sys.argv[1])
for path, text, voice, rate in json.loads(sys.stdin.read()):
    speaker.configure(rate_wpm=rate, voice=voice)
    speaker.save_wav(text, path)
print(json.dumps(espeak.loaded().as_dict()))
"""


def synth_wavs(folder: Path, items: dict[str, tuple[str, str, int]], library: str = "auto") -> dict:
    """Speak each ``name: (text, voice, rate)`` with espeak-ng into ``folder/name.wav``, in a child process
    (a process holds one espeak-ng library, ``library``); returns the library it used (``EspeakLibrary``'s dict)."""
    folder.mkdir(parents=True, exist_ok=True)
    jobs = [(str(folder / f"{name}.wav"), *spec) for name, spec in items.items()]
    r = subprocess.run([sys.executable, "-c", SYNTH, library], input=json.dumps(jobs), capture_output=True,
                       text=True, timeout=120, check=False)
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout.strip().splitlines()[-1])


@contextlib.contextmanager
def small_disk(path: Path, size: str = "1m") -> Iterator[Path]:
    """A real, small filesystem (tmpfs of ``size``) mounted on ``path``: its writes fail with ``ENOSPC``
    once it is full, as a full disk's do. Skips the test where mounting is not allowed (not root)."""
    import pytest

    path.mkdir(parents=True, exist_ok=True)
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size},mode=0755", "tmpfs", str(path)],
                       capture_output=True, text=True, check=False)
    if r.returncode != 0:
        pytest.skip(f"cannot mount a small tmpfs here (needs root): {r.stderr.strip()}")
    try:
        yield path
    finally:
        subprocess.run(["umount", "-l", str(path)], capture_output=True, check=False)


def fill_disk(path: Path) -> int:
    """Fill the filesystem of ``path`` (a file ``filler`` in it) until a write fails with ENOSPC; bytes
    written."""
    fd = os.open(path / "filler", os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
    n = 0
    try:
        for chunk in (1 << 16, 1 << 12, 1):
            try:
                while True:
                    n += os.write(fd, b"\0" * chunk)
            except OSError as e:
                if e.errno != errno.ENOSPC:
                    raise
    finally:
        os.close(fd)
    return n


class Collector(threading.Thread):
    """Subscribe to everything on ``endpoint`` (connected before the daemon binds, so nothing after its
    start is missed) and keep ``(received_at, topic, message)``."""

    def __init__(self, endpoint: str) -> None:
        super().__init__(daemon=True, name="test-collector")
        self.ctx = zmq.Context()
        self.sock = self.ctx.socket(zmq.SUB)
        self.sock.setsockopt(zmq.SUBSCRIBE, b"")
        self.sock.setsockopt(zmq.RCVHWM, 0)
        self.sock.setsockopt(zmq.LINGER, 0)
        self.sock.connect(endpoint)
        self.msgs: list[tuple[float, str, dict[str, Any]]] = []
        self.cond = threading.Condition()
        self._halt = threading.Event()

    def run(self) -> None:
        try:
            while not self._halt.is_set():
                if self.sock.poll(50):
                    topic, data = self.sock.recv_multipart()
                    with self.cond:
                        self.msgs.append((time.monotonic(), topic.decode(), json.loads(data)))
                        self.cond.notify_all()
        finally:
            self.sock.close(0)
            self.ctx.term()

    def halt(self) -> None:
        self._halt.set()
        self.join(5)

    def __len__(self) -> int:
        with self.cond:
            return len(self.msgs)

    def wait_for(self, pred: Callable[[str, dict], bool], timeout_s: float, start: int = 0,
                 what: str = "message") -> tuple[int, dict]:
        """The first message at index >= ``start`` matching ``pred``: ``(index, message)``."""
        end = time.monotonic() + timeout_s
        i = start
        with self.cond:
            while True:
                while i < len(self.msgs):
                    _, topic, msg = self.msgs[i]
                    if pred(topic, msg):
                        return i, msg
                    i += 1
                left = end - time.monotonic()
                if left <= 0:
                    raise AssertionError(f"no {what} within {timeout_s} s")
                self.cond.wait(min(left, 0.5))

    def event(self, kind: str, timeout_s: float = 30.0, start: int = 0, **match: Any) -> tuple[int, dict]:
        return self.wait_for(
            lambda tp, m: tp == "event" and m["type"] == kind and all(m.get(k) == v for k, v in match.items()),
            timeout_s, start, what=f"{kind} event {match or ''}",
        )

    def state(self, pred: Callable[[dict], bool] = lambda s: True, timeout_s: float = 30.0, start: int = 0,
              what: str = "state") -> tuple[int, dict]:
        return self.wait_for(lambda tp, m: tp == "state" and pred(m), timeout_s, start, what=what)

    def slice(self, start: int = 0, end: int | None = None, topic: str | None = None) -> list[dict]:
        with self.cond:
            part = self.msgs[start:end]
        return [m for _, tp, m in part if topic is None or tp == topic]

    def received(self, start: int = 0, end: int | None = None, topic: str | None = None
                 ) -> list[tuple[float, dict]]:
        """``(received_at, message)`` pairs (``time.monotonic`` of this process)."""
        with self.cond:
            part = self.msgs[start:end]
        return [(at, m) for at, tp, m in part if topic is None or tp == topic]

    def latest_state(self) -> dict:
        with self.cond:
            for _, tp, m in reversed(self.msgs):
                if tp == "state":
                    return m
        raise AssertionError("no state yet")


class DaemonProc:
    """One ``sa-daemon run`` subprocess with its own ports, files and collector.

    ``entry`` replaces the command that is started (default: the CLI module), e.g.
    ``[sys.executable, FAULTD, "--"]``; ``run`` replaces the arm/input/scene/task arguments; with
    ``stdin=True`` the process gets a stdin pipe and its ``FAULTD`` reply lines are read from stdout
    (:meth:`fault`). ``env`` adds environment variables.
    """

    def __init__(self, workdir: Path, *extra: str, config: str | None = None, entry: list[str] | None = None,
                 run: tuple[str, ...] = DEFAULT_RUN, stdin: bool = False, env: dict[str, str] | None = None) -> None:
        self.dir = workdir
        workdir.mkdir(parents=True, exist_ok=True)
        self.pub = f"tcp://127.0.0.1:{free_port()}"
        self.cmd = f"tcp://127.0.0.1:{free_port()}"
        self.collector = Collector(self.pub)
        self.collector.start()
        args = [*(entry or CLI)]
        if config is not None:
            cfg = workdir / "config.toml"
            cfg.write_text(config)
            args += ["--config", str(cfg)]
        args += ["run", *run, "--pub", self.pub, "--cmd", self.cmd, "--quiet", *extra]
        self.args = args
        self.stdout = open(workdir / "stdout.txt", "wb")  # noqa: SIM115
        self.stderr = open(workdir / "stderr.txt", "wb")  # noqa: SIM115
        self.replies: queue.Queue[dict] = queue.Queue()
        self.final: dict | None = None  # faultd's last line (exit code, the fake arm's last commands)
        penv = {**os.environ, **(env or {})}
        self.proc = subprocess.Popen(args, cwd=workdir, stdin=subprocess.PIPE if stdin else None,
                                     stdout=subprocess.PIPE if stdin else self.stdout, stderr=self.stderr, env=penv)
        self._reader: threading.Thread | None = None
        if stdin:
            self._reader = threading.Thread(target=self._read_stdout, daemon=True, name="test-faultd-out")
            self._reader.start()

    def _read_stdout(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            if line.startswith(b"FAULTD "):
                msg = json.loads(line[len(b"FAULTD "):])
                if "exit" in msg:
                    self.final = msg
                else:
                    self.replies.put(msg)
            else:
                self.stdout.write(line)

    def fault(self, line: str, timeout_s: float = 30.0) -> dict:
        """Send one faultd command and return its reply (raises if faultd refused it)."""
        assert self.proc.stdin is not None, "started without stdin=True"
        self.proc.stdin.write(line.encode() + b"\n")
        self.proc.stdin.flush()
        try:
            r = self.replies.get(timeout=timeout_s)
        except queue.Empty:
            raise AssertionError(f"faultd did not answer {line!r} within {timeout_s} s: {self.log}") from None
        assert r["cmd"] == line, r
        assert r["ok"], r
        return r

    @property
    def log(self) -> str:
        if not self.stderr.closed:
            self.stderr.flush()
        return (self.dir / "stderr.txt").read_text(errors="replace")[-3000:]

    def wait_ready(self) -> dict:
        try:
            _, ev = self.collector.event("ready", START_TIMEOUT_S)
        except AssertionError:
            alive = self.proc.poll() is None
            if alive and self._reader is not None:  # faultd: every thread's stack to stderr
                self.proc.send_signal(signal.SIGUSR1)
                time.sleep(1.0)
            got = self.collector.slice()
            raise AssertionError(
                f"daemon not ready (exit {self.proc.poll()}; {len(got)} messages, events "
                f"{[m['type'] for m in got if 'type' in m][:20]}): "
                f"{(self.dir / 'stderr.txt').read_text(errors='replace')[-12000:]}") from None
        return ev

    def request(self, obj: dict | bytes, timeout_s: float = 5.0) -> dict:
        return request(self.cmd, obj, timeout_s=timeout_s)

    def stop(self, sig: int = signal.SIGTERM, timeout_s: float = 30.0) -> int:
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
        try:
            rc = self.proc.wait(timeout_s)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            rc = self.proc.wait()
        if self._reader is not None:
            self._reader.join(5)
        return rc

    def close(self) -> None:
        if self.proc.poll() is None:
            self.stop()
        if self.proc.stdin is not None:
            try:
                self.proc.stdin.close()
            except OSError:
                pass
        self.collector.halt()
        if self._reader is not None:
            self._reader.join(5)
        self.stdout.close()
        self.stderr.close()


def predicted_input(cfg, p, q, kp, kq, g: int, mode, speed: tuple[float, float]) -> np.ndarray:
    """The watch model's predicted joystick twist (m/s, rad/s) at pose ``(p, q)`` for a user heading to
    goal ``g`` (``kp``, ``kq``: the goals' poses) in joystick ``mode`` at ``speed``: toward the pre-grasp
    point first in translation, toward the goal's orientation in rotation."""
    from sa_daemon.model.actions import Mode
    from sa_daemon.model.huber import pregrasp_points
    from sa_daemon.model.twists import user_angular, user_linear

    u = np.zeros(6)
    standoff = cfg.intent.user_standoff_m
    if mode is Mode.TRANSLATION:
        u[:3] = user_linear(p, kp[g], pregrasp_points(kp[g], kq[g], standoff), speed[0], standoff)
    else:
        u[3:] = user_angular(q, kq[g], speed[1])
    return u
