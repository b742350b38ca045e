"""The one espeak-ng engine of a process, in espeak-ng's synchronous mode.

espeak-ng's state is global to the library, so a process has one :class:`Engine` (:func:`engine`), on
the library :func:`.espeak.load` chose. It runs espeak-ng with ``AUDIO_OUTPUT_SYNCHRONOUS``: ``Synth``
returns once the whole utterance has gone through the callback, in the calling thread, so a voice, rate
or volume set before an utterance is the one it is spoken with, and the same text with the same
settings has the same timing in every process (the same samples with Debian's espeak-ng 1.51; the
wheel's 1.52 varies the noise of breathy variants such as ``+f2`` from process to process).

Why not pyttsx3 (sessions 1-23): its espeak driver starts espeak-ng in ``AUDIO_OUTPUT_RETRIEVAL``,
espeak-ng's asynchronous mode, where ``SetParameter`` is queued to espeak-ng's own thread while
``SetVoiceByName`` is not; measured on espeak-ng 1.51 and 1.52, an utterance at 120 words a minute
after one at 200 came out at either rate from run to run (`tests/test_speech.py` holds the fix), which
made a profile's rate unreliable and the voice tests' synthetic speech differ between runs.
"""

from __future__ import annotations

import ctypes
import threading
import wave
from pathlib import Path

import numpy as np

from . import espeak

AUDIO_OUTPUT_SYNCHRONOUS = 2
CHARS_UTF8 = 1
ENDPAUSE = 0x1000
POS_CHARACTER = 1
PARAM_RATE = 1
PARAM_VOLUME = 2
DEFAULT_VOICE = "en"
"""The voice for ``speech.voice = ""``: espeak-ng's English (``gmw/en``), which pyttsx3 used too."""

_Callback = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.POINTER(ctypes.c_short), ctypes.c_int, ctypes.c_void_p)


class Engine:
    """espeak-ng speaking 16-bit mono samples at :attr:`sample_rate_hz` (22050 Hz). Thread-safe: one
    utterance at a time. Make it with :func:`engine`."""

    def __init__(self, lib: ctypes.CDLL) -> None:
        lib.espeak_Initialize.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.c_char_p, ctypes.c_int]
        lib.espeak_SetVoiceByName.argtypes = [ctypes.c_char_p]
        lib.espeak_SetParameter.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.c_int]
        lib.espeak_Synth.argtypes = [ctypes.c_char_p, ctypes.c_size_t, ctypes.c_uint, ctypes.c_int, ctypes.c_uint,
                                     ctypes.c_uint, ctypes.c_void_p, ctypes.c_void_p]
        rate = lib.espeak_Initialize(AUDIO_OUTPUT_SYNCHRONOUS, 0, None, 0)
        if rate <= 0:
            raise espeak.SpeechUnavailable(f"espeak-ng did not initialise (espeak_Initialize returned {rate})")
        self._lib = lib
        self._rate_hz = int(rate)
        self._chunks: list[bytes] = []
        self._callback = _Callback(self._on_samples)  # kept: espeak-ng holds only the pointer
        lib.espeak_SetSynthCallback(self._callback)
        self._lock = threading.Lock()
        self._voice = ""
        self.configure(voice="")

    @property
    def sample_rate_hz(self) -> int:
        """The rate of the samples :meth:`synthesise` returns (Hz)."""
        return self._rate_hz

    @property
    def voice(self) -> str:
        """The voice set last (``""``: :data:`DEFAULT_VOICE`)."""
        return self._voice

    def _on_samples(self, wav, n: int, events) -> int:
        if n > 0 and wav:
            self._chunks.append(ctypes.string_at(wav, 2 * n))
        return 0  # go on

    def configure(self, rate_wpm: int | None = None, volume: float | None = None, voice: str | None = None) -> None:
        """Speak from the next utterance on with ``voice`` (an espeak-ng name, e.g. ``en-us+f3``; ``""``:
        :data:`DEFAULT_VOICE`), ``rate_wpm`` (words a minute) and ``volume`` (0-1, espeak-ng's 0-100);
        ``None`` keeps a setting. An unknown voice raises ``ValueError`` and changes nothing."""
        with self._lock:
            if voice is not None:
                status = self._lib.espeak_SetVoiceByName((voice or DEFAULT_VOICE).encode())
                if status != 0:
                    raise ValueError(f"espeak-ng has no voice {voice!r} (espeak_SetVoiceByName returned {status})")
                self._voice = voice
            if rate_wpm is not None:
                self._lib.espeak_SetParameter(PARAM_RATE, int(rate_wpm), 0)
            if volume is not None:
                self._lib.espeak_SetParameter(PARAM_VOLUME, round(100 * float(volume)), 0)

    def synthesise(self, text: str) -> np.ndarray:
        """``text`` spoken: int16 samples at :attr:`sample_rate_hz`, with espeak-ng's pause at the end."""
        data = text.encode("utf-8")
        with self._lock:
            self._chunks = []
            status = self._lib.espeak_Synth(data, len(data) + 1, 0, POS_CHARACTER, 0, CHARS_UTF8 | ENDPAUSE, None, None)
            chunks, self._chunks = self._chunks, []
        if status != 0:
            raise RuntimeError(f"espeak-ng could not speak {text!r} (espeak_Synth returned {status})")
        return np.frombuffer(b"".join(chunks), dtype="<i2").copy()

    def save_wav(self, text: str, path: str | Path) -> np.ndarray:
        """:meth:`synthesise` ``text`` into a 16-bit mono WAV at ``path``; returns the samples."""
        x = self.synthesise(text)
        with wave.open(str(path), "wb") as w:
            w.setnchannels(1)
            w.setsampwidth(2)
            w.setframerate(self._rate_hz)
            w.writeframes(x.astype("<i2").tobytes())
        return x


_engine: Engine | None = None
_engine_lock = threading.Lock()


def engine(library: str = "auto") -> Engine:
    """This process's engine, made on first use on the library :func:`.espeak.load` picks for ``library``
    (:class:`.espeak.SpeechUnavailable` if there is none)."""
    global _engine
    lib = espeak.load(library)
    with _engine_lock:
        if _engine is None:
            _engine = Engine(ctypes.CDLL(lib.path))
        return _engine
