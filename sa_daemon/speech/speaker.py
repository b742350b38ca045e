"""Spoken questions: espeak-ng, in one dedicated worker thread.

Synthesis blocks for a fraction of a second, so every utterance goes through a queue to a single
``sa-speech`` thread; the event loop only enqueues. Each utterance is synthesised by the process's
espeak-ng engine (``engine.py``, synchronous: the voice, rate and volume set are the ones spoken) to a
16-bit mono 22050 Hz WAV (in ``speech.wav_dir`` when set, else a temporary file) and played with
``aplay``, a subprocess that can be given a timeout.

The espeak-ng library is the system's or the ``espeakng-loader`` wheel's (``espeak.py``), so speech
needs no system package. What happens to each question is one of :data:`SPEECH_STATES`, decided when
the engine comes up (:attr:`Speaker.mode`): ``played`` (synthesised and played through ``aplay``),
``written`` (synthesised to a WAV only: ``speech.play`` is off, or no ``aplay`` is installed, which
:attr:`Speaker.player_missing` names once) or ``unavailable`` (no engine). If no engine can be created,
the speaker says so once (``available`` false, ``error`` set) and the daemon goes on with published
text. A hung engine blocks only its own thread: new utterances are dropped while one is pending too long.
"""

from __future__ import annotations

import contextlib
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
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from ..config import SpeechConfig
from . import engine as espeak_engine
from . import espeak

log = logging.getLogger(__name__)


def _spoken_target(target: str) -> tuple[str, str]:
    """``"meat can:side_horizontal"`` -> ``("meat can", "side horizontal")`` (underscores read as spaces)."""
    obj, _, grasp = target.partition(":")
    return obj, grasp.replace("_", " ").strip()


def question_text(target: str) -> str:
    """``"cup:top"`` -> ``"Is the cup with top grasp your goal?"``."""
    obj, grasp = _spoken_target(target)
    return f"Is the {obj} with {grasp} grasp your goal?" if grasp else f"Is the {obj} your goal?"


def echo_text(answer: str, target: str) -> str:
    """What the robot says back after a spoken answer (``yes``, ``no`` or ``other``): ``"Yes: the cup,
    top grasp"``, ``"Another grasp of the cup"``."""
    obj, grasp = _spoken_target(target)
    if answer == "other":
        return f"Another grasp of the {obj}"
    return f"{'Yes' if answer == 'yes' else 'No'}: the {obj}" + (f", {grasp} grasp" if grasp else "")


SPEECH_STATES = ("played", "written", "unavailable")
"""What happens to a question's speech (the ``spoken`` field of the ``question`` event)."""

PLAYER = "aplay"
PLAYER_PACKAGE = "alsa-utils"  # the Debian/Ubuntu package that brings aplay


@dataclass(frozen=True)
class Spoken:
    """What happened to one utterance. ``outcome``: ``played``; ``written`` (synthesised, not played:
    playing is off, there is no player, or the player failed, and then ``error`` says why); or
    ``failed`` (synthesis failed, ``error`` says why). ``error`` also names a voice the engine refused
    just before this utterance (the previous voice spoke it). ``wav`` is the file kept in
    ``speech.wav_dir`` (``None`` without one), ``seconds`` the time synthesis and playing took."""

    text: str
    outcome: str
    wav: str | None
    seconds: float
    error: str | None = None

    @property
    def played(self) -> bool:
        return self.outcome == "played"


EngineFactory = Callable[[], Any]


