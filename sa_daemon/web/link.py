"""The page's link to the daemon: a client of the documented ZeroMQ protocol, nothing else.

:class:`DaemonLink` subscribes to ``state`` and ``event`` and sends commands on a REQ socket, one at a
time. Every command from a page is validated by the protocol's own :func:`~..io.protocol.parse_request`
first, and only the commands the page offers pass (:data:`PAGE_COMMANDS`): a malformed or foreign
message never reaches the daemon. A daemon that does not answer within ``timeout_s`` gets its REQ
socket replaced (a REQ socket that lost its reply cannot send again) and the page an error.
"""

from __future__ import annotations

import asyncio
import json
import time
from collections.abc import Awaitable, Callable
from typing import Any

import zmq
import zmq.asyncio

from ..io import protocol
from ..io.security import ClientCurve, apply_client

#: What a page may ask of the daemon (``docs/web.md``).
PAGE_COMMANDS = ("answer", "stop", "resume", "set_method", "status", "scene", "set_profile")

OnMessage = Callable[[str, dict[str, Any], float], Awaitable[None] | None]
"""``on_message(topic, message, received_wall_s)`` for every ``state`` and ``event`` message."""


class PageMessageError(ValueError):
    """A page message refused before it reached the daemon; the text is the reason the page is sent."""


def parse_page_message(raw: str | bytes, max_bytes: int) -> protocol.Request:
    """A page's WebSocket message as a protocol request, or :class:`PageMessageError` naming why not."""
    data = raw.encode() if isinstance(raw, str) else raw
    try:
        req = protocol.parse_request(data, max_bytes=max_bytes, max_depth=4)
    except protocol.RequestError as e:
        raise PageMessageError(str(e)) from None
    if req.cmd not in PAGE_COMMANDS:
        raise PageMessageError(f"the page may not send {req.cmd!r} (one of {', '.join(PAGE_COMMANDS)})")
    return req


class DaemonLink:
    """SUB (state, event) and REQ (commands) to one daemon at ``pub`` / ``cmd``."""

    def __init__(self, pub: str, cmd: str, curve: ClientCurve | None = None, timeout_s: float = 2.0) -> None:
        self.pub, self.cmd, self.curve, self.timeout_s = pub, cmd, curve, timeout_s
        self._ctx = zmq.asyncio.Context()
        self._sub = self._socket(zmq.SUB)
        for topic in (protocol.TOPIC_STATE, protocol.TOPIC_EVENT):
            self._sub.setsockopt(zmq.SUBSCRIBE, topic)
        self._sub.connect(pub)
        self._req: zmq.asyncio.Socket | None = None
        self._lock = asyncio.Lock()
        #: Counters for ``status``: messages received, commands forwarded, replies missed.
        self.received = self.forwarded = self.timeouts = 0

    def _socket(self, kind: int) -> zmq.asyncio.Socket:
        sock = self._ctx.socket(kind)
        sock.setsockopt(zmq.LINGER, 0)
        if self.curve is not None:
            apply_client(sock, self.curve)
        return sock

    async def receive(self, on_message: OnMessage) -> None:
        """Forward every ``state``/``event`` message until cancelled; undecodable ones are skipped."""
        while True:
            frames = await self._sub.recv_multipart()
            at = time.time()
            if len(frames) != 2:
                continue
            try:
                msg = json.loads(frames[1])
            except ValueError:
                continue
            self.received += 1
            out = on_message(frames[0].decode(errors="replace"), msg, at)
            if asyncio.iscoroutine(out):
                await out

    async def command(self, req: protocol.Request) -> dict[str, Any]:
        """Send one validated request and return the daemon's reply (``ok: false`` with a reason if the
        daemon does not answer in time)."""
        async with self._lock:
            if self._req is None:
                self._req = self._socket(zmq.REQ)
                self._req.connect(self.cmd)
            body = {"cmd": req.cmd, **req.args}
            await self._req.send(protocol.encode(body))
            self.forwarded += 1
            if await self._req.poll(int(self.timeout_s * 1000)):
                return json.loads(await self._req.recv())
            self.timeouts += 1
            self._req.close(linger=0)
            self._req = None
            return {"ok": False, "error": f"the daemon did not answer within {self.timeout_s:g} s"}

    def close(self) -> None:
        self._sub.close(linger=0)
        if self._req is not None:
            self._req.close(linger=0)
        self._ctx.term()
