"""Subscriber load for ``bench loop`` and ``bench soak``: N SUB sockets that read everything the daemon
publishes and M that connect and never read.

The sockets live in a separate (spawned) process, so that their work is not the daemon's process's
work; on a small machine they still share its cores. A stalled subscriber has a receive high-water mark
of one message and a small kernel receive buffer, so its connection backs up within seconds and the
daemon's PUB queue for it fills (ZeroMQ then drops that subscriber's messages, never blocking the
sender). When the load stops, each stalled socket is drained: the messages it holds then, against the
number a reading subscriber received, show how many it lost.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from multiprocessing.connection import Connection
from typing import Any

import zmq

from .load import LoadProcess

#: Receive high-water mark of a stalled subscriber (messages).
STALLED_RCVHWM = 1
#: Kernel receive buffer asked for a stalled subscriber's connection (bytes; Linux doubles it).
STALLED_RCVBUF = 4096
#: How long a stalled socket is drained for at the end, s of silence.
DRAIN_IDLE_S = 0.3


@dataclass
class _Reader:
    """Counts of one reading subscriber; gaps are between arrivals of consecutive ``state`` messages."""

    messages: int = 0
    states: int = 0
    first_state: float = 0.0  # time.monotonic() s
    last_state: float = 0.0
    max_gap_s: float = 0.0

    def got(self, topic: bytes, now: float) -> None:
        self.messages += 1
        if topic != b"state":
            return
        if self.states:
            self.max_gap_s = max(self.max_gap_s, now - self.last_state)
        else:
            self.first_state = now
        self.states += 1
        self.last_state = now

    @property
    def state_hz(self) -> float:
        span = self.last_state - self.first_state
        return (self.states - 1) / span if self.states > 1 and span > 0 else 0.0


def _sub(ctx: zmq.Context, endpoint: str, stalled: bool) -> zmq.Socket:
    s = ctx.socket(zmq.SUB)
    s.setsockopt(zmq.LINGER, 0)
    if stalled:
        s.setsockopt(zmq.RCVHWM, STALLED_RCVHWM)
        s.setsockopt(zmq.RCVBUF, STALLED_RCVBUF)
    s.setsockopt(zmq.SUBSCRIBE, b"")
    s.connect(endpoint)
    return s


def _drain(sock: zmq.Socket) -> int:
    n = 0
    while sock.poll(int(DRAIN_IDLE_S * 1000)):
        sock.recv_multipart()
        n += 1
    return n


def _swarm_main(endpoint: str, n_reading: int, n_stalled: int, ready: Any, stop: Any, out: Connection) -> None:
    """The load process: read with ``n_reading`` sockets until ``stop`` is set, then report."""
    ctx = zmq.Context()
    readers = [_sub(ctx, endpoint, stalled=False) for _ in range(n_reading)]
    stalled = [_sub(ctx, endpoint, stalled=True) for _ in range(n_stalled)]
    counts = {s: _Reader() for s in readers}
    poller = zmq.Poller()
    for s in readers:
        poller.register(s, zmq.POLLIN)
    ready.set()
    try:
        while not stop.is_set():
            for s, _ in poller.poll(100):
                now = time.monotonic()
                while True:
                    try:
                        topic, _data = s.recv_multipart(zmq.NOBLOCK)
                    except zmq.Again:
                        break
                    counts[s].got(topic, now)
        rs = list(counts.values())
        out.send({
            "subscribers": n_reading,
            "stalled_subscribers": n_stalled,
            "reader_messages_min": min((r.messages for r in rs), default=0),
            "reader_messages_max": max((r.messages for r in rs), default=0),
            "reader_states_min": min((r.states for r in rs), default=0),
            "reader_state_hz_min": min((r.state_hz for r in rs), default=0.0),
            "reader_state_gap_ms_max": 1e3 * max((r.max_gap_s for r in rs), default=0.0),
            "stalled_messages_held": [_drain(s) for s in stalled],
        })
    finally:
        for s in readers + stalled:
            s.close(0)
        ctx.term()


class SubscriberSwarm(LoadProcess):
    """``n_reading`` reading and ``n_stalled`` never-reading subscribers of ``endpoint`` in a spawned
    process. :meth:`start` returns once every socket is connecting; :meth:`stop` returns the figures:
    messages and ``state`` messages per reading subscriber (min/max), their lowest state rate (Hz) and
    longest gap between state arrivals (ms), and per stalled subscriber the messages it held at the end.
    """

    def __init__(self, endpoint: str, n_reading: int, n_stalled: int) -> None:
        if "*" in endpoint:
            raise ValueError(f"subscribers need a fixed PUB endpoint, not {endpoint!r}")
        if n_reading < 0 or n_stalled < 0:
            raise ValueError("subscriber counts must be >= 0")
        super().__init__(_swarm_main, (endpoint, n_reading, n_stalled), "sa-bench-subscribers")
