"""Which espeak-ng library speaks, loaded once per process (the engine that speaks with it: ``engine.py``).

Two libraries can answer:

* **system**: Debian's ``libespeak-ng1`` (with ``espeak-ng-data``), found by the dynamic loader;
* **wheel**: the ``espeakng-loader`` wheel, a pip dependency, which ships ``libespeak-ng.so.1``
  (espeak-ng 1.52) and its ``espeak-ng-data`` inside site-packages: speech after ``pip install``
  alone, with no system package.

:func:`load` picks one (``speech.library``: ``auto`` = the system's when present, else the wheel's;
or ``system`` / ``wheel``), opens it with ``RTLD_GLOBAL`` so that any later ``dlopen`` of the same
soname gets this one, and for the wheel sets ``ESPEAK_DATA_PATH`` to the wheel's data. A process can
hold one espeak-ng library only: the first :func:`load` decides, later calls return its result.
"""

from __future__ import annotations

import contextlib
import ctypes
import logging
import os
import threading
import wave
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

log = logging.getLogger(__name__)

SONAME = "libespeak-ng.so.1"
LIBRARIES = ("auto", "system", "wheel")


class SpeechUnavailable(RuntimeError):
    """No espeak-ng library could be loaded (the message says what was tried)."""


@dataclass(frozen=True)
class EspeakLibrary:
    """The loaded library: ``source`` (``system`` or ``wheel``), its ``path``, the espeak-ng
    ``version`` it reports and its data directory (``None``: the library's built-in default)."""

    source: str
    path: str
    version: str
    data_path: str | None

    def as_dict(self) -> dict[str, Any]:
        return {"source": self.source, "path": self.path, "version": self.version, "data_path": self.data_path}


_lock = threading.Lock()
_loaded: EspeakLibrary | None = None
_error: str | None = None


def _version(lib: ctypes.CDLL) -> str:
    lib.espeak_Info.restype = ctypes.c_char_p
    lib.espeak_Info.argtypes = [ctypes.POINTER(ctypes.c_char_p)]
    v = lib.espeak_Info(None)
    return v.decode() if v else "unknown"


def _mapped_path(fallback: str) -> str:
    """The espeak-ng file the loader mapped into this process (from ``/proc/self/maps``), else ``fallback``."""
    with contextlib.suppress(OSError):
        for line in Path("/proc/self/maps").read_text().splitlines():
            if "libespeak-ng" in line and "/" in line:
                return line[line.index("/"):]
    return fallback


def _system() -> EspeakLibrary:
    lib = ctypes.CDLL(SONAME, mode=ctypes.RTLD_GLOBAL)
    return EspeakLibrary("system", _mapped_path(SONAME), _version(lib), None)


def _wheel() -> EspeakLibrary:
    try:
        import espeakng_loader
    except ImportError as e:
        raise OSError(f"the espeakng-loader wheel is not installed ({e}): pip install espeakng-loader") from e
    data = espeakng_loader.get_data_path()
    path = str(Path(espeakng_loader.get_library_path()).with_name(SONAME))
    if not Path(path).exists():
        path = espeakng_loader.get_library_path()
    os.environ["ESPEAK_DATA_PATH"] = data  # read by espeak_Initialize when the engine starts
    lib = ctypes.CDLL(path, mode=ctypes.RTLD_GLOBAL)
    return EspeakLibrary("wheel", path, _version(lib), data)


def load(library: str = "auto") -> EspeakLibrary:
    """Load espeak-ng once for this process (see the module doc); :class:`SpeechUnavailable` if none."""
    global _loaded, _error
    if library not in LIBRARIES:
        raise ValueError(f"speech.library must be one of {', '.join(LIBRARIES)}, not {library!r}")
    with _lock:
        if _loaded is not None:
            return _loaded
        if _error is not None:
            raise SpeechUnavailable(_error)
        order = {"auto": (_system, _wheel), "system": (_system,), "wheel": (_wheel,)}[library]
        tried = []
        for candidate in order:
            try:
                _loaded = candidate()
            except OSError as e:
                tried.append(f"{candidate.__name__.strip('_')}: {e}")
                continue
            log.info("espeak-ng %s from the %s library %s", _loaded.version, _loaded.source, _loaded.path)
            return _loaded
        _error = "no espeak-ng library (" + "; ".join(tried) + ")"
        raise SpeechUnavailable(_error)


def loaded() -> EspeakLibrary | None:
    """The library this process loaded, if any."""
    return _loaded


def read_wav(path: str | Path) -> tuple[np.ndarray, int]:
    """A 16-bit PCM WAV as (int16 samples of its first channel, sample rate in Hz)."""
    with wave.open(str(path), "rb") as w:
        if w.getsampwidth() != 2:
            raise ValueError(f"{path}: {8 * w.getsampwidth()}-bit WAV; 16-bit PCM expected")
        x = np.frombuffer(w.readframes(w.getnframes()), dtype="<i2")
        return x[:: w.getnchannels()].copy(), w.getframerate()

