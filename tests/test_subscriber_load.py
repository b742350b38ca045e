"""The daemon under subscriber load (issue 6): 50 subscribers that read everything and one that never
reads, run by ``sa-daemon bench loop --subscribers 50 --stalled-subscribers 1`` as a real subprocess.

The test keeps its own reading subscriber (connected before the daemon binds) and asks ``status`` throughout.
State messages are published at 200 Hz here (the highest rate the config allows) so that the stalled
subscriber's connection and the daemon's PUB queue for it are full halfway through the run: the kernel
buffers about 3 MB of a stalled loopback connection, which at the default 30 Hz takes a minute or more.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from itertools import pairwise

import pytest
from helpers import Collector, free_port

from sa_daemon.io.client import request

CLI = [sys.executable, "-m", "sa_daemon.cli"]
RUN_S = 30.0
PUBLISH_HZ = 200.0
STATUS_EVERY_S = 0.5
CONFIG = f"[runtime]\npublish_hz = {PUBLISH_HZ}\n"


@pytest.fixture(scope="module")
def loaded(tmp_path_factory):
    """Run the loaded bench; yield (exit code, stderr, figures, own ``(arrival, t)`` of each state, status
    replies)."""
    d = tmp_path_factory.mktemp("load")
    (d / "config.toml").write_text(CONFIG)
    pub, cmd = f"tcp://127.0.0.1:{free_port()}", f"tcp://127.0.0.1:{free_port()}"
    stream = Collector(pub)
    stream.start()
    out = d / "loop.json"
    with open(d / "stderr.txt", "wb") as err:
        proc = subprocess.Popen(
            [*CLI, "--config", str(d / "config.toml"), "bench", "loop", "--arm", "kinematic", "--duration", str(RUN_S),
             "--subscribers", "50", "--stalled-subscribers", "1", "--json", str(out), "--quiet",
             "--no-speech", "--pub", pub, "--cmd", cmd],
            cwd=d, stdout=subprocess.DEVNULL, stderr=err,
        )
        replies: list[dict] = []
        try:
            end = time.monotonic() + 60
            while not len(stream) and time.monotonic() < end:
                time.sleep(0.1)
            assert len(stream), "no message from the bench's daemon"
            first = time.monotonic()
            while time.monotonic() < first + RUN_S - 3 and proc.poll() is None:
                replies.append(request(cmd, {"cmd": "status"}, timeout_s=2.0))
                time.sleep(STATUS_EVERY_S)
            rc = proc.wait(RUN_S + 60)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
            stream.halt()
    figs = json.loads(out.read_text()) if out.exists() else {}
    states = [(at, m["t"]) for at, topic, m in stream.msgs if topic == "state"]
    yield rc, (d / "stderr.txt").read_text(errors="replace")[-2000:], figs, states, replies


def test_status_answers_throughout(loaded):
    rc, err, _, _, replies = loaded
    assert rc == 0, err
    assert len(replies) >= 0.5 * (RUN_S - 3) / STATUS_EVERY_S  # half of those asked for: none hung
    assert all(r["ok"] is True and r["planner"]["restarts"] == 0 for r in replies)
    uptimes = [r["uptime_s"] for r in replies]
    assert uptimes == sorted(uptimes)


def test_a_reading_subscriber_gets_states_at_20_hz_without_gaps(loaded):
    _, _, _, states, _ = loaded
    ts = [t for _, t in states]
    span = ts[-1] - ts[0]
    assert span >= RUN_S - 5
    assert (len(ts) - 1) / span >= 20.0, f"{len(ts)} states in {span:.1f} s"
    gaps = [b - a for a, b in pairwise(ts)]
    assert max(gaps) <= 0.2, f"the daemon's state stream paused {max(gaps):.3f} s"
    # Arrival gaps also hold this process's own scheduling on 2 cores shared with the daemon, its worker
    # and 51 subscribers (CI saw 217 ms with the daemon's clock under 200 ms): a looser bound here.
    arrivals = [a for a, _ in states]
    late = max(b - a for a, b in pairwise(arrivals))
    assert late <= 0.5, f"no state arrived for {late:.3f} s"


def test_the_bench_reports_its_subscribers_and_the_stall_filled(loaded):
    _, _, figs, _, _ = loaded
    sub = figs["subscribers"]
    assert sub["subscribers"] == 50 and sub["stalled_subscribers"] == 1
    assert sub["reader_states_min"] >= 0.5 * PUBLISH_HZ * RUN_S
    assert sub["reader_state_hz_min"] >= 20.0
    assert sub["reader_messages_max"] >= sub["reader_messages_min"] >= sub["reader_states_min"]
    [held] = sub["stalled_messages_held"]
    # The stalled subscriber held far fewer than were published: its queue filled and the daemon's PUB
    # socket dropped its messages rather than waiting for it.
    assert 0 < held < 0.8 * sub["reader_messages_min"]
    assert figs["state_messages_published"] >= 0.5 * PUBLISH_HZ * RUN_S
    assert figs["planner_restarts"] == 0 and figs["tasks_done"] >= 0
    assert isinstance(figs["pub_dropped"], int)
