"""MCAP recording: readable by read_recording and by mcap's own reader, while being written, and cut short."""

from __future__ import annotations

import json
import shutil
import time
from pathlib import Path

from helpers import fill_disk, small_disk, until
from mcap.reader import make_reader

from sa_daemon.io.recorder import Recorder, read_recording


def _state(i: int) -> dict:
    return {
        "t": round(i * 0.01, 4), "mode": "translation", "user_twist": [0.01 * i, 0, 0, 0, 0, 0],
        "robot_twist": [0.0] * 6, "command_twist": [0.0] * 6,
        "gripper_pose": {"position": [0.25, 0.0, 0.35], "quat_wxyz": [0.0, 1.0, 0.0, 0.0]},
        "belief": {"cup:top": 0.5, "bowl:top": 0.5}, "action": "none", "opposed": False, "safety": "ok",
        "question": None, "i": i,
    }


def _write(path: Path, n_states: int, flush_s: float = 1.0) -> Recorder:
    rec = Recorder(path, flush_s=flush_s)
    rec.add("/event", {"t": 0.0, "type": "ready"})
    for i in range(n_states):
        rec.add("/state", _state(i), t_ns=1_000_000_000 + i * 10_000_000)
        if i == n_states // 2:
            rec.add("/event", {"t": i * 0.01, "type": "question", "goal": "cup:top"})
    rec.add("/event", {"t": n_states * 0.01, "type": "stopped", "code": 0})
    return rec


def test_state_and_event_round_trip(tmp_path):
    path = tmp_path / "sub" / "run.mcap"  # the folder is created
    rec = _write(path, 300)
    rec.close()
    assert rec.written == 303 and rec.dropped == 0
    msgs = list(read_recording(path))
    states = [m for topic, _, m in msgs if topic == "/state"]
    events = [m for topic, _, m in msgs if topic == "/event"]
    assert [s["i"] for s in states] == list(range(300))
    assert states[7] == _state(7)
    assert [e["type"] for e in events] == ["ready", "question", "stopped"]
    log_times = [t for topic, t, _ in msgs if topic == "/state"]
    assert log_times == [1_000_000_000 + i * 10_000_000 for i in range(300)]


def test_mcap_reader_sees_json_channels_with_json_schemas(tmp_path):
    path = tmp_path / "run.mcap"
    _write(path, 50).close()
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None and summary.statistics.message_count == 53
        topics = {}
        for schema, channel, message in reader.iter_messages():
            assert schema.encoding == "jsonschema"
            assert channel.message_encoding == "json"
            json.loads(schema.data)  # the schema itself is JSON
            topics.setdefault(channel.topic, []).append(json.loads(message.data))
    assert set(topics) == {"/state", "/event"}
    assert len(topics["/state"]) == 50 and len(topics["/event"]) == 3
    schemas = {c.topic: summary.schemas[c.schema_id] for c in summary.channels.values()}
    assert json.loads(schemas["/state"].data)["properties"]["command_twist"]["maxItems"] == 6
    assert schemas["/event"].name == "sa_daemon.Event"


def test_a_copy_taken_while_recording_is_readable_up_to_the_flush(tmp_path):
    path = tmp_path / "live.mcap"
    rec = Recorder(path, flush_s=0.2)
    try:
        for i in range(100):
            rec.add("/state", _state(i))
        until(lambda: rec.written == 100, 20.0, "writer caught up")

        def copy_has_all() -> list:
            snap = tmp_path / "snap.mcap"
            shutil.copyfile(path, snap)  # the file as a crash would leave it
            states = [m for topic, _, m in read_recording(snap) if topic == "/state"]
            return states if len(states) == 100 else []

        states = until(copy_has_all, 20.0, "flushed data on disk")
        assert [s["i"] for s in states] == list(range(100))
        for i in range(100, 150):  # still recording, later messages follow
            rec.add("/state", _state(i))
    finally:
        rec.close()
    assert [m["i"] for topic, _, m in read_recording(path) if topic == "/state"] == list(range(150))


