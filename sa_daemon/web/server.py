"""``sa-daemon web``: the page, served with aiohttp, pushing the daemon's state over a WebSocket.

A separate process: it only talks to the daemon through the ZeroMQ protocol (:mod:`.link`), so the
daemon's loops are not touched and a page that misbehaves cannot slow them.

* ``GET /``: the page (``static/``); ``GET /ws``: the WebSocket. On connect the page gets ``hello``
  (the protocol version and the running scene), then every ``state`` message (the latest only, if the
  page is slow: a tablet on a weak network never builds a queue) and every ``event``. Each ``state``
  carries ``rx_wall``, when this process received it (Unix time, s), so the page can measure how long
  the state took to reach its pixels.
* Page messages are JSON commands (``{"cmd": "answer", "value": "yes"}``, ``stop``, ``resume``,
  ``set_method``, ``status``, ``scene``), validated like the daemon's own requests before they are
  forwarded; a refused one gets ``{"type": "refused", "reason": ...}`` and the connection stays.
* Access: loopback by default. With ``web.token_file`` every request needs the token, as ``?token=``
  (once: the reply sets an HttpOnly cookie) or the cookie; without it the reply is 401 and nothing
  else. A non-loopback ``web.listen`` needs TLS and a token (:func:`check_exposure`). The WebSocket
  also refuses a cross-site ``Origin`` (a page elsewhere must not drive the arm through a browser).
"""

from __future__ import annotations

import asyncio
import hmac
import ipaddress
import json
import logging
import ssl
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from aiohttp import WSMsgType, web

from ..config import ConfigError, WebConfig
from ..io import protocol
from .link import DaemonLink, PageMessageError, parse_page_message

log = logging.getLogger(__name__)

STATIC = Path(__file__).resolve().parent / "static"
COOKIE = "sa_web_token"
EVENT_QUEUE = 200  # events a slow page may fall behind by before the oldest are dropped


def split_listen(listen: str) -> tuple[str, int]:
    """``HOST:PORT`` (``[v6]:PORT`` too) as ``(host, port)``; ``ConfigError`` naming ``web.listen``."""
    host, sep, port = listen.rpartition(":")
    if not sep or not port.isdigit() or not 0 <= int(port) <= 65535:
        raise ConfigError(f"web.listen: {listen!r} is not HOST:PORT")
    return host.strip("[]") or "0.0.0.0", int(port)  # an empty host: every interface


def is_loopback_host(host: str) -> bool:
    if host.lower() == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def check_exposure(cfg: WebConfig, host: str) -> None:
    """Refuse (``ConfigError`` naming the key) a non-loopback bind without TLS and a token, or half a
    TLS setting."""
    if bool(cfg.tls_cert) != bool(cfg.tls_key):
        raise ConfigError("web.tls_key: set tls_cert and tls_key together" if cfg.tls_cert
                          else "web.tls_cert: set tls_cert and tls_key together")
    if is_loopback_host(host):
        return
    for key in ("tls_cert", "token_file"):
        if not getattr(cfg, key):
            raise ConfigError(f"web.{key}: {host} is not a loopback address, and the page is only exposed "
                              "with TLS (web.tls_cert, web.tls_key) and a token (web.token_file, made by "
                              "sa-daemon keygen DIR --web-token)")


def read_token(path: str) -> str:
    """The token in ``path`` (``ConfigError`` naming ``web.token_file`` if unreadable or too short)."""
    try:
        token = Path(path).read_text().strip()
    except OSError as e:
        raise ConfigError(f"web.token_file: {e}") from None
    if len(token) < 16:
        raise ConfigError(f"web.token_file: {path} holds no token of at least 16 characters")
    return token


def ssl_context(cfg: WebConfig) -> ssl.SSLContext | None:
    if not cfg.tls_cert:
        return None
    ctx = ssl.create_default_context(ssl.Purpose.CLIENT_AUTH)
    try:
        ctx.load_cert_chain(cfg.tls_cert, cfg.tls_key)
    except (OSError, ssl.SSLError) as e:
        raise ConfigError(f"web.tls_cert: cannot load {cfg.tls_cert} / {cfg.tls_key}: {e}") from None
    return ctx


@dataclass(eq=False)
class _Page:
    """One connected page: the latest state (replaced, never queued) and its events."""

    ws: web.WebSocketResponse
    state: dict[str, Any] | None = None
    events: list[dict[str, Any]] = field(default_factory=list)
    wake: asyncio.Event = field(default_factory=asyncio.Event)
    dropped: int = 0


