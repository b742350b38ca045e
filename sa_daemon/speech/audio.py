"""Audio in: sources of 16 kHz mono 16-bit PCM, and the cutter that finds utterances in them.

Sources (``voice.source``):

* ``alsa``: ``arecord -q -D DEVICE -t raw -f S16_LE -c 1 -r 16000`` (alsa-utils) writing raw PCM to a
  pipe; the microphone on a wheelchair computer;
* ``pcm:PATH``: raw 16-bit little-endian mono PCM at 16 kHz from a file or a FIFO (a test, a
  replayed recording, another program's audio);
* ``wav:PATH``: a 16-bit PCM WAV at any rate, resampled to 16 kHz.

:class:`UtteranceCutter` runs pocketsphinx's voice-activity endpointer over the stream and returns
each stretch of speech with the monotonic times it started and ended (taken when the audio arrived).
The microphone, ``sa-daemon hear`` and ``bench voice`` all go through it.
"""

from __future__ import annotations

import shutil
import subprocess
import time
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

import numpy as np

from ..extras import require
from .espeak import read_wav
from .recogniser import SAMPLE_RATE, AnswerRecogniser, Heard, to_16k

RECORDER = "arecord"
RECORDER_PACKAGE = "alsa-utils"


class AudioSource:
    """A stream of raw PCM (16 kHz, mono, int16 little-endian). ``read`` returns ``b""`` at the end."""

    description = "audio"

    def __init__(self, stream: BinaryIO) -> None:
        self._stream = stream

    def read(self, n_bytes: int) -> bytes:
        return self._stream.read(n_bytes) or b""

    def close(self) -> None:
        self._stream.close()


class ArecordSource(AudioSource):
    """The microphone through ``arecord`` (documented flags: ``-t raw -f S16_LE -c 1 -r 16000``)."""

    def __init__(self, device: str) -> None:
        if shutil.which(RECORDER) is None:
            raise OSError(f"voice.source alsa: {RECORDER} not found (install the {RECORDER_PACKAGE} package)")
        self._proc = subprocess.Popen(
            [RECORDER, "-q", "-D", device, "-t", "raw", "-f", "S16_LE", "-c", "1", "-r", str(SAMPLE_RATE)],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE,
        )
        assert self._proc.stdout is not None
        super().__init__(self._proc.stdout)
        self.description = f"alsa {device}"

    def read(self, n_bytes: int) -> bytes:
        data = super().read(n_bytes)
        if not data and self._exit_code() not in (None, 0):
            assert self._proc.stderr is not None
            err = self._proc.stderr.read().decode(errors="replace").strip().splitlines()
            raise OSError(f"{RECORDER} exited {self._proc.returncode}: {err[-1] if err else 'no message'}")
        return data

    def _exit_code(self) -> int | None:
        """The recorder's exit code once its output has ended (the end of the pipe comes just before
        the exit: wait for it briefly), or ``None`` if it is still running."""
        try:
            return self._proc.wait(1.0)
        except subprocess.TimeoutExpired:
            return None

    def close(self) -> None:
        self._proc.kill()
        self._proc.wait(2.0)
        super().close()


class ArraySource(AudioSource):
    """Samples already in memory (a WAV read whole): served in order, then the end."""

    def __init__(self, pcm: np.ndarray, description: str = "array") -> None:
        self._buf = np.ascontiguousarray(pcm, dtype="<i2").tobytes()
        self._pos = 0
        self.description = description

    def read(self, n_bytes: int) -> bytes:
        out = self._buf[self._pos:self._pos + n_bytes]
        self._pos += len(out)
        return out

    def close(self) -> None:
        self._buf = b""


def open_source(spec: str, device: str = "default") -> AudioSource:
    """The source that ``voice.source`` names (``OSError`` naming the key if it cannot be opened)."""
    kind, _, path = spec.partition(":")
    if spec == "alsa":
        return ArecordSource(device)
    try:
        if kind == "pcm":
            src = AudioSource(open(path, "rb", buffering=0))  # noqa: SIM115 - closed by close()
            src.description = f"pcm {path}"
            return src
        if kind == "wav":
            return ArraySource(wav_to_16k(path), f"wav {path}")
    except (OSError, ValueError) as e:
        raise OSError(f"voice.source {spec}: {e}") from None
    raise ValueError(f"voice.source must be alsa, pcm:PATH or wav:PATH, not {spec!r}")


