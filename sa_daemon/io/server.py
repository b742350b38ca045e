"""ZeroMQ sockets of the daemon: a PUB socket for ``state``/``event`` and a ROUTER for commands.

PUB never blocks: each send is ``NOBLOCK`` with a small high-water mark, so a slow or absent subscriber
loses messages instead of slowing a loop. The command socket is a ROUTER so that any number of REQ
clients can talk to it; each request gets exactly one reply, in the REQ envelope it came with.

Security (``docs/protocol.md``, section 5): the command socket binds to a non-loopback endpoint only
with CURVE (:mod:`.security`); then a ZAP authenticator, started before the first bind and stopped in
:meth:`ZmqServer.close`, admits only the configured client keys. The PUB socket never reads what a
peer sends, so exposing it cannot expose commands.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Callable
from typing import Any

import zmq
import zmq.asyncio
from zmq.auth.thread import ThreadAuthenticator

from . import protocol
from .security import (
    AllowList,
    ServerCurve,
    apply_server,
    exposure_error,
    is_loopback,
    start_authenticator,
)

log = logging.getLogger(__name__)

Handler = Callable[[protocol.Request], dict[str, Any]]


class ZmqServer:
    """Bind ``pub`` and ``cmd`` endpoints; :meth:`serve` answers commands with ``handler``.

    ``curve``: CURVE keys and allowed clients (``None``: no CURVE, and ``cmd`` must be loopback, else
    :class:`~sa_daemon.config.ConfigError` naming ``zmq.cmd`` before any socket exists).
    """

    def __init__(self, pub: str, cmd: str, max_request_bytes: int = 65536, max_json_depth: int = 8,
                 curve: ServerCurve | None = None) -> None:
        err = exposure_error(cmd, curve)
        if err is not None:
            raise err
        self.ctx = zmq.asyncio.Context()
        self.curve = curve
        self.allow: AllowList | None = None
        self.auth: ThreadAuthenticator | None = None
        self.max_request_bytes = max_request_bytes
        self.max_json_depth = max_json_depth
        # Sends libzmq refused (zmq.Again). A PUB socket drops a slow subscriber's messages silently at
        # its high-water mark and never refuses, so this stays 0 unless the socket itself cannot send.
        self.dropped = 0
        self.requests = 0
        self.refused = 0
        #: Windows whose request budget ran out (:meth:`serve` with ``batch``): the flood had to wait.
        self.deferred = 0
        self.pub = self.ctx.socket(zmq.PUB)
        self.pub.setsockopt(zmq.SNDHWM, 200)
        self.pub.setsockopt(zmq.LINGER, 0)
        self.cmd = self.ctx.socket(zmq.ROUTER)
        self.cmd.setsockopt(zmq.LINGER, 0)
        # Frames beyond this are dropped by libzmq before they reach us (the limit check below
        # answers anything between max_request_bytes and this with a reason).
        self.cmd.setsockopt(zmq.MAXMSGSIZE, 16 * max_request_bytes)
        try:
            if curve is not None:
                self.allow = AllowList(curve.allowed)
                # Before any bind: libzmq admits every CURVE client while no ZAP handler is running.
                self.auth = start_authenticator(self.ctx, self.allow)
                apply_server(self.cmd, curve.keys)
                if curve.pub:
                    apply_server(self.pub, curve.keys)
            self.pub.bind(pub)
            self.cmd.bind(cmd)
        except (zmq.ZMQError, RuntimeError) as e:
            self.close()
            raise OSError(f"cannot bind ZeroMQ endpoint ({pub}, {cmd}): {e}") from None
        if (curve is None or not curve.pub) and not is_loopback(pub):
            log.warning("zmq.pub %s is reachable from other machines without CURVE: anyone there can read the "
                        "state stream (but never command: a PUB socket reads nothing)", pub)
        self.pub_endpoint = self.pub.getsockopt_string(zmq.LAST_ENDPOINT)
        self.cmd_endpoint = self.cmd.getsockopt_string(zmq.LAST_ENDPOINT)

    def publish(self, topic: bytes, obj: dict[str, Any]) -> None:
        """Send ``[topic, JSON]`` without ever blocking (a full subscriber queue loses it, silently)."""
        try:
            self.pub.send_multipart([topic, protocol.encode(obj)], flags=zmq.NOBLOCK)
        except zmq.Again:
            self.dropped += 1

    async def serve(self, handler: Handler, batch: int | None = None, period_s: float | None = None) -> None:
        """Answer commands forever (cancel to stop). A handler exception becomes ``ok: false``.

        With ``batch`` and ``period_s``, at most ``batch`` requests are answered per ``period_s`` (the
        daemon passes its control period): when a window's budget is spent, this task sleeps until the
        window ends, and the requests behind it wait in ZeroMQ's queue (libzmq then stops reading the
        peers' connections: back-pressure, nothing dropped). Each request is still answered exactly once,
        in the order of its connection. A request that arrives while the socket is idle is answered at
        once. Between two requests the task yields, so a due timer waits for one request at most.
        """
        window_end = 0.0
        in_window = 0
        while True:
            frames = await self.cmd.recv_multipart()
            now = time.monotonic()
            if period_s is not None and now >= window_end:
                window_end, in_window = now + period_s, 0
            if len(frames) < 2:
                continue
            # REQ envelope: [identity, b"", payload]; a DEALER may omit the empty delimiter.
            envelope, payload = frames[:-1], frames[-1]
            self.requests += 1
            in_window += 1
            try:
                req = protocol.parse_request(payload, self.max_request_bytes, self.max_json_depth)
                reply = protocol.encode({"ok": True, **handler(req)})
            except protocol.RequestError as e:
                self.refused += 1
                reply = protocol.error(str(e))
            except Exception as e:
                self.refused += 1
                log.exception("command failed")
                reply = protocol.error(f"internal error: {type(e).__name__}: {e}")
            try:
                await self.cmd.send_multipart([*envelope, reply], flags=zmq.NOBLOCK)
            except zmq.ZMQError:
                pass  # the client went away
            if batch is not None and period_s is not None and in_window >= batch:
                self.deferred += 1  # budget spent: the rest waits for the next window
                await asyncio.sleep(max(0.0, window_end - time.monotonic()))
            else:
                await asyncio.sleep(0)

    def close(self, linger_s: float = 0.2) -> None:
        """Close both sockets; the PUB socket gets ``linger_s`` to deliver the last events (a stuck
        subscriber cannot hold the shutdown longer than that)."""
        self.pub.close(linger=int(linger_s * 1000))
        self.cmd.close(linger=0)
        if self.auth is not None:  # after the sockets it guards, before the context
            self.auth.stop()
            self.auth = None
        self.ctx.term()
