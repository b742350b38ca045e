"""Answers by voice: audio capture and recognition in a spawned process, gated by the daemon.

The process (``sa-voice``) reads its :mod:`.audio` source all the time, cuts utterances, and
recognises only those that lie inside the listening window the daemon opened for the pending
question: from ``after_speech_s`` after the robot finished speaking the question until ``listen_s``
later, with the answers that question takes (yes/no, and "other grasp" with ``asking.third_answer``).
Speech that started before the window opened (the robot's own voice, its echo) and anything while no
window is open is dropped without decoding, so the robot never answers itself. Decoding
(up to 0.4 s) runs in this process, never on the daemon's event loop or under its interpreter lock.

Messages on the pipe: daemon -> process ``("listen", qid, t_open, t_close, third)`` (monotonic s; ``third``:
the third answer is one),
``("mute",)``, ``None`` (exit); process -> daemon ``("hello", pid, source)``, ``("heard", qid,
Heard.as_dict(), t_start, t_end)``, ``("error", text)`` (the source failed or ended; the process
exits).
"""

from __future__ import annotations

import asyncio
import multiprocessing as mp
import os
import threading
from collections.abc import Callable
from multiprocessing.connection import Connection

from ..config import VoiceConfig

CHUNK_BYTES = 3200  # 0.1 s of 16 kHz int16


def _listener_main(conn: Connection, cfg_data: dict) -> None:
    """Entry point of the voice process."""
    from .audio import UtteranceCutter, open_source
    from .recogniser import AnswerRecogniser, Heard

    cfg = VoiceConfig.model_validate(cfg_data)
    try:
        os.nice(5)  # below the daemon, like the planner
    except OSError:
        pass
    window: list = [None]  # (qid, t_open, t_close, third) or None; written by the control thread
    lock = threading.Lock()

    def control() -> None:
        while True:
            try:
                msg = conn.recv()
            except (EOFError, OSError):
                msg = None
            if msg is None:
                os._exit(0)  # the daemon stopped: leave the blocking read behind
            with lock:
                window[0] = tuple(msg[1:]) if msg[0] == "listen" else None

    try:
        recogniser = AnswerRecogniser()
        cutter = UtteranceCutter(max_s=cfg.max_segment_s + 1.0)
        source = open_source(cfg.source, cfg.device)
    except Exception as e:  # noqa: BLE001 - reported to the daemon, which goes on without voice
        conn.send(("error", f"{type(e).__name__}: {e}"))
        return
    conn.send(("hello", os.getpid(), source.description))
    threading.Thread(target=control, name="sa-voice-control", daemon=True).start()
    try:
        while True:
            data = source.read(CHUNK_BYTES)
            if not data:
                conn.send(("error", f"the audio source ended ({source.description})"))
                return
            for u in cutter.feed(data):
                with lock:
                    w = window[0]
                if w is None or u.t_start < w[1] or u.t_start > w[2]:
                    continue  # no question pending, or the robot's own speech
                if u.seconds > cfg.max_segment_s:  # not decoded
                    heard = {**Heard("none", 0.0, "", "", u.seconds, 0.0).as_dict(), "reason": "too long for an answer"}
                    conn.send(("heard", w[0], heard, u.t_start, u.t_end))
                    continue
                conn.send(("heard", w[0], recogniser.recognise(u.pcm, w[3]).as_dict(), u.t_start, u.t_end))
    except (OSError, BrokenPipeError) as e:
        try:
            conn.send(("error", f"{type(e).__name__}: {e}"))
        except OSError:
            pass
    finally:
        source.close()


class VoiceListener:
    """Daemon-side handle of the voice process (use from the event loop only)."""

    def __init__(self, cfg: VoiceConfig, on_heard: Callable[[int, dict, float, float], None],
                 on_error: Callable[[str], None]) -> None:
        self._cfg = cfg
        self._on_heard, self._on_error = on_heard, on_error
        self._ctx = mp.get_context("spawn")
        self._proc: mp.process.BaseProcess | None = None
        self._conn: Connection | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self.pid: int | None = None
        self.source: str | None = None
        self.error: str | None = None
        self.heard = 0
        self.window: tuple[int, float, float, bool] | None = None

    @property
    def ready(self) -> bool:
        return self.source is not None and self._conn is not None

    def start(self) -> None:
        self._loop = asyncio.get_running_loop()
        parent, child = self._ctx.Pipe(duplex=True)
        proc = self._ctx.Process(target=_listener_main, args=(child, self._cfg.model_dump()), daemon=True,
                                 name="sa-voice")
        proc.start()
        child.close()
        self._proc, self._conn, self.pid = proc, parent, proc.pid
        self._loop.add_reader(parent.fileno(), self._readable)

    def listen(self, qid: int, t_open: float, t_close: float, third: bool = False) -> None:
        """Open the window for question ``qid`` (monotonic s); ``third``: "other grasp" is an answer."""
        self.window = (qid, t_open, t_close, third)
        self._send(("listen", qid, t_open, t_close, third))

    def mute(self) -> None:
        if self.window is not None:
            self.window = None
            self._send(("mute",))

    def _send(self, msg: tuple) -> None:
        if self._conn is not None:
            try:
                self._conn.send(msg)
            except OSError:
                pass

    def _readable(self) -> None:
        conn = self._conn
        if conn is None:
            return
        try:
            while conn.poll():
                msg = conn.recv()
                if msg[0] == "hello":
                    self.pid, self.source = int(msg[1]), str(msg[2])
                elif msg[0] == "heard":
                    self.heard += 1
                    self._on_heard(int(msg[1]), dict(msg[2]), float(msg[3]), float(msg[4]))
                else:
                    self._fail(str(msg[1]))
                    return
        except (EOFError, OSError):
            self._fail("the voice process ended")

    def _fail(self, text: str) -> None:
        self.error = text
        self._detach()
        self._on_error(text)

    def _detach(self) -> None:
        if self._conn is not None and self._loop is not None:
            self._loop.remove_reader(self._conn.fileno())
            self._conn.close()
        self._conn = None

    def status(self) -> dict:
        return {"pid": self.pid, "source": self.source, "listening": self.window is not None,
                "heard": self.heard, "error": self.error}

    def stop(self, timeout_s: float = 1.0) -> None:
        self._send(None)  # type: ignore[arg-type]
        self._detach()
        proc = self._proc
        if proc is not None:
            proc.join(timeout_s)
            if proc.is_alive():
                proc.kill()
                proc.join(1.0)
        self._proc = None