class Speaker:
    """Queue utterances to the speech thread; ``on_done(Spoken)`` is called from that thread."""

    def __init__(
        self,
        cfg: SpeechConfig,
        on_done: Callable[[Spoken], None] = lambda s: None,
        engine_factory: EngineFactory | None = None,
        max_pending: int = 4,
    ) -> None:
        """``engine_factory`` makes the engine in the speech thread (default: the process's espeak-ng
        engine on the library ``speech.library`` selects): an object with :class:`~.engine.Engine`'s
        ``configure(rate_wpm, volume, voice)`` and ``save_wav(text, path)``."""
        self.cfg = cfg
        self.on_done = on_done
        self._factory = engine_factory or (lambda: espeak_engine.engine(cfg.library))
        self._q: queue.Queue = queue.Queue(maxsize=max_pending)
        self._ready = threading.Event()
        self._available = False
        self._error: str | None = None
        self._player_path = shutil.which(PLAYER) if cfg.play else None
        self.dropped = 0
        self._reconfigured = False  # configure() was called: set voice, rate, volume before the next utterance
        self.busy_since: float | None = None  # time.monotonic() when the current utterance started
        self._player: subprocess.Popen | None = None  # the aplay process playing now
        self._count = 0
        self._thread = threading.Thread(target=self._run, name="sa-speech", daemon=True)
        self._thread.start()

    # -- what this speaker can do ------------------------------------------------------------------------

    @property
    def available(self) -> bool:
        """The engine is up (read after :meth:`wait_ready`)."""
        return self._available

    @property
    def error(self) -> str | None:
        """Why there is no engine, or ``None``."""
        return self._error

    @property
    def mode(self) -> str:
        """What happens to each utterance: one of :data:`SPEECH_STATES`."""
        if not self._available:
            return "unavailable"
        return "played" if self._player_path is not None else "written"

    @property
    def player_missing(self) -> str | None:
        """A sentence naming the missing player and its package when playing is on but ``aplay`` is not
        installed; else ``None``."""
        if not self.cfg.play or self._player_path is not None:
            return None
        return (f"{PLAYER} not found: questions are written as WAV files, not played "
                f"(install the {PLAYER_PACKAGE} package, e.g. apt-get install {PLAYER_PACKAGE})")

    def status(self) -> dict[str, Any]:
        """For the daemon's ``status`` reply."""
        lib = espeak.loaded()
        return {"mode": self.mode, "library": lib.as_dict() if lib is not None else None,
                "player": self._player_path, "error": self._error, "dropped": self.dropped}

    # -- use ---------------------------------------------------------------------------------------------

    def wait_ready(self, timeout_s: float = 5.0) -> bool:
        """Block until the engine is up (or failed); ``True`` if it is available."""
        self._ready.wait(timeout_s)
        return self._available

    def say(self, text: str) -> bool:
        """Queue ``text``; ``False`` if dropped (no engine, or too many pending: a hung engine)."""
        if not self._available:
            return False
        try:
            self._q.put_nowait(text)
        except queue.Full:
            self.dropped += 1
            return False
        return True

    def configure(self, cfg: Any) -> None:
        """New voice, rate and volume (a person's profile), used from the next utterance on."""
        self.cfg = cfg
        self._reconfigured = True

    @property
    def speaking(self) -> bool:
        """An utterance is being synthesised or played (or waits for that)."""
        return self.busy_since is not None or not self._q.empty()

    def _run(self) -> None:
        try:
            engine = self._factory()
            self._set_voice(engine)
            self._available = True
        except Exception as e:  # noqa: BLE001 - no engine: say so once, go on without speech
            self._error = f"speech unavailable: {type(e).__name__}: {e}"
            self._ready.set()
            return
        self._ready.set()
        while True:
            text = self._q.get()
            if text is None:
                return
            kept = None
            if self._reconfigured:
                self._reconfigured = False
                try:
                    self._set_voice(engine)
                except ValueError as e:  # an unknown voice changes nothing: the previous one speaks on
                    kept = f"{e}; kept the previous voice"
                    log.warning("%s", kept)
            self.busy_since = time.monotonic()
            try:
                spoken = self._speak(engine, text)
                if kept is not None:
                    spoken = replace(spoken, error=kept if spoken.error is None else f"{kept}; {spoken.error}")
            except Exception as e:  # noqa: BLE001 - one failed utterance must not end speech
                spoken = Spoken(text, "failed", None, time.monotonic() - self.busy_since, f"{type(e).__name__}: {e}")
            self.busy_since = None
            try:
                self.on_done(spoken)
            except Exception:
                log.exception("speech callback failed")

    def _set_voice(self, engine: Any) -> None:
        """The engine speaks with ``cfg``'s voice (an espeak-ng name, e.g. en-us; ``""``: the default), rate
        and volume; an unknown voice raises ``ValueError`` and changes nothing."""
        try:
            engine.configure(rate_wpm=self.cfg.rate_wpm, volume=self.cfg.volume, voice=self.cfg.voice)
        except ValueError as e:
            raise ValueError(f"speech.voice: {e}") from None

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
        try:
            engine.save_wav(text, path)
            outcome, err = "written", None
            if self._player_path is not None:
                try:
                    returncode, stderr = self._play(path)
                except OSError as e:  # the player went away since start-up
                    returncode, stderr = -1, str(e).encode()
                if returncode == 0:
                    outcome = "played"
                else:
                    lines = stderr.decode(errors="replace").strip().splitlines()
                    err = f"{PLAYER}: {lines[-1][:200]}" if lines else f"{PLAYER} failed"
        finally:
            if not keep:
                path.unlink(missing_ok=True)
        return Spoken(text, outcome, str(path) if keep else None, time.monotonic() - t0, err)

    def _play(self, path: Path) -> tuple[int, bytes]:
        """Run ``aplay`` (killed after 60 s, or by :meth:`close`): its exit code and stderr."""
        proc = subprocess.Popen([PLAYER, "-q", str(path)], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
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
