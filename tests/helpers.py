"""Helpers shared by the tests that run real processes, sockets and audio (imported as ``helpers``:
pytest puts this folder on ``sys.path``)."""

from __future__ import annotations

import socket
import wave
from pathlib import Path

import numpy as np


def free_port() -> int:
    """A free loopback TCP port (bind to port 0, read it back, release it)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


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
