"""A small client of the daemon's ZeroMQ protocol (``docs/protocol.md``), used by ``answer`` and
``monitor`` and by the tests.

With ``curve`` (:class:`~.security.ClientCurve`) the sockets authenticate with CURVE. A daemon that
refuses a client simply never answers; so that a timeout can say why, each socket watches its own
handshake events and the ``TimeoutError`` names the cause (key not allowed, CURVE on one side only,
wrong server key).
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from typing import Any

import zmq
from zmq.utils.monitor import recv_monitor_message

from .security import ClientCurve, apply_client

_HANDSHAKE_EVENTS = (
    zmq.EVENT_HANDSHAKE_FAILED_NO_DETAIL | zmq.EVENT_HANDSHAKE_FAILED_PROTOCOL | zmq.EVENT_HANDSHAKE_FAILED_AUTH
)
_ZAP_REFUSED = 400  # ZAP status code of a refused key (RFC 27)


class _HandshakeWatch:
    """Handshake failures of one socket, read from its monitor socket (inproc, same context)."""

    def __init__(self, sock: zmq.Socket, curve: ClientCurve | None) -> None:
        self.sock = sock
        self.curve = curve
        self.mon = sock.get_monitor_socket(_HANDSHAKE_EVENTS)
        self.reason: str | None = None
        self.rank = -1

    def _explain(self, ev: dict[str, Any]) -> tuple[int, str]:
        """``(rank, cause)`` of one failure event; a retried connection may fail differently (a reset
        mid-handshake says less than the refusal before it), so the most specific cause wins."""
        kind, value = ev["event"], ev["value"]
        if kind == zmq.EVENT_HANDSHAKE_FAILED_AUTH:
            if value == _ZAP_REFUSED:
                return 3, "the daemon refused this client's CURVE key (not in its zmq.curve_clients_dir)"
            return 3, f"the daemon refused this client (authentication status {value})"
        if kind == zmq.EVENT_HANDSHAKE_FAILED_PROTOCOL and value == zmq.PROTOCOL_ERROR_ZMTP_MECHANISM_MISMATCH:
            if self.curve is None:
                return 2, ("the daemon requires CURVE: set zmq.curve_client_secret and zmq.curve_server_public "
                           "(sa-daemon keygen)")
            return 2, "this client uses CURVE but the daemon's socket does not (check zmq.curve_pub, curve_server_secret)"
        if kind == zmq.EVENT_HANDSHAKE_FAILED_NO_DETAIL:
            if self.curve is not None:
                return 1, ("CURVE handshake failed: is zmq.curve_server_public the daemon's server.key, and "
                           "does the daemon's socket use CURVE (zmq.curve_pub, curve_server_secret)?")
            return 1, ("the daemon closed the connection during the handshake: does it require CURVE "
                       "(zmq.curve_client_secret, zmq.curve_server_public)?")
        return 0, "the connection handshake failed"

    def failure(self) -> str | None:
        """The most specific cause of the handshake failures so far (``None``: none seen)."""
        while self.mon.poll(0):
            rank, reason = self._explain(recv_monitor_message(self.mon))
            if rank >= self.rank:
                self.rank, self.reason = rank, reason
        return self.reason

    def close(self) -> None:
        self.sock.disable_monitor()
        self.mon.close(linger=0)


def _timeout(what: str, watch: _HandshakeWatch) -> TimeoutError:
    reason = watch.failure()
    return TimeoutError(f"{what}: {reason}" if reason else what)


def request(endpoint: str, obj: dict[str, Any] | bytes, timeout_s: float = 2.0,
            curve: ClientCurve | None = None) -> dict[str, Any]:
    """Send one command (a dict, or raw bytes) with a REQ socket and return the decoded reply.

    ``TimeoutError`` if no reply arrives within ``timeout_s`` (naming a handshake failure if any).
    """
    ctx = zmq.Context.instance()
    sock = ctx.socket(zmq.REQ)
    sock.setsockopt(zmq.LINGER, 0)
    sock.setsockopt(zmq.RCVTIMEO, int(timeout_s * 1000))
    sock.setsockopt(zmq.SNDTIMEO, int(timeout_s * 1000))
    if curve is not None:
        apply_client(sock, curve)
    watch = _HandshakeWatch(sock, curve)
    try:
        sock.connect(endpoint)
        try:
            sock.send(obj if isinstance(obj, bytes) else json.dumps(obj).encode())
            return json.loads(sock.recv())
        except zmq.Again:
            raise _timeout(f"no reply from {endpoint} within {timeout_s} s", watch) from None
    finally:
        watch.close()
        sock.close(linger=0)


def subscribe(endpoint: str, topics: tuple[bytes, ...] = (b"state", b"event"), timeout_s: float = 2.0,
              curve: ClientCurve | None = None) -> Iterator[tuple[str, dict[str, Any]]]:
    """Yield ``(topic, message)`` from the PUB socket; ``TimeoutError`` after ``timeout_s`` of silence."""
    ctx = zmq.Context.instance()
    sock = ctx.socket(zmq.SUB)
    sock.setsockopt(zmq.LINGER, 0)
    sock.setsockopt(zmq.RCVTIMEO, int(timeout_s * 1000))
    for t in topics:
        sock.setsockopt(zmq.SUBSCRIBE, t)
    if curve is not None:
        apply_client(sock, curve)
    watch = _HandshakeWatch(sock, curve)
    sock.connect(endpoint)
    try:
        while True:
            try:
                topic, data = sock.recv_multipart()
            except zmq.Again:
                raise _timeout(f"nothing from {endpoint} for {timeout_s} s", watch) from None
            yield topic.decode(), json.loads(data)
    finally:
        watch.close()
        sock.close(linger=0)
