"""Offscreen rendering of a MuJoCo world to PNG files, without an image library.

Headless machines need an offscreen OpenGL backend chosen *before* ``mujoco`` is imported:
``MUJOCO_GL=egl`` (GPU or Mesa EGL) or ``MUJOCO_GL=osmesa`` (software). :func:`prefer_headless_gl`
picks EGL when no display exists and the variable is unset; ``sa_daemon.arm.mujoco_arm`` calls it on
import. On the development machine EGL works (Mesa) and OSMesa does not (no libOSMesa).
"""

from __future__ import annotations

import ctypes.util
import os
import struct
import zlib
from pathlib import Path

import numpy as np


def has_display() -> bool:
    """Whether an X11 or Wayland display is available (a window can be opened)."""
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def prefer_headless_gl() -> None:
    """Set ``MUJOCO_GL=egl`` if it is unset, there is no display and libEGL exists. Must run before the
    first ``import mujoco`` of the process to take effect; harmless afterwards."""
    if not os.environ.get("MUJOCO_GL") and not has_display() and ctypes.util.find_library("EGL"):
        os.environ["MUJOCO_GL"] = "egl"


def write_png(path: str | Path, rgb: np.ndarray) -> Path:
    """Write an ``H x W x 3`` uint8 image as an 8-bit RGB PNG (zlib only)."""
    img = np.ascontiguousarray(rgb, dtype=np.uint8)
    if img.ndim != 3 or img.shape[2] != 3:
        raise ValueError(f"expected an H x W x 3 image, got shape {img.shape}")
    h, w, _ = img.shape
    raw = b"".join(b"\x00" + img[i].tobytes() for i in range(h))  # filter type 0 on every row

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_bytes(
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
        + chunk(b"IDAT", zlib.compress(raw, 6))
        + chunk(b"IEND", b"")
    )
    return p


def read_png_size(path: str | Path) -> tuple[int, int]:
    """(width, height) from a PNG header (for checks)."""
    data = Path(path).read_bytes()[:24]
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        raise ValueError(f"{path} is not a PNG file")
    w, h = struct.unpack(">II", data[16:24])
    return w, h
