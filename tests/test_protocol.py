"""Request validation and encoding of the ZeroMQ protocol (``docs/protocol.md``), including a fuzz test."""

from __future__ import annotations

import json
import math

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from sa_daemon.config import METHODS
from sa_daemon.io import protocol
from sa_daemon.io.protocol import COMMANDS, Request, RequestError, encode, parse_request


def _req(obj) -> bytes:
    return json.dumps(obj).encode()


# -- accepted ------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "obj, args",
    [
        ({"cmd": "status"}, {}),
        ({"cmd": "stop"}, {}),
        ({"cmd": "resume"}, {}),
        ({"cmd": "answer", "value": "yes"}, {"value": "yes"}),
        ({"cmd": "answer", "value": "no"}, {"value": "no"}),
        *[({"cmd": "set_method", "method": m}, {"method": m}) for m in METHODS],
        ({"cmd": "status", "id": 17}, {"id": 17}),
        ({"cmd": "answer", "value": "no", "id": {"any": ["thing"]}}, {"value": "no", "id": {"any": ["thing"]}}),
    ],
)
def test_valid_commands_are_accepted(obj, args):
    r = parse_request(_req(obj))
    assert r == Request(obj["cmd"], args)


def test_every_documented_command_is_known():
    """The commands table of docs/protocol.md and the code list the same commands."""
    import re
    from pathlib import Path

    doc = (Path(__file__).resolve().parents[1] / "docs" / "protocol.md").read_text()
    documented = set(re.findall(r'^\| `\{"cmd": "([a-z_]+)"', doc, re.MULTILINE))
    assert documented == set(COMMANDS) and "scene" in documented


def test_whitespace_and_unicode_are_fine():
    assert parse_request(b'  \n{ "cmd" : "status", "id": "caf\xc3\xa9 \xe2\x9c\x93" }\n ').cmd == "status"


def test_brackets_inside_strings_do_not_count_as_nesting():
    raw = _req({"cmd": "status", "id": "[[[[[[[[[[{{{{{{{{{{ \" [[[[[[[["})
    assert parse_request(raw).cmd == "status"


def test_nesting_up_to_the_limit_is_accepted():
    deep_ok = {"cmd": "status", "id": [[[[[[[1]]]]]]]}  # object + 7 lists = depth 8
    assert parse_request(_req(deep_ok), max_depth=8).cmd == "status"


# -- refused -------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "raw, reason",
    [
        (b'{"cmd": "status", "id": "\xff\xfe"}', "UTF-8"),
        (b"\xc3\x28", "UTF-8"),
        (b"", "not valid JSON"),
        (b"{cmd: status}", "not valid JSON"),
        (b'{"cmd": "status"', "not valid JSON"),
        (b'{"cmd": "status"} trailing', "not valid JSON"),
        (b'{"cmd": "status", "id": NaN}', "NaN"),
        (b'{"cmd": "status", "id": Infinity}', "Infinity"),
        (b'{"cmd": "status", "id": -Infinity}', "Infinity"),
        (b'{"cmd": "status", "id": 1' + b"1" * 5000 + b"}", "not valid JSON"),  # int digit limit
        (b'[{"cmd": "status"}]', "JSON object"),
        (b'"status"', "JSON object"),
        (b"42", "JSON object"),
        (b"null", "JSON object"),
        (b"true", "JSON object"),
        (b"{}", '"cmd"'),
        (b'{"cmd": 3}', '"cmd"'),
        (b'{"cmd": null}', '"cmd"'),
        (b'{"cmd": ["status"]}', '"cmd"'),
        (b'{"command": "status"}', '"cmd"'),
        (b'{"cmd": "reboot"}', "unknown command 'reboot'"),
        (b'{"cmd": "STATUS"}', "unknown command"),
        (b'{"cmd": "status", "verbose": true}', "unexpected field.*verbose"),
        (b'{"cmd": "stop", "value": "yes"}', "unexpected field.*value"),
        (b'{"cmd": "answer", "value": "yes", "method": "ho"}', "unexpected field.*method"),
        (b'{"cmd": "answer"}', '"value" must be "yes", "no" or "other"'),
        (b'{"cmd": "answer", "value": "YES"}', '"value" must be'),
        (b'{"cmd": "answer", "value": true}', '"value" must be'),
        (b'{"cmd": "answer", "value": 1}', '"value" must be'),
        (b'{"cmd": "answer", "value": ["yes"]}', '"value" must be'),
        (b'{"cmd": "set_method", "method": "teleport"}', '"method" must be one of'),
        (b'{"cmd": "set_method", "method": 3}', '"method" must be one of'),
        (b'{"cmd": "set_method"}', '"method" must be one of'),
    ],
)
def test_bad_requests_are_refused_with_a_reason(raw, reason):
    with pytest.raises(RequestError, match=reason):
        parse_request(raw)


