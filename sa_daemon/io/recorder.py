"""MCAP recording of the daemon's state (control rate) and events, readable by Foxglove.

``/state`` and ``/event`` are JSON with a JSON-Schema per channel, so Foxglove's plot panel can plot
any field; more JSON topics are named with their schemas at construction (the live view's
``/belief``), and a Foxglove message (``foxglove.messages``: the live view's ``/scene``, ``/log``) is
written protobuf-encoded with the schema the SDK gives it, so a recording shows what the live view
showed (``docs/foxglove.md``). Encoding and disk writes happen in one writer thread fed by a bounded queue, never
on the event loop; the writer flushes a finished chunk at least every ``flush_s`` seconds, so a crash
(even SIGKILL) loses at most about that much. :func:`read_recording` reads a finished file, and also
one cut short by a crash, up to its last complete chunk.

A write that fails (a full disk: ``ENOSPC``; any ``OSError``) ends the recording, never the caller:
the file is closed and cut back to its last complete flush (so what was on disk before stays readable,
without a torn chunk at its end), :attr:`Recorder.error` says why, ``on_error`` is called once (from
the writer thread), and later messages are counted as dropped. The writer thread keeps draining its
queue, so :meth:`Recorder.add` and :meth:`Recorder.close` never wait on it.
"""

from __future__ import annotations

import errno
import json
import os
import queue
import threading
import time
from collections.abc import Callable, Iterator
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
BATCH_S = 0.02
"""The writer thread sleeps this long after each batch it writes (s)."""
BATCH_MAX = 1000
"""Messages written in one batch at most."""


