"""A small client of the daemon's ZeroMQ protocol (``docs/protocol.md``), used by ``answer`` and
``monitor`` and by the tests."""

from __future__ import annotations

import json
from collections.abc import Iterator
from typing import Any

import zmq


def request(endpoint: str, obj: dict[str, Any] | bytes, timeout_s: float = 2.0) -> dict[str, Any]:
    """Send one command (a dict, or raw bytes) with a REQ socket and return the decoded reply.

    ``TimeoutError`` if no reply arrives within ``timeout_s``.
    """
    ctx = zmq.Context.instance()
    sock = ctx.socket(zmq.REQ)
    sock.setsockopt(zmq.LINGER, 0)
    sock.setsockopt(zmq.RCVTIMEO, int(timeout_s * 1000))
    sock.setsockopt(zmq.SNDTIMEO, int(timeout_s * 1000))
    try:
        sock.connect(endpoint)
        sock.send(obj if isinstance(obj, bytes) else json.dumps(obj).encode())
        try:
            return json.loads(sock.recv())
        except zmq.Again:
            raise TimeoutError(f"no reply from {endpoint} within {timeout_s} s") from None
    finally:
        sock.close(linger=0)


def subscribe(endpoint: str, topics: tuple[bytes, ...] = (b"state", b"event"), timeout_s: float = 2.0
              ) -> Iterator[tuple[str, dict[str, Any]]]:
    """Yield ``(topic, message)`` from the PUB socket; ``TimeoutError`` after ``timeout_s`` of silence."""
    ctx = zmq.Context.instance()
    sock = ctx.socket(zmq.SUB)
    sock.setsockopt(zmq.LINGER, 0)
    sock.setsockopt(zmq.RCVTIMEO, int(timeout_s * 1000))
    for t in topics:
        sock.setsockopt(zmq.SUBSCRIBE, t)
    sock.connect(endpoint)
    try:
        while True:
            try:
                topic, data = sock.recv_multipart()
            except zmq.Again:
                raise TimeoutError(f"nothing from {endpoint} for {timeout_s} s") from None
            yield topic.decode(), json.loads(data)
    finally:
        sock.close(linger=0)