def test_truncated_files_are_read_up_to_the_last_complete_record(tmp_path):
    path = tmp_path / "full.mcap"
    rec = Recorder(path, flush_s=0.05)
    for i in range(400):
        rec.add("/state", _state(i))
        if i % 50 == 49:
            until(lambda n=i + 1: rec.written == n, 20.0)
            time.sleep(0.06)  # let a flush close the chunk: several chunks in the file
    rec.close()
    data = path.read_bytes()
    full = [m["i"] for topic, _, m in read_recording(path) if topic == "/state"]
    assert full == list(range(400))
    cut = tmp_path / "cut.mcap"
    counts = []
    for n in sorted({*range(0, len(data), max(1, len(data) // 97)), 1, 7, 8, 9, len(data) - 1}):
        cut.write_bytes(data[:n])
        got = [m["i"] for topic, _, m in read_recording(cut) if topic == "/state"]  # never raises
        assert got == list(range(len(got))), f"cut at {n}: not a prefix"
        counts.append(got and len(got))
    counts = [c or 0 for c in counts]
    assert counts == sorted(counts)  # more bytes never means fewer messages
    assert 0 < max(counts[:-1]) and len({*counts}) >= 4  # several chunks were recovered one by one
    assert counts[-1] == 400  # only the footer missing: everything is there


def test_garbage_and_empty_files_read_as_empty(tmp_path):
    for name, data in (("empty.mcap", b""), ("junk.mcap", b"not an mcap file at all" * 10)):
        p = tmp_path / name
        p.write_bytes(data)
        assert list(read_recording(p)) == []


def test_close_is_idempotent(tmp_path):
    path = tmp_path / "run.mcap"
    rec = _write(path, 10)
    rec.close()
    size = path.stat().st_size
    rec.close()
    rec.close()
    assert path.stat().st_size == size
    assert len(list(read_recording(path))) == 13


def test_add_never_blocks_and_drops_when_full(tmp_path):
    rec = Recorder(tmp_path / "small.mcap", max_queue=5)
    try:
        t0 = time.monotonic()
        for i in range(5000):
            rec.add("/state", _state(i))
        assert time.monotonic() - t0 < 5.0
        assert rec.dropped > 0
    finally:
        rec.close()
    assert rec.written + rec.dropped == 5000
    assert len(list(read_recording(tmp_path / "small.mcap"))) == rec.written


def test_a_bad_message_is_dropped_and_recording_goes_on(tmp_path):
    """One message that cannot be written (no such topic, not JSON-serialisable) must not end the writer
    thread: the rest of the run is still recorded and the file is finished on close()."""
    rec = Recorder(tmp_path / "t.mcap", flush_s=0.1)
    try:
        rec.add("/state", _state(0))
        rec.add("/nope", {"t": 0})
        rec.add("/state", {"t": 0.5, "x": object()})
        rec.add("/state", _state(1))
        until(lambda: rec.written + rec.dropped == 4, 20.0, "all four handled")
    finally:
        rec.close()
    assert rec.written == 2 and rec.dropped == 2
    states = [m for topic, _, m in read_recording(tmp_path / "t.mcap") if topic == "/state"]
    assert [s["i"] for s in states] == [0, 1]
    with open(tmp_path / "t.mcap", "rb") as f:
        assert make_reader(f).get_summary().statistics.message_count == 2  # finished: summary written


def test_a_full_disk_stops_the_recording_reports_once_and_keeps_what_was_flushed(tmp_path):
    """A real ENOSPC (a 256 KiB tmpfs filled by another file): the writer thread neither dies with a
    traceback nor blocks; ``error`` and ``on_error`` say why (once); ``add`` and ``close`` return at once;
    the file is cut back to its last complete flush and reads back exactly the flushed messages."""
    errors: list[str] = []
    with small_disk(tmp_path / "disk", "256k") as disk:
        rec = Recorder(disk / "run.mcap", flush_s=0.05, on_error=errors.append)
        try:
            for i in range(100):
                rec.add("/state", _state(i))
            until(lambda: rec.flushed == 100, 20.0, "the first 100 on disk")
            fill_disk(disk)
            i = 100
            while not errors:  # the next chunk that needs a new page of the full disk fails
                rec.add("/state", _state(i))
                i += 1
                time.sleep(0.002)
                assert i < 20000, "no write failed on a full disk"
            flushed = rec.flushed
            t0 = time.monotonic()
            for j in range(50):
                rec.add("/state", _state(i + j))  # dropped at once, never queued
        finally:
            rec.close()
        close_s = time.monotonic() - t0
        assert errors == [rec.error] and "No space left on device (ENOSPC)" in rec.error, errors
        assert f"the {flushed} messages before it are readable" in rec.error
        assert close_s < 1.0 and not rec._thread.is_alive()
        got = [m["i"] for topic, _, m in read_recording(disk / "run.mcap") if topic == "/state"]
        assert got == list(range(flushed)) and flushed >= 100
        assert rec.dropped >= 50 and rec.written + rec.dropped >= i + 50 - 1
        assert (disk / "run.mcap").stat().st_size == rec._good_size  # no torn chunk left at the end