class WebServer:
    """The aiohttp application of the module doc around one :class:`DaemonLink`."""

    def __init__(self, cfg: WebConfig, link: DaemonLink, token: str | None) -> None:
        self.cfg, self.link, self.token = cfg, link, token
        self.pages: set[_Page] = set()
        self.scene: dict[str, Any] | None = None
        self.refused = 0
        self.app = web.Application(middlewares=[self._auth])
        self.app.router.add_get("/", self._index)
        self.app.router.add_get("/ws", self._ws)
        self.app.router.add_static("/static/", STATIC, show_index=False)
        self.app.on_startup.append(self._start)
        self.app.on_cleanup.append(self._stop)
        self._tasks: list[asyncio.Task] = []

    # -- access ------------------------------------------------------------------------------------------

    def _token_ok(self, given: str | None) -> bool:
        return self.token is None or (given is not None and hmac.compare_digest(given.encode(), self.token.encode()))

    @web.middleware
    async def _auth(self, request: web.Request, handler: Any) -> web.StreamResponse:
        query = request.query.get("token")
        if not (self._token_ok(query) or self._token_ok(request.cookies.get(COOKIE))):
            return web.Response(status=401, text="")
        response = await handler(request)
        if self.token is not None and query is not None and not response.prepared:
            response.set_cookie(COOKIE, self.token, httponly=True, samesite="Strict",
                                secure=self.cfg.tls_cert != "")
        return response

    # -- handlers ----------------------------------------------------------------------------------------

    async def _index(self, request: web.Request) -> web.StreamResponse:
        return web.FileResponse(STATIC / "index.html", headers={"Cache-Control": "no-store"})

    async def _ws(self, request: web.Request) -> web.StreamResponse:
        origin = request.headers.get("Origin")
        if origin is not None and origin.split("://", 1)[-1] != request.host:
            return web.Response(status=403, text="")
        ws = web.WebSocketResponse(heartbeat=10.0, max_msg_size=self.cfg.max_message_bytes)
        await ws.prepare(request)
        page = _Page(ws)
        self.pages.add(page)
        sender = asyncio.create_task(self._send_loop(page))
        try:
            await ws.send_str(self._hello())
            async for msg in ws:
                if msg.type == WSMsgType.TEXT:
                    await self._on_page_message(ws, msg.data)
                elif msg.type == WSMsgType.BINARY:
                    await self._refuse(ws, "binary messages are not accepted: send JSON text")
                elif msg.type == WSMsgType.ERROR:
                    break
        finally:
            self.pages.discard(page)
            sender.cancel()
        return ws

    async def _refuse(self, ws: web.WebSocketResponse, reason: str) -> None:
        self.refused += 1
        await ws.send_json({"type": "refused", "reason": reason})

    async def _on_page_message(self, ws: web.WebSocketResponse, text: str) -> None:
        try:
            req = parse_page_message(text, self.cfg.max_message_bytes)
        except PageMessageError as e:
            await self._refuse(ws, str(e))
            return
        reply = await self.link.command(req)
        log.info("page command %s -> %s", req.cmd, "ok" if reply.get("ok") else reply.get("error"))
        await ws.send_json({"type": "reply", "cmd": req.cmd, "id": req.args.get("id"), **reply})

    async def _send_loop(self, page: _Page) -> None:
        """Send what arrived for ``page``: its events in order, then the latest state."""
        while not page.ws.closed:
            await page.wake.wait()
            page.wake.clear()
            events, page.events = page.events, []
            state, page.state = page.state, None
            try:
                for e in events:
                    await page.ws.send_str(e["_json"])
                if state is not None:
                    await page.ws.send_str(state["_json"])
            except (ConnectionError, RuntimeError):
                return

    # -- the daemon's stream -----------------------------------------------------------------------------

    def _on_daemon(self, topic: str, msg: dict[str, Any], at: float) -> None:
        if topic == "state":
            item = {"_json": json.dumps({"type": "state", "rx_wall": at, "state": msg})}
            for p in self.pages:
                p.state = item
                p.wake.set()
        elif topic == "event":
            item = {"_json": json.dumps({"type": "event", "event": msg})}
            for p in self.pages:
                if len(p.events) >= EVENT_QUEUE:
                    p.events.pop(0)
                    p.dropped += 1
                p.events.append(item)
                p.wake.set()
            if msg.get("type") in ("ready", "scene"):
                self._tasks.append(asyncio.create_task(self._fetch_scene()))

    async def _fetch_scene(self) -> None:
        reply = await self.link.command(protocol.Request("scene", {}))
        if reply.get("ok"):
            self.scene = {k: v for k, v in reply.items() if k != "ok"}
            hello = self._hello()
            for p in self.pages:
                p.events.append({"_json": hello})
                p.wake.set()

    def _hello(self) -> str:
        """The ``hello`` a page gets on connect and when the scene changes."""
        return json.dumps({"type": "hello", "version": protocol.PROTOCOL_VERSION, "scene": self.scene})

    async def _start(self, app: web.Application) -> None:
        self._tasks.append(asyncio.create_task(self.link.receive(self._on_daemon)))
        self._tasks.append(asyncio.create_task(self._fetch_scene()))

    async def _stop(self, app: web.Application) -> None:
        for t in self._tasks:
            t.cancel()
        await asyncio.gather(*self._tasks, return_exceptions=True)
        for p in list(self.pages):
            await p.ws.close()
        self.link.close()


def run_web(cfg: WebConfig, pub: str, cmd: str, curve: Any = None) -> None:
    """Serve the page until SIGINT/SIGTERM (``sa-daemon web``)."""
    host, port = split_listen(cfg.listen)
    check_exposure(cfg, host)
    token = read_token(cfg.token_file) if cfg.token_file else None
    context = ssl_context(cfg)
    server = WebServer(cfg, DaemonLink(pub, cmd, curve), token)
    scheme = "https" if context else "http"
    print(f"sa-daemon web: {scheme}://{host}:{port}/{'?token=...' if token else ''} "
          f"(daemon {pub}, {cmd}); started {time.strftime('%H:%M:%S')}", flush=True)
    web.run_app(server.app, host=host, port=port, ssl_context=context, print=None, access_log=None,
                handle_signals=True)
