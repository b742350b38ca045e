"""Spoken questions: pyttsx3 with espeak-ng, in one dedicated worker thread.

pyttsx3 blocks in ``runAndWait`` and must create and run its engine in one thread, so every
utterance goes through a queue to a single ``sa-speech`` thread; the event loop only enqueues. Each
utterance is synthesised with ``save_to_file`` to a 16-bit mono 22050 Hz WAV (in ``speech.wav_dir``
when set, else a temporary file) and played with ``aplay``. Why not ``engine.say``: in pyttsx3 2.99 the
espeak driver keeps the last ``save_to_file`` path, so a later ``say`` overwrites that file instead of
playing; and ``aplay`` as a subprocess can be given a timeout. If no engine can be created, the
speaker says so once (``available`` false, ``error`` set) and the daemon goes on with published text.
A hung engine blocks only its own thread: new utterances are dropped while one is pending too long.
"""

from __future__ import annotations

import contextlib
import io
import logging
import os
import queue
import re
import shutil
import subprocess
import tempfile
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..config import SpeechConfig

log = logging.getLogger(__name__)


def question_text(target: str) -> str:
    """``"cup:top"`` -> ``"Is the cup with top grasp your goal?"`` (underscores read as spaces)."""
    obj, _, grasp = target.partition(":")
    grasp = grasp.replace("_", " ").strip()
    return f"Is the {obj} with {grasp} grasp your goal?" if grasp else f"Is the {obj} your goal?"


@dataclass(frozen=True)
class Spoken:
    """What happened to one utterance: its WAV (``None`` if synthesis failed), whether it played,
    the time it took (s) and an error text."""

    text: str
    wav: str | None
    played: bool
    seconds: float
    error: str | None = None


EngineFactory = Callable[[], Any]


def _pyttsx3_engine() -> Any:
    import pyttsx3

    return pyttsx3.init()


class Speaker:
    """Queue utterances to the speech thread; ``on_done(Spoken)`` is called from that thread."""

    def __init__(
        self,
        cfg: SpeechConfig,
        on_done: Callable[[Spoken], None] = lambda s: None,
        engine_factory: EngineFactory = _pyttsx3_engine,
        max_pending: int = 4,
    ) -> None:
        self.cfg = cfg
        self.on_done = on_done
        self._factory = engine_factory
        self._q: queue.Queue = queue.Queue(maxsize=max_pending)
        self._ready = threading.Event()
        self.available = False
        self.error: str | None = None
        self.dropped = 0
        self.busy_since: float | None = None  # time.monotonic() when the current utterance started
        self._player: subprocess.Popen | None = None  # the aplay process playing now
        self._count = 0
        self._thread = threading.Thread(target=self._run, name="sa-speech", daemon=True)
        self._thread.start()

    def wait_ready(self, timeout_s: float = 5.0) -> bool:
        """Block until the engine is up (or failed); ``True`` if it is available."""
        self._ready.wait(timeout_s)
        return self.available

    def say(self, text: str) -> bool:
        """Queue ``text``; ``False`` if dropped (no engine, or too many pending: a hung engine)."""
        if not self.available:
            return False
        try:
            self._q.put_nowait(text)
        except queue.Full:
            self.dropped += 1
            return False
        return True

    def _run(self) -> None:
        try:
            engine = self._factory()
            engine.setProperty("rate", self.cfg.rate_wpm)
            engine.setProperty("volume", self.cfg.volume)
            self.available = True
        except Exception as e:  # noqa: BLE001 - no engine: say so once, go on without speech
            self.error = f"speech unavailable: {type(e).__name__}: {e}"
            self._ready.set()
            return
        self._ready.set()
        while True:
            text = self._q.get()
            if text is None:
                return
            self.busy_since = time.monotonic()
            try:
                spoken = self._speak(engine, text)
            except Exception as e:  # noqa: BLE001 - one failed utterance must not end speech
                spoken = Spoken(text, None, False, time.monotonic() - self.busy_since, f"{type(e).__name__}: {e}")
            self.busy_since = None
            try:
                self.on_done(spoken)
            except Exception:
                log.exception("speech callback failed")

    def _wav_path(self, text: str) -> tuple[Path, bool]:
        self._count += 1
        if self.cfg.wav_dir:
            d = Path(self.cfg.wav_dir)
            d.mkdir(parents=True, exist_ok=True)
            slug = re.sub(r"[^a-z0-9]+", "-", text.lower()).strip("-")[:48]
            return d / f"{time.strftime('%Y%m%d-%H%M%S')}-{self._count:04d}-{slug}.wav", True
        fd, name = tempfile.mkstemp(suffix=".wav", prefix="sa-speech-")
        os.close(fd)
        return Path(name), False

    def _speak(self, engine: Any, text: str) -> Spoken:
        t0 = time.monotonic()
        path, keep = self._wav_path(text)
        with contextlib.redirect_stdout(io.StringIO()):  # pyttsx3 prints "Audio saved to ..."
            engine.save_to_file(text, str(path))
            engine.runAndWait()
        played, err = False, None
        if self.cfg.play:
            if shutil.which("aplay") is None:
                err = "aplay not found (install alsa-utils)"
            else:
                returncode, stderr = self._play(path)
                played = returncode == 0
                if not played:
                    lines = stderr.decode(errors="replace").strip().splitlines()
                    err = f"aplay: {lines[-1][:200]}" if lines else "aplay failed"
        if not keep:
            path.unlink(missing_ok=True)
        return Spoken(text, str(path) if keep else None, played, time.monotonic() - t0, err)

    def _play(self, path: Path) -> tuple[int, bytes]:
        """Run ``aplay`` (killed after 60 s, or by :meth:`close`): its exit code and stderr."""
        proc = subprocess.Popen(["aplay", "-q", str(path)], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        self._player = proc
        try:
            _, err = proc.communicate(timeout=60)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.communicate()
            raise
        finally:
            self._player = None
        return proc.returncode, err

    def close(self, timeout_s: float = 2.0) -> None:
        """Stop the thread after the current utterance (a hung engine is abandoned: daemon thread; a hung
        player is killed, so it does not outlive the daemon)."""
        with contextlib.suppress(queue.Empty):  # drop what is still queued, so the stop always fits
            while True:
                self._q.get_nowait()
        player = self._player
        if player is not None:
            with contextlib.suppress(OSError):
                player.kill()
        with contextlib.suppress(queue.Full):
            self._q.put_nowait(None)
        self._thread.join(timeout_s)