def test_unknown_command_name_is_truncated_in_the_reason():
    with pytest.raises(RequestError) as e:
        parse_request(_req({"cmd": "x" * 10000}))
    assert len(str(e.value)) < 200


def test_too_large_is_refused_before_decoding():
    raw = _req({"cmd": "status", "id": "a" * 70000})
    with pytest.raises(RequestError, match="too large"):
        parse_request(raw)
    with pytest.raises(RequestError, match="too large"):
        parse_request(b"\xff" * 300, max_bytes=256)  # size first, even for garbage
    assert parse_request(raw, max_bytes=len(raw)).cmd == "status"


def test_too_deep_is_refused():
    deep = {"cmd": "status", "id": [[[[[[[[1]]]]]]]]}  # depth 9
    with pytest.raises(RequestError, match="nested deeper than 8"):
        parse_request(_req(deep))
    with pytest.raises(RequestError, match="nested deeper than 2"):
        parse_request(b'{"cmd": "status", "id": {"a": {"b": 1}}}', max_depth=2)
    assert parse_request(b'{"cmd": "status", "id": {"a": {"b": 1}}}', max_depth=3).cmd == "status"


@pytest.mark.parametrize("opener", [b"[", b"{", b'{"a":', b"[{"])
def test_hostile_nesting_is_refused_without_recursion(opener):
    raw = opener * 100000
    with pytest.raises(RequestError, match="nested deeper"):
        parse_request(raw, max_bytes=len(raw))
    closed = b"[" * 100000 + b"]" * 100000
    with pytest.raises(RequestError, match="nested deeper"):
        parse_request(closed, max_bytes=len(closed))


# -- fuzz ----------------------------------------------------------------------------------------------

json_values = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False, allow_infinity=False) | st.text(),
    lambda children: st.lists(children, max_size=4) | st.dictionaries(st.text(max_size=8), children, max_size=4),
    max_leaves=30,
)


def _check(raw: bytes) -> None:
    try:
        r = parse_request(raw)
    except RequestError as e:
        assert str(e)  # every refusal has a reason
        return
    assert isinstance(r, Request) and r.cmd in COMMANDS
    json.dumps(r.args)  # arguments are plain JSON


@settings(max_examples=300, suppress_health_check=[HealthCheck.too_slow], deadline=None)
@given(st.binary(max_size=300))
def test_fuzz_random_bytes(raw):
    _check(raw)


@settings(max_examples=300, deadline=None)
@given(json_values)
def test_fuzz_random_json_values(value):
    _check(json.dumps(value).encode())
    _check(json.dumps(value, ensure_ascii=False).encode("utf-8", "surrogatepass"))


@settings(max_examples=300, deadline=None)
@given(
    st.sampled_from(COMMANDS + ("", "statu", "answer ")),
    st.dictionaries(st.sampled_from(["value", "method", "id", "x", "cmd"]), json_values, max_size=3),
)
def test_fuzz_command_shaped_objects(cmd, extra):
    obj = {"cmd": cmd, **extra}
    raw = json.dumps(obj).encode()
    try:
        r = parse_request(raw)
    except RequestError:
        return
    # Accepted only when it is exactly a valid request.
    assert r.cmd == obj["cmd"] in COMMANDS
    allowed = {"answer": {"value"}, "set_method": {"method"}}.get(r.cmd, set()) | {"id"}
    assert set(r.args) <= allowed
    if r.cmd == "answer":
        assert r.args["value"] in ("yes", "no")
    if r.cmd == "set_method":
        assert r.args["method"] in METHODS


# -- encoding ------------------------------------------------------------------------------------------


def test_encode_is_compact_json():
    assert encode({"a": [1, 2.5], "b": None}) == b'{"a":[1,2.5],"b":null}'
    assert json.loads(protocol.ok(method="ho")) == {"ok": True, "method": "ho"}
    assert json.loads(protocol.error("no question is pending")) == {"ok": False, "error": "no question is pending"}


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_encode_refuses_non_finite_numbers(bad):
    with pytest.raises(ValueError):
        encode({"t": 1.0, "x": [0.0, bad]})


def test_finite_list_rounds_and_zeroes_non_finite():
    assert protocol.finite_list([1.23456789, math.nan, math.inf, -2.0], ndigits=3) == [1.235, 0.0, 0.0, -2.0]


@pytest.mark.parametrize("name", ["../etc/passwd", "a/b", "alex.toml", "", ".hidden", 5, None, "x" * 65])
def test_set_profile_takes_a_plain_name_only(name):
    with pytest.raises(RequestError, match="profile name"):
        parse_request(_req({"cmd": "set_profile", "profile": name}))
    assert parse_request(_req({"cmd": "set_profile", "profile": "alex-2.left_hand"})).args["profile"] == "alex-2.left_hand"