class Recorder:
    """Write ``/state`` and ``/event`` messages to ``path`` from a background thread.

    ``on_error(text)`` is called once, from the writer thread, when a write fails and the recording
    stops (see the module doc).
    """

    def __init__(self, path: str | Path, flush_s: float = 1.0, max_queue: int = 10000,
                 on_error: Callable[[str], None] | None = None,
                 json_topics: dict[str, dict[str, Any]] | None = None) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.flush_s = flush_s
        self.dropped = 0
        self.written = 0  # messages handed to the MCAP writer
        self.flushed = 0  # of those, the ones in chunks flushed to the file without an error
        #: Why the recording stopped early (a failed write), else ``None``.
        self.error: str | None = None
        self._on_error = on_error
        self._q: queue.Queue = queue.Queue(maxsize=max_queue)
        self._file = open(self.path, "wb")  # noqa: SIM115 - owned by the writer thread
        self._writer = Writer(self._file, compression=CompressionType.ZSTD)
        self._writer.start(profile="", library="sa-daemon")
        ids = {}
        for topic, schema in {"/state": STATE_SCHEMA, "/event": EVENT_SCHEMA, **(json_topics or {})}.items():
            sid = self._writer.register_schema(schema["title"], "jsonschema", json.dumps(schema).encode())
            ids[topic] = self._writer.register_channel(topic, "json", sid)
        self._channels = ids
        self._typed: dict[str, int] = {}  # topic -> channel of Foxglove messages, registered on first use
        self._writer.flush()
        self._good_size = self._file.tell()  # the file up to its last complete flush
        self._thread = threading.Thread(target=self._run, name="sa-recorder", daemon=True)
        self._thread.start()

    def add(self, topic: str, msg: Any, t_ns: int | None = None) -> None:
        """Queue ``msg`` on ``topic``: a dict on a JSON topic (``/state``, ``/event``, or one given at
        construction), or a Foxglove message on any topic; never blocks (drops when full, and once the
        recording has stopped on a write error)."""
        if self.error is not None:
            self.dropped += 1
            return
        try:
            self._q.put_nowait((topic, time.time_ns() if t_ns is None else t_ns, msg))
        except queue.Full:
            self.dropped += 1

    def _run(self) -> None:
        try:
            self._write_until_stopped()
        except OSError as e:
            self._fail(e)
            while self._q.get() is not _STOP:  # drained, so that neither add() nor close() waits
                self.dropped += 1

    def _write_until_stopped(self) -> None:
        """Write in batches: wait for a message, take what else is queued, write it all, then sleep
        :data:`BATCH_S`, so that the thread wakes (and takes the interpreter's lock from the event loop)
        about 1 / BATCH_S times a second rather than once per message."""
        last_flush = time.monotonic()
        stop = False
        while not stop:
            try:
                batch = [self._q.get(timeout=self.flush_s / 2)]
            except queue.Empty:
                batch = []
            while batch and len(batch) < BATCH_MAX:
                try:
                    batch.append(self._q.get_nowait())
                except queue.Empty:
                    break
            for item in batch:
                if item is _STOP:
                    stop = True
                    break
                self._write(*item)
            if time.monotonic() - last_flush >= self.flush_s:
                self._writer.flush()
                self._flushed_ok()
                last_flush = time.monotonic()
            if batch and not stop:
                time.sleep(BATCH_S)
        self._writer.finish()
        self._file.close()
        self.flushed = self.written

    def _write(self, topic: str, t_ns: int, msg: Any) -> None:
        try:
            if isinstance(msg, dict):
                channel, data = self._channels[topic], json.dumps(msg, separators=(",", ":")).encode()
            else:
                channel, data = self._typed_channel(topic, msg), msg.encode()
            self._writer.add_message(channel, log_time=t_ns, data=data, publish_time=t_ns)
            self.written += 1
        except (TypeError, ValueError, KeyError, AttributeError):  # not JSON, no such topic, not a Foxglove
            self.dropped += 1  # message: lose this one only

    def _typed_channel(self, topic: str, msg: Any) -> int:
        """The channel of Foxglove messages on ``topic``, registered with the message type's schema."""
        if topic not in self._typed:
            if topic in self._channels:
                raise KeyError(topic)  # a JSON topic
            schema = type(msg).get_schema()
            sid = self._writer.register_schema(schema.name, schema.encoding, schema.data)
            self._typed[topic] = self._writer.register_channel(topic, schema.encoding, sid)
        return self._typed[topic]

    def _flushed_ok(self) -> None:
        self.flushed = self.written
        self._good_size = self._file.tell()

    def _fail(self, e: OSError) -> None:
        """A write failed: close the file, cut it back to its last complete flush, report once."""
        code = errno.errorcode.get(e.errno, str(e.errno)) if e.errno is not None else type(e).__name__
        self.dropped += self.written - self.flushed
        try:
            self._file.close()  # (flushing what is buffered fails again: the cut below removes it)
        except OSError:
            pass
        try:
            os.truncate(self.path, self._good_size)  # frees, never needs space
        except OSError:
            pass
        self.error = (f"recording stopped: {e.strerror or e} ({code}) writing {self.path}; "
                      f"the {self.flushed} messages before it are readable")
        if self._on_error is not None:
            try:
                self._on_error(self.error)
            except Exception:  # noqa: BLE001, S110 - a reporting failure must not kill the writer thread
                pass

    def close(self, timeout_s: float = 5.0) -> None:
        """Write what is queued, finish the file (summary and footer) and close it. Idempotent.
        Waits at most about ``timeout_s`` for the writer thread (a write blocked in the kernel cannot hold
        the daemon's shutdown)."""
        if self._thread.is_alive():
            try:
                self._q.put(_STOP, timeout=timeout_s)
            except queue.Full:
                return
            self._thread.join(timeout_s)


def read_recording(path: str | Path) -> Iterator[tuple[str, int, dict[str, Any]]]:
    """Yield ``(topic, log_time_ns, message)`` of the JSON topics in file order (the Foxglove messages
    of the live view are skipped); a file cut short by a crash is read up to its last complete record."""
    channels: dict[int, str] = {}
    with open(path, "rb") as f:
        reader = StreamReader(f, skip_magic=False)
        try:
            for rec in reader.records:
                if isinstance(rec, Channel):
                    if rec.message_encoding == "json":
                        channels[rec.id] = rec.topic
                elif isinstance(rec, Message) and rec.channel_id in channels:
                    yield channels[rec.channel_id], rec.log_time, json.loads(rec.data)
        except Exception:  # noqa: BLE001
            # A torn last record (end of file, half a chunk, a bad CRC or zstd frame) ends the
            # recording: everything before it has been yielded.
            return
