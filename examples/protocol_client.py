#!/usr/bin/env python3
"""Standalone client for the sa-daemon ZeroMQ protocol, version 2.

Written only from ``docs/protocol.md``; it needs pyzmq and the standard library, and does not
import ``sa_daemon``.

The daemon has two sockets:

* a publisher (``--pub``, default ``tcp://127.0.0.1:5555``) sending two-frame messages
  ``[topic, json]`` on the topics ``state`` (at least 20 Hz) and ``event``;
* a command socket (``--cmd``, default ``tcp://127.0.0.1:5556``) answering one JSON object per
  request, reached with a ``REQ`` socket (one frame each way) or a ``DEALER`` socket (an empty
  delimiter frame, then the JSON, each way).

Library use::

    from protocol_client import Subscriber, CommandClient

    with Subscriber("tcp://127.0.0.1:5555") as sub, CommandClient("tcp://127.0.0.1:5556") as cmd:
        state = sub.wait_for(lambda m: m.topic == "state", timeout=5.0).body
        print(state["mode"], cmd.command("status")["uptime_s"])

Command line::

    python examples/protocol_client.py --pub tcp://127.0.0.1:5555 --cmd tcp://127.0.0.1:5556 \\
        follow --seconds 10
    python examples/protocol_client.py --cmd tcp://127.0.0.1:5556 command '{"cmd": "status"}'
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from typing import Any, Self

import zmq

__all__ = [
    "DEFAULT_CMD",
    "DEFAULT_PUB",
    "PROTOCOL_VERSION",
    "CommandClient",
    "CommandTimeout",
    "Message",
    "ProtocolError",
    "Subscriber",
    "encode_request",
    "main",
    "parse_json",
    "summarize_state",
]

PROTOCOL_VERSION = 2
DEFAULT_PUB = "tcp://127.0.0.1:5555"
DEFAULT_CMD = "tcp://127.0.0.1:5556"
TOPICS = ("state", "event")


class ProtocolError(Exception):
    """A message from the daemon does not have the documented shape."""


class CommandTimeout(TimeoutError):
    """No reply arrived in time (the daemon may be busy, gone, or may have dropped the request)."""


@dataclass(frozen=True)
class Message:
    """One publisher message: its ``topic`` (``"state"`` or ``"event"``), decoded ``body`` and
    the local ``received`` time (``time.monotonic()``)."""

    topic: str
    body: dict[str, Any]
    received: float


def _reject_constant(name: str) -> Any:
    raise ValueError(f"non-standard JSON constant {name}")


def parse_json(data: bytes | str) -> Any:
    """Decode strict JSON (UTF-8, no ``NaN``/``Infinity``), raising :class:`ProtocolError`."""
    try:
        text = data.decode("utf-8") if isinstance(data, bytes) else data
        return json.loads(text, parse_constant=_reject_constant)
    except (UnicodeDecodeError, ValueError) as exc:
        raise ProtocolError(f"invalid JSON from daemon: {exc}") from exc


def encode_request(request: dict[str, Any] | str | bytes) -> bytes:
    """Encode a request: a dict becomes strict JSON; ``str``/``bytes`` are sent as given, so
    malformed requests can be sent on purpose."""
    if isinstance(request, bytes):
        return request
    if isinstance(request, str):
        return request.encode("utf-8")
    return json.dumps(request, allow_nan=False, separators=(",", ":")).encode("utf-8")


def _seconds_to_ms(timeout: float | None) -> int | None:
    return None if timeout is None else max(0, math.ceil(timeout * 1000.0))


class _SocketOwner:
    """Closes its ``_socket`` on :meth:`close` and at the end of a ``with`` block."""

    _socket: zmq.Socket

    def close(self) -> None:
        """Close the socket."""
        self._socket.close(linger=0)

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class Subscriber(_SocketOwner):
    """A ``SUB`` socket on the daemon's publisher.

    ``topics`` are ZeroMQ prefix subscriptions. ``event`` is subscribed before ``state`` on
    purpose: subscriptions travel to the publisher in order, so once a ``state`` message arrives
    the ``event`` subscription is active too (see :meth:`wait_ready`).
    """

    def __init__(
        self,
        endpoint: str = DEFAULT_PUB,
        topics: Iterable[str] = TOPICS,
        context: zmq.Context | None = None,
    ) -> None:
        self.endpoint = endpoint
        self.topics = sorted(set(topics), key=lambda t: (t != "event", t))
        self._context = context or zmq.Context.instance()
        self._socket = self._context.socket(zmq.SUB)
        self._socket.setsockopt(zmq.LINGER, 0)
        for topic in self.topics:
            self._socket.setsockopt(zmq.SUBSCRIBE, topic.encode("ascii"))
        self._socket.connect(endpoint)

    def recv(self, timeout: float | None = 1.0) -> Message | None:
        """Return the next message, or ``None`` if none arrives within ``timeout`` seconds
        (``None`` waits forever). Raises :class:`ProtocolError` on a malformed message."""
        if not self._socket.poll(_seconds_to_ms(timeout), zmq.POLLIN):
            return None
        frames = self._socket.recv_multipart()
        received = time.monotonic()
        if len(frames) != 2:
            raise ProtocolError(f"expected 2 frames, got {len(frames)}")
        try:
            topic = frames[0].decode("ascii")
        except UnicodeDecodeError as exc:
            raise ProtocolError(f"topic is not ASCII: {frames[0]!r}") from exc
        body = parse_json(frames[1])
        if not isinstance(body, dict):
            raise ProtocolError(f"{topic} body is not a JSON object: {body!r}")
        return Message(topic, body, received)

    def messages(self, duration: float) -> Iterator[Message]:
        """Yield every message received during the next ``duration`` seconds."""
        deadline = time.monotonic() + duration
        while (left := deadline - time.monotonic()) > 0:
            message = self.recv(left)
            if message is not None:
                yield message

    def wait_for(
        self,
        predicate: Callable[[Message], bool],
        timeout: float,
        seen: list[Message] | None = None,
    ) -> Message:
        """Return the first message satisfying ``predicate`` within ``timeout`` seconds, else
        raise :class:`TimeoutError`. Every message read on the way is appended to ``seen``."""
        deadline = time.monotonic() + timeout
        while (left := deadline - time.monotonic()) > 0:
            message = self.recv(left)
            if message is None:
                break
            if seen is not None:
                seen.append(message)
            if predicate(message):
                return message
        raise TimeoutError(f"no matching message on {self.endpoint} within {timeout:.1f} s")

    def wait_state(self, predicate: Callable[[dict], bool] = lambda s: True, timeout: float = 5.0,
                   seen: list[Message] | None = None) -> dict[str, Any]:
        """Return the body of the first ``state`` message satisfying ``predicate``."""
        return self.wait_for(lambda m: m.topic == "state" and predicate(m.body), timeout, seen).body

    def wait_event(self, event_type: str | Iterable[str], timeout: float = 5.0,
                   seen: list[Message] | None = None) -> dict[str, Any]:
        """Return the body of the first ``event`` whose ``type`` is (one of) ``event_type``."""
        types = {event_type} if isinstance(event_type, str) else set(event_type)
        return self.wait_for(
            lambda m: m.topic == "event" and m.body.get("type") in types, timeout, seen
        ).body

    def wait_ready(self, timeout: float = 30.0) -> dict[str, Any]:
        """Wait for the first ``state`` message: the daemon is up and, when ``event`` is also
        subscribed, events from now on will be delivered."""
        return self.wait_state(timeout=timeout)

    def drain(self) -> int:
        """Discard every message already queued; return how many were dropped."""
        count = 0
        while self._socket.poll(0, zmq.POLLIN):
            self._socket.recv_multipart()
            count += 1
        return count


class CommandClient(_SocketOwner):
    """A client of the daemon's command socket, as ``REQ`` (default) or ``DEALER``.

    :meth:`request` sends one request and returns the decoded reply. If no reply arrives within
    the timeout, the socket is closed and re-created (a ``REQ`` socket cannot send again before
    it receives, and a late reply must not be mistaken for the answer to the next request), and
    :class:`CommandTimeout` is raised.
    """

    def __init__(
        self,
        endpoint: str = DEFAULT_CMD,
        socket_type: str = "req",
        context: zmq.Context | None = None,
        timeout: float = 5.0,
    ) -> None:
        if socket_type not in ("req", "dealer"):
            raise ValueError("socket_type must be 'req' or 'dealer'")
        self.endpoint = endpoint
        self.socket_type = socket_type
        self.timeout = timeout
        self._context = context or zmq.Context.instance()
        self._socket = self._open()

    def _open(self) -> zmq.Socket:
        socket = self._context.socket(zmq.REQ if self.socket_type == "req" else zmq.DEALER)
        socket.setsockopt(zmq.LINGER, 0)
        socket.connect(self.endpoint)
        return socket

    def _reset(self) -> None:
        self._socket.close(linger=0)
        self._socket = self._open()

    def request(
        self, request: dict[str, Any] | str | bytes, timeout: float | None = None
    ) -> dict[str, Any]:
        """Send ``request`` (a dict, or raw ``str``/``bytes``) and return the reply object.

        Raises :class:`CommandTimeout` when no reply arrives within ``timeout`` seconds (default:
        the client's ``timeout``), and :class:`ProtocolError` when the reply is malformed.
        """
        timeout = self.timeout if timeout is None else timeout
        payload = encode_request(request)
        if self.socket_type == "req":
            self._socket.send(payload)
        else:
            self._socket.send_multipart([b"", payload])
        if not self._socket.poll(_seconds_to_ms(timeout), zmq.POLLIN):
            self._reset()
            raise CommandTimeout(f"no reply from {self.endpoint} within {timeout:.1f} s")
        frames = self._socket.recv_multipart()
        if self.socket_type == "dealer":
            if len(frames) != 2 or frames[0] != b"":
                self._reset()
                raise ProtocolError(f"DEALER reply is not [empty, json]: {frames!r}")
            frames = frames[1:]
        elif len(frames) != 1:
            self._reset()
            raise ProtocolError(f"REQ reply has {len(frames)} frames, expected 1")
        reply = parse_json(frames[0])
        if not isinstance(reply, dict) or not isinstance(reply.get("ok"), bool):
            raise ProtocolError(f"reply is not an object with a boolean 'ok': {reply!r}")
        if reply["ok"] is False and not isinstance(reply.get("error"), str):
            raise ProtocolError(f"refusal without an 'error' string: {reply!r}")
        return reply

    def command(self, cmd: str, timeout: float | None = None, **fields: Any) -> dict[str, Any]:
        """Send ``{"cmd": cmd, **fields}``; e.g. ``command("set_method", method="ho")``."""
        return self.request({"cmd": cmd, **fields}, timeout=timeout)

    # Convenience wrappers for the documented commands.
    def status(self, timeout: float | None = None) -> dict[str, Any]:
        """``{"cmd": "status"}``."""
        return self.command("status", timeout)

    def stop(self, timeout: float | None = None) -> dict[str, Any]:
        """``{"cmd": "stop"}``: engage the latched stop."""
        return self.command("stop", timeout)

    def resume(self, timeout: float | None = None) -> dict[str, Any]:
        """``{"cmd": "resume"}``: release the stop and clear an arm fault."""
        return self.command("resume", timeout)

    def answer(self, value: str, timeout: float | None = None) -> dict[str, Any]:
        """``{"cmd": "answer", "value": value}`` with ``value`` ``"yes"`` or ``"no"``."""
        return self.command("answer", timeout, value=value)

    def set_method(self, method: str, timeout: float | None = None) -> dict[str, Any]:
        """``{"cmd": "set_method", "method": method}``."""
        return self.command("set_method", timeout, method=method)


def summarize_state(state: dict[str, Any]) -> str:
    """One line: t, mode, action, top belief goal and p, question, planner status, safety."""
    action = state.get("action") or {}
    action_text = str(action.get("kind"))
    if action.get("goal"):
        action_text += f":{action['goal']}"
    belief = state.get("belief") or []
    if belief:
        top = max(belief, key=lambda b: b.get("p", 0.0))
        belief_text = f"{top.get('goal')} p={top.get('p', 0.0):.3f}"
    else:
        belief_text = "- p=-"
    question = state.get("question")
    planner = state.get("planner") or {}
    flags = " STOPPED" if state.get("stopped") else ""
    return (
        f"t={state.get('t', float('nan')):8.2f}  mode={state.get('mode')}  action={action_text}  "
        f"top={belief_text}  question={json.dumps(question)}  "
        f"planner={planner.get('status')}  safety={state.get('safety')}{flags}"
    )


def _follow(args: argparse.Namespace) -> int:
    """Print a summary of the latest state once per second (and events if asked)."""
    with Subscriber(args.pub) as sub:
        deadline = time.monotonic() + args.seconds
        next_print = time.monotonic() + 1.0
        latest: dict[str, Any] | None = None
        while (now := time.monotonic()) < deadline:
            message = sub.recv(max(0.0, min(next_print, deadline) - now))
            if message is not None:
                if message.topic == "state":
                    latest = message.body
                elif message.topic == "event" and args.events:
                    print(f"event {json.dumps(message.body, sort_keys=True)}", flush=True)
            if time.monotonic() >= next_print:
                print(summarize_state(latest) if latest else "(no state yet)", flush=True)
                latest = None
                next_print += 1.0
    return 0


def _command(args: argparse.Namespace) -> int:
    """Send one raw request and print the reply; exit 0 if ok, 1 if refused, 2 on timeout."""
    with CommandClient(args.cmd, socket_type="dealer" if args.dealer else "req") as client:
        try:
            reply = client.request(args.request, timeout=args.timeout)
        except CommandTimeout as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 2
        except ProtocolError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 3
    print(json.dumps(reply, indent=2, sort_keys=True))
    return 0 if reply["ok"] else 1


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--pub", default=DEFAULT_PUB, help=f"publisher endpoint ({DEFAULT_PUB})")
    parser.add_argument("--cmd", default=DEFAULT_CMD, help=f"command endpoint ({DEFAULT_CMD})")
    sub = parser.add_subparsers(dest="action", required=True)
    follow = sub.add_parser("follow", help="print a one-line state summary per second")
    follow.add_argument("--seconds", type=float, default=10.0, help="how long to follow")
    follow.add_argument("--events", action="store_true", help="also print every event")
    follow.set_defaults(func=_follow)
    command = sub.add_parser("command", help="send one JSON request and print the reply")
    command.add_argument("request", help='the request, sent verbatim, e.g. \'{"cmd":"status"}\'')
    command.add_argument("--timeout", type=float, default=5.0, help="reply timeout (s)")
    command.add_argument("--dealer", action="store_true", help="use a DEALER socket, not REQ")
    command.set_defaults(func=_command)
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
