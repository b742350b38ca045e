"""The ZeroMQ protocol of ``docs/protocol.md``: request validation and message encoding.

Pure functions, no sockets: the server (:mod:`.server`) and any client share them. Version
:data:`PROTOCOL_VERSION` is in every state message and in the ``status`` reply.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass
from typing import Any

from ..config import METHODS

PROTOCOL_VERSION = 2
TOPIC_STATE = b"state"
TOPIC_EVENT = b"event"

COMMANDS = ("status", "answer", "stop", "resume", "set_method", "scene", "set_profile", "set_scene")
#: A profile named over the protocol: a name in ``profiles.dir``, never a path.
PROFILE_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,63}$")


class RequestError(ValueError):
    """A refused request; the message is the ``error`` of the reply."""


@dataclass(frozen=True)
class Request:
    """A validated command: ``cmd`` and its arguments."""

    cmd: str
    args: dict[str, Any]


def _bracket_depth(text: str) -> int:
    """Nesting depth of a JSON text, counted on the raw text (brackets outside strings): a hostile
    document is refused before ``json.loads`` recurses into it, and for any text ``json.loads``
    accepts this is exactly the depth of the decoded value."""
    depth = peak = 0
    in_str = esc = False
    for ch in text:
        if in_str:
            if esc:
                esc = False
            elif ch == "\\":
                esc = True
            elif ch == '"':
                in_str = False
        elif ch == '"':
            in_str = True
        elif ch in "[{":
            depth += 1
            peak = max(peak, depth)
        elif ch in "]}":
            depth -= 1
    return peak


def parse_request(raw: bytes, max_bytes: int = 65536, max_depth: int = 8) -> Request:
    """Decode and validate one request; raise :class:`RequestError` with the reason otherwise."""
    if len(raw) > max_bytes:
        raise RequestError(f"request too large: {len(raw)} bytes (limit {max_bytes})")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        raise RequestError("request is not UTF-8 text") from None
    if _bracket_depth(text) > max_depth:
        raise RequestError(f"request nested deeper than {max_depth} levels")
    try:
        obj = json.loads(text, parse_constant=_refuse_constant)
    except RequestError:
        raise
    except (ValueError, RecursionError) as e:
        raise RequestError(f"request is not valid JSON: {e}") from None
    if not isinstance(obj, dict):
        raise RequestError(f"request must be a JSON object, got {type(obj).__name__}")
    cmd = obj.get("cmd")
    if not isinstance(cmd, str):
        raise RequestError('request needs "cmd" (a string)')
    if cmd not in COMMANDS:
        raise RequestError(f"unknown command {cmd[:40]!r} (one of {', '.join(COMMANDS)})")
    args = {k: v for k, v in obj.items() if k != "cmd"}
    allowed = {"answer": {"value"}, "set_method": {"method"}, "set_profile": {"profile"},
               "set_scene": {"scene", "when", "marker_to_base"}}.get(cmd, set())
    extra = sorted(set(args) - allowed - {"id"})
    if extra:
        raise RequestError(f"{cmd}: unexpected field(s) {', '.join(repr(e[:40]) for e in extra[:5])}")
    if cmd == "answer":
        value = args.get("value")
        if value not in ("yes", "no", "other"):
            raise RequestError('answer: "value" must be "yes", "no" or "other" (that object, another grasp)')
    if cmd == "set_profile":
        name = args.get("profile")
        if not isinstance(name, str) or not PROFILE_NAME.match(name) or name.endswith(".toml"):
            raise RequestError('set_profile: "profile" must be a profile name (letters, digits, _ . -; no path)')
    if cmd == "set_scene":
        if not isinstance(args.get("scene"), dict):
            raise RequestError('set_scene: "scene" must be an object (the scene file\'s format as JSON)')
        if args.get("when", "now") not in ("now", "next_task"):
            raise RequestError('set_scene: "when" must be "now" or "next_task"')
        if args.get("marker_to_base") is not None and not isinstance(args["marker_to_base"], dict):
            raise RequestError('set_scene: "marker_to_base" must be {"position": [...], "quat_wxyz": [...]}')
    if cmd == "set_method":
        method = args.get("method")
        if not isinstance(method, str) or method not in METHODS:
            raise RequestError(f'set_method: "method" must be one of {", ".join(METHODS)}')
    return Request(cmd, args)


def _refuse_constant(name: str) -> Any:
    raise RequestError(f"request contains {name}, which is not JSON")


def encode(obj: Any) -> bytes:
    """Compact JSON; NaN/inf are refused (they never reach a client either)."""
    return json.dumps(obj, separators=(",", ":"), allow_nan=False).encode()


def ok(**fields: Any) -> bytes:
    return encode({"ok": True, **fields})


def error(reason: str) -> bytes:
    return encode({"ok": False, "error": reason})


def finite_list(values: Any, ndigits: int = 6) -> list[float]:
    """A JSON-ready list of rounded floats; non-finite values become 0 (and are counted as a fault
    upstream: the safety pipeline never lets them reach the arm)."""
    return [round(float(v), ndigits) if math.isfinite(float(v)) else 0.0 for v in values]
