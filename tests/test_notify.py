"""systemd's notify protocol over a real AF_UNIX datagram socket, and the daemon's use of it end to end."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
import uuid

import pytest
from helpers import free_port

from sa_daemon.io.notify import Notifier


def _bind(addr: str) -> socket.socket:
    s = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    s.bind(addr)
    s.settimeout(5.0)
    return s


def test_ready_datagram_on_a_path_socket(tmp_path):
    path = str(tmp_path / "notify.sock")
    srv = _bind(path)
    n = Notifier({"NOTIFY_SOCKET": path})
    try:
        assert n.enabled
        assert n.notify("READY=1", "STATUS=running") is True
        assert srv.recv(4096) == b"READY=1\nSTATUS=running"
        assert n.notify("WATCHDOG=1")
        assert srv.recv(4096) == b"WATCHDOG=1"
        assert n.sent == 2
    finally:
        n.close()
        srv.close()
    assert n.notify("STOPPING=1") is False  # closed


def test_abstract_socket_address():
    name = f"sa-daemon-test-{uuid.uuid4().hex}"
    srv = _bind("\0" + name)
    n = Notifier({"NOTIFY_SOCKET": "@" + name})
    try:
        assert n.notify("READY=1")
        assert srv.recv(4096) == b"READY=1"
    finally:
        n.close()
        srv.close()


def test_no_listener_is_not_an_error(tmp_path):
    n = Notifier({"NOTIFY_SOCKET": str(tmp_path / "nobody.sock")})
    try:
        assert n.enabled
        assert n.notify("READY=1") is False
        assert n.sent == 0
    finally:
        n.close()


def test_without_notify_socket_nothing_is_sent():
    n = Notifier({})
    assert not n.enabled
    assert n.notify("READY=1") is False
    assert n.watchdog_interval_s is None
    n.close()
    assert Notifier({"NOTIFY_SOCKET": ""}).notify("READY=1") is False


def test_reads_the_process_environment_by_default(tmp_path, monkeypatch):
    path = str(tmp_path / "env.sock")
    srv = _bind(path)
    monkeypatch.setenv("NOTIFY_SOCKET", path)
    monkeypatch.setenv("WATCHDOG_USEC", "500000")
    monkeypatch.delenv("WATCHDOG_PID", raising=False)
    n = Notifier()
    try:
        assert n.watchdog_interval_s == pytest.approx(0.25)
        assert n.notify("READY=1")
        assert srv.recv(4096) == b"READY=1"
    finally:
        n.close()
        srv.close()


@pytest.mark.parametrize(
    "env, interval",
    [
        ({"WATCHDOG_USEC": "2000000"}, 1.0),
        ({"WATCHDOG_USEC": "30000000", "WATCHDOG_PID": str(os.getpid())}, 15.0),
        ({"WATCHDOG_USEC": "2000000", "WATCHDOG_PID": str(os.getpid() + 1)}, None),  # meant for another process
        ({"WATCHDOG_USEC": "0"}, None),
        ({"WATCHDOG_USEC": "-5"}, None),
        ({"WATCHDOG_USEC": "soon"}, None),
        ({}, None),
    ],
)
def test_watchdog_interval_is_half_of_watchdog_usec(env, interval):
    n = Notifier(env)
    if interval is None:
        assert n.watchdog_interval_s is None
    else:
        assert n.watchdog_interval_s == pytest.approx(interval)


def test_daemon_sends_ready_watchdog_and_stopping(tmp_path):
    """``sa-daemon run`` under a systemd-like supervisor: READY=1 once up, WATCHDOG=1 about every second
    (WATCHDOG_USEC = 2 s), STOPPING=1 after SIGTERM, exit code 0."""
    path = str(tmp_path / "notify.sock")
    srv = _bind(path)
    env = {**os.environ, "NOTIFY_SOCKET": path, "WATCHDOG_USEC": "2000000"}
    env.pop("WATCHDOG_PID", None)
    args = [
        sys.executable, "-m", "sa_daemon.cli", "run", "--arm", "kinematic", "--input", "sim", "--scene", "scene1",
        "--task", "cup:top", "--duration", "6", "--no-speech", "--quiet",
        "--pub", f"tcp://127.0.0.1:{free_port()}", "--cmd", f"tcp://127.0.0.1:{free_port()}",
    ]
    proc = subprocess.Popen(args, env=env, cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    got: list[tuple[float, bytes]] = []
    try:
        end = time.monotonic() + 60
        terminated = False
        while time.monotonic() < end:
            try:
                got.append((time.monotonic(), srv.recv(4096)))
            except TimeoutError:
                if proc.poll() is not None:
                    break
                continue
            kinds = [m for _, m in got]
            after_ready = kinds[next((i for i, m in enumerate(kinds) if m.startswith(b"READY=1")), len(kinds)):]
            if not terminated and after_ready.count(b"WATCHDOG=1") >= 3:
                proc.send_signal(signal.SIGTERM)
                terminated = True
            if any(m.startswith(b"STOPPING=1") for m in kinds):
                break
        _, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        srv.close()
    msgs = [m for _, m in got]
    assert proc.returncode == 0, err.decode()[-2000:]
    assert msgs, "no datagram at all"
    ready = [i for i, m in enumerate(msgs) if m.split(b"\n")[0] == b"READY=1"]
    assert len(ready) == 1, msgs
    assert b"STATUS=running" in msgs[ready[0]]
    assert terminated, f"fewer than 3 WATCHDOG=1 before the daemon stopped: {msgs}"
    i_stop = next(i for i, m in enumerate(msgs) if m.startswith(b"STOPPING=1"))
    # (The control loop may already ping before READY=1 while the planner starts: harmless for systemd.)
    assert msgs[ready[0] + 1:i_stop].count(b"WATCHDOG=1") >= 3
    assert i_stop == len(msgs) - 1  # nothing after STOPPING=1
    # About once a second (half of WATCHDOG_USEC), not once per control tick.
    assert msgs.count(b"WATCHDOG=1") < 10, msgs