@dataclass(frozen=True)
class Utterance:
    """One stretch of speech: its samples (16 kHz int16, with the endpointer's lead-in and tail) and
    the monotonic times (s) its first and last audio arrived."""

    pcm: np.ndarray
    t_start: float
    t_end: float

    @property
    def seconds(self) -> float:
        return len(self.pcm) / SAMPLE_RATE


class UtteranceCutter:
    """pocketsphinx's ``Endpointer`` over a stream: :meth:`feed` raw PCM as it arrives, get back the
    utterances that ended in it. ``max_s`` bounds one utterance (longer speech is cut there)."""

    def __init__(self, max_s: float = 30.0, window_s: float = 0.3, ratio: float = 0.9) -> None:
        ps = require("pocketsphinx", "voice")
        self._ep = ps.Endpointer(window=window_s, ratio=ratio, sample_rate=SAMPLE_RATE)
        self.frame_bytes = int(self._ep.frame_bytes)
        self._pending = b""
        self._speech: list[bytes] = []
        self._speech_bytes = 0
        self._t_start = 0.0
        self._max_bytes = int(max_s * SAMPLE_RATE) * 2

    def _close(self, now: float) -> Utterance:
        pcm = np.frombuffer(b"".join(self._speech), dtype="<i2").copy()
        self._speech, self._speech_bytes = [], 0
        return Utterance(pcm, self._t_start, now)

    def feed(self, data: bytes, now: float | None = None) -> list[Utterance]:
        """Audio that arrived at ``now`` (``time.monotonic()`` if not given); the utterances it ended."""
        now = time.monotonic() if now is None else now
        self._pending += data
        out = []
        fb = self.frame_bytes
        while len(self._pending) >= fb:
            frame, self._pending = self._pending[:fb], self._pending[fb:]
            was = self._ep.in_speech
            speech = self._ep.process(frame)
            if speech is None:
                continue
            if not was:
                self._t_start = now
            self._speech.append(bytes(speech))
            self._speech_bytes += len(speech)
            if not self._ep.in_speech or self._speech_bytes >= self._max_bytes:
                out.append(self._close(now))
        return out

    def end(self, now: float | None = None) -> list[Utterance]:
        """The stream ended: the utterance still open, if any (padded with silence to close it)."""
        now = time.monotonic() if now is None else now
        out = self.feed(bytes(2 * SAMPLE_RATE), now)  # 1 s of silence
        if self._speech:
            out.append(self._close(now))
        return out


def utterances_of(pcm: np.ndarray, max_s: float = 30.0) -> list[Utterance]:
    """Every utterance in samples already in memory (a WAV file), through the same cutter."""
    cutter = UtteranceCutter(max_s)
    return cutter.feed(np.ascontiguousarray(pcm, dtype="<i2").tobytes(), 0.0) + cutter.end(0.0)


def answer_in(pcm: np.ndarray, recogniser: AnswerRecogniser, min_confidence: float, max_segment_s: float,
              third: bool = False) -> tuple[str, float, list[Heard]]:
    """The answer in a recording (``sa-daemon hear``, ``bench voice``): its utterances are cut and
    recognised as the microphone's are; the answer is ``yes``/``no`` (or ``other`` with ``third``) when
    every utterance recognised at ``min_confidence`` or above, and no longer than ``max_segment_s``, says
    the same, else ``none``. Returns (answer, its confidence or the best one seen, every utterance's result)."""
    pad = np.zeros(SAMPLE_RATE // 2, dtype=np.int16)
    heard = [recogniser.recognise(u.pcm, third)
             for u in utterances_of(np.concatenate([pad, pcm, pad]), max_segment_s + 1)]
    answers = [h for h in heard if h.answer != "none" and h.confidence >= min_confidence
               and h.seconds <= max_segment_s]
    if answers and len({h.answer for h in answers}) == 1:
        best = max(answers, key=lambda h: h.confidence)
        return best.answer, best.confidence, heard
    return "none", max((h.confidence for h in heard), default=0.0), heard


def wav_to_16k(path: str | Path) -> np.ndarray:
    """A WAV file's first channel at 16 kHz."""
    x, rate = read_wav(path)
    return to_16k(x, rate)
