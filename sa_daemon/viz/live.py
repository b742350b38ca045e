"""The live view: a Foxglove WebSocket server on the loopback interface (``docs/foxglove.md``).

:class:`LiveView` owns a private ``foxglove.Context`` (so nothing else in the process logs to it), a
server from ``foxglove.start_server`` bound to 127.0.0.1 only, and the three channels of
:mod:`.messages`: ``/scene`` (``foxglove.SceneUpdate``), ``/belief`` (JSON) and ``/log``
(``foxglove.Log``). Logging a message hands it to the SDK's per-client queues (Rust, no network I/O
on the caller's thread); a slow client loses its oldest messages, never the daemon's time.
"""

from __future__ import annotations

import logging
from typing import Any

import foxglove
from foxglove.channels import LogChannel, SceneUpdateChannel

from .messages import JSON_TOPICS

HOST = "127.0.0.1"
"""The only interface the live view listens on (reach it from elsewhere through an SSH tunnel)."""


class LiveView:
    """A Foxglove WebSocket server for the daemon's live state.

    Args:
        port: TCP port on 127.0.0.1 (0: any free port; :attr:`port` tells which).
        name: the server name Foxglove shows.

    Raises:
        OSError: the port cannot be bound (the message names ``foxglove.port``).
    """

    def __init__(self, port: int, name: str = "sa-daemon") -> None:
        logging.getLogger("foxglove").setLevel(logging.WARNING)  # the daemon reports the URL in ``ready``
        self._ctx = foxglove.Context()
        try:
            self._server = foxglove.start_server(name=name, host=HOST, port=port, context=self._ctx)
        except Exception as e:  # noqa: BLE001 - the SDK's own error type (FoxgloveError) for a bind failure
            raise OSError(f"foxglove.port {port}: cannot serve the live view on {HOST}: {e}") from None
        self._channels: dict[str, Any] = {
            "/scene": SceneUpdateChannel("/scene", context=self._ctx),
            **{topic: foxglove.Channel(topic, schema=schema, context=self._ctx) for topic, schema in JSON_TOPICS.items()},
            "/log": LogChannel("/log", context=self._ctx),
        }
        self._closed = False

    @property
    def port(self) -> int:
        """The TCP port the server listens on."""
        return int(self._server.port)

    @property
    def url(self) -> str:
        """The WebSocket URL to open in Foxglove ("Open connection" -> Foxglove WebSocket)."""
        return f"ws://{HOST}:{self.port}"

    def log(self, topic: str, msg: Any, t_ns: int) -> None:
        """Send ``msg`` on ``topic`` (a :data:`~.feed.Sink`); nothing once closed."""
        if not self._closed:
            self._channels[topic].log(msg, log_time=t_ns)

    def close(self) -> None:
        """Stop the server (idempotent)."""
        if not self._closed:
            self._closed = True
            self._server.stop()
