"""MCAP recording of the daemon's state (control rate) and events, readable by Foxglove.

Messages are JSON with a JSON-Schema per channel (``/state``, ``/event``), so Foxglove's plot panel
can plot any field. Encoding and disk writes happen in one writer thread fed by a bounded queue, never
on the event loop; the writer flushes a finished chunk at least every ``flush_s`` seconds, so a crash
(even SIGKILL) loses at most about that much. :func:`read_recording` reads a finished file, and also
one cut short by a crash, up to its last complete chunk.
"""

from __future__ import annotations

import json
import queue
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from mcap.records import Channel, Message
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, Writer

_VEC6 = {"type": "array", "items": {"type": "number"}, "minItems": 6, "maxItems": 6}
STATE_SCHEMA = {
    "type": "object",
    "title": "sa_daemon.State",
    "properties": {
        "t": {"type": "number", "description": "s since start"},
        "mode": {"type": "string"},
        "user_twist": _VEC6,
        "robot_twist": _VEC6,
        "command_twist": _VEC6,
        "gripper_pose": {
            "type": "object",
            "properties": {
                "position": {"type": "array", "items": {"type": "number"}},
                "quat_wxyz": {"type": "array", "items": {"type": "number"}},
            },
        },
        "belief": {"type": "object", "additionalProperties": {"type": "number"}},
        "action": {"type": "string"},
        "opposed": {"type": "boolean"},
        "safety": {"type": "string"},
        "question": {"type": ["string", "null"]},
    },
}
EVENT_SCHEMA = {
    "type": "object",
    "title": "sa_daemon.Event",
    "properties": {"t": {"type": "number"}, "type": {"type": "string"}},
}

_STOP = object()


class Recorder:
    """Write ``/state`` and ``/event`` messages to ``path`` from a background thread."""

    def __init__(self, path: str | Path, flush_s: float = 1.0, max_queue: int = 10000) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.flush_s = flush_s
        self.dropped = 0
        self.written = 0
        self._q: queue.Queue = queue.Queue(maxsize=max_queue)
        self._file = open(self.path, "wb")  # noqa: SIM115 - owned by the writer thread
        self._writer = Writer(self._file, compression=CompressionType.ZSTD)
        self._writer.start(profile="", library="sa-daemon")
        ids = {}
        for topic, schema in (("/state", STATE_SCHEMA), ("/event", EVENT_SCHEMA)):
            sid = self._writer.register_schema(schema["title"], "jsonschema", json.dumps(schema).encode())
            ids[topic] = self._writer.register_channel(topic, "json", sid)
        self._channels = ids
        self._writer.flush()
        self._thread = threading.Thread(target=self._run, name="sa-recorder", daemon=True)
        self._thread.start()

    def add(self, topic: str, msg: dict[str, Any], t_ns: int | None = None) -> None:
        """Queue ``msg`` on ``topic`` (``/state`` or ``/event``); never blocks (drops when full)."""
        try:
            self._q.put_nowait((topic, time.time_ns() if t_ns is None else t_ns, msg))
        except queue.Full:
            self.dropped += 1

    def _run(self) -> None:
        last_flush = time.monotonic()
        while True:
            try:
                item = self._q.get(timeout=self.flush_s / 2)
            except queue.Empty:
                item = None
            if item is _STOP:
                break
            if item is not None:
                topic, t_ns, msg = item
                try:
                    data = json.dumps(msg, separators=(",", ":")).encode()
                    self._writer.add_message(self._channels[topic], log_time=t_ns, data=data, publish_time=t_ns)
                    self.written += 1
                except (TypeError, ValueError, KeyError):  # not JSON, or no such topic: lose this one only
                    self.dropped += 1
            if time.monotonic() - last_flush >= self.flush_s:
                self._writer.flush()
                last_flush = time.monotonic()
        self._writer.finish()
        self._file.close()

    def close(self) -> None:
        """Write what is queued, finish the file (summary and footer) and close it. Idempotent."""
        if self._thread.is_alive():
            self._q.put(_STOP)
            self._thread.join()


def read_recording(path: str | Path) -> Iterator[tuple[str, int, dict[str, Any]]]:
    """Yield ``(topic, log_time_ns, message)`` in file order; a file cut short by a crash is read up
    to its last complete record."""
    channels: dict[int, str] = {}
    with open(path, "rb") as f:
        reader = StreamReader(f, skip_magic=False)
        try:
            for rec in reader.records:
                if isinstance(rec, Channel):
                    channels[rec.id] = rec.topic
                elif isinstance(rec, Message):
                    yield channels.get(rec.channel_id, "?"), rec.log_time, json.loads(rec.data)
        except Exception:  # noqa: BLE001
            # A torn last record (end of file, half a chunk, a bad CRC or zstd frame) ends the
            # recording: everything before it has been yielded.
            return
