"""Black-box tests of the daemon's ZeroMQ protocol (docs/protocol.md), through
examples/protocol_client.py only.

The daemon is started once per module as a real subprocess (``sa-daemon run`` with the simulated
arm and user) on free loopback ports. Tests run in file order; the last one shuts the daemon down
with SIGTERM. Every wait is event-driven (a deadline on a message predicate), with generous
timeouts, except the latencies the document promises.
"""

from __future__ import annotations

import importlib.util
import itertools
import json
import math
import shutil
import signal
import socket
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import pytest
from helpers import COMMIT_MODEL_TOML

ROOT = Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location("protocol_client", ROOT / "examples" / "protocol_client.py")
pc = importlib.util.module_from_spec(_spec)
sys.modules.setdefault("protocol_client", pc)
_spec.loader.exec_module(pc)

STARTUP_TIMEOUT = 30.0
REPLY_TIMEOUT = 5.0
STATE_TIMEOUT = 5.0

MODES = {"translation", "rotation"}
ACTION_KINDS = {"move", "ho", "none", "question"}
PLANNER_STATUSES = {"idle", "starting", "ok", "late", "restarting", "failed"}
SAFETY_CODES = [
    "ok", "speed_limited", "accel_limited", "workspace_limited", "singularity_slow",
    "joint_speed_limited", "singularity_halt", "joint_bound", "stale_input", "nan_refused",
    "arm_fault", "stopped",
]
METHODS = {
    "manual", "ho", "ho+noassist", "blend", "policy", "policy+noqns",
    "policy+withoutnoassist", "policy+noho",
}
ARM_BACKENDS = {"kinematic", "mujoco", "xarm"}
INPUT_BACKENDS = {"sim", "evdev"}
MAX_REQUEST_BYTES = 65536  # documented default of zmq.max_request_bytes


# --------------------------------------------------------------------------- helpers


def free_port() -> int:
    """A free loopback TCP port (bind to port 0, read it back, release it)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def is_number(x: object) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def is_int(x: object) -> bool:
    return isinstance(x, int) and not isinstance(x, bool)


def is_numbers(x: object, n: int) -> bool:
    return isinstance(x, list) and len(x) == n and all(is_number(v) for v in x)


def nested(depth: int) -> dict:
    """An object ``depth`` levels deep: nested(1) == {}, nested(2) == {"a": {}}."""
    return {} if depth <= 1 else {"a": nested(depth - 1)}


def find_event(seen: list, event_type: str) -> dict | None:
    for m in seen:
        if m.topic == "event" and m.body.get("type") == event_type:
            return m.body
    return None


def check_state(state: dict) -> list[str]:
    """Every documented field of a ``state`` message with its documented type; returns problems."""
    bad: list[str] = []

    def need(cond: bool, what: str) -> None:
        if not cond:
            bad.append(what)

    need(is_int(state.get("v")) and state.get("v") == pc.PROTOCOL_VERSION, f"v={state.get('v')!r}")
    need(is_number(state.get("t")) and state["t"] >= 0, f"t={state.get('t')!r}")
    need(state.get("mode") in MODES, f"mode={state.get('mode')!r}")
    for key in ("user_twist", "robot_twist", "command_twist"):
        need(is_numbers(state.get(key), 6), f"{key}={state.get(key)!r}")
    pose = state.get("gripper_pose")
    need(isinstance(pose, dict) and is_numbers(pose.get("position"), 3)
         and is_numbers(pose.get("quat_wxyz"), 4), f"gripper_pose={pose!r}")
    need(isinstance(state.get("gripper_closed"), bool), f"gripper_closed={state.get('gripper_closed')!r}")

    belief = state.get("belief")
    goals: set[str] = set()
    if isinstance(belief, list) and belief and all(isinstance(b, dict) for b in belief):
        for b in belief:
            goal, p = b.get("goal"), b.get("p")
            need(isinstance(goal, str) and ":" in goal, f"belief goal {goal!r} is not '<object>:<grasp>'")
            need(is_number(p) and 0.0 <= p <= 1.0, f"belief p={p!r}")
            goals.add(goal)
        total = math.fsum(b["p"] for b in belief if is_number(b.get("p")))
        # "within 1e-6", inclusive; the 1e-12 only absorbs the binary representation of decimals
        # (the daemon publishes p with 6 decimals, so the decimal sum can be exactly 1 +/- 1e-6).
        need(abs(total - 1.0) <= 1e-6 + 1e-12, f"belief p sum to {total!r}")
    else:
        bad.append(f"belief={belief!r}")

    action = state.get("action")
    if isinstance(action, dict) and action.get("kind") in ACTION_KINDS:
        if action["kind"] in ("move", "question"):
            need(isinstance(action.get("goal"), str) and action["goal"] in goals,
                 f"action {action!r} has no goal name from the belief")
    else:
        bad.append(f"action={action!r}")
    need(state.get("question") is None or isinstance(state.get("question"), str),
         f"question={state.get('question')!r}")

    planner = state.get("planner")
    if isinstance(planner, dict):
        need(planner.get("pid") is None or is_int(planner.get("pid")), f"planner.pid={planner.get('pid')!r}")
        need(planner.get("status") in PLANNER_STATUSES, f"planner.status={planner.get('status')!r}")
        # Type not stated in the document; a number, or null before the first plan.
        need(planner.get("last_plan_ms") is None or is_number(planner.get("last_plan_ms")),
             f"planner.last_plan_ms={planner.get('last_plan_ms')!r}")
        need(is_int(planner.get("restarts")), f"planner.restarts={planner.get('restarts')!r}")
        need(is_int(planner.get("plans")), f"planner.plans={planner.get('plans')!r}")
    else:
        bad.append(f"planner={planner!r}")

    need(state.get("safety") in SAFETY_CODES, f"safety={state.get('safety')!r}")
    codes = state.get("safety_codes")
    need(isinstance(codes, list) and all(isinstance(c, str) for c in codes), f"safety_codes={codes!r}")
    need(state.get("method") in METHODS, f"method={state.get('method')!r}")
    need(isinstance(state.get("assist"), bool), f"assist={state.get('assist')!r}")
    need(isinstance(state.get("stopped"), bool), f"stopped={state.get('stopped')!r}")
    arm = state.get("arm")
    need(isinstance(arm, dict) and arm.get("backend") in ARM_BACKENDS
         and (arm.get("fault") is None or isinstance(arm.get("fault"), str)), f"arm={arm!r}")
    inp = state.get("input")
    need(isinstance(inp, dict) and inp.get("backend") in INPUT_BACKENDS
         and isinstance(inp.get("connected"), bool) and isinstance(inp.get("fresh"), bool), f"input={inp!r}")
    need(state.get("task") is None or isinstance(state.get("task"), str), f"task={state.get('task')!r}")
    return bad


# --------------------------------------------------------------------------- fixtures


@dataclass
class Daemon:
    proc: subprocess.Popen
    pub: str
    cmd: str
    log: Path

    def log_text(self) -> str:
        try:
            return self.log.read_text(errors="replace")[-4000:]
        except OSError:
            return ""


@pytest.fixture(scope="module")
def daemon(tmp_path_factory: pytest.TempPathFactory):
    exe = shutil.which("sa-daemon")
    if exe is None:
        pytest.skip("sa-daemon is not on PATH")
    pub = f"tcp://127.0.0.1:{free_port()}"
    cmd = f"tcp://127.0.0.1:{free_port()}"
    folder = tmp_path_factory.mktemp("daemon")
    log = folder / "daemon.log"
    config = folder / "config.toml"
    config.write_text(COMMIT_MODEL_TOML)  # a question is pending within the tests' timeouts
    args = [exe, "run", "--arm", "kinematic", "--input", "sim", "--scene", "scene1",
            "--task", "cup:top", "--duration", "40", "--pub", pub, "--cmd", cmd,
            "--no-speech", "--quiet", "--config", str(config)]
    with open(log, "wb") as out:
        proc = subprocess.Popen(args, stdout=out, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
    d = Daemon(proc, pub, cmd, log)
    try:
        with pc.Subscriber(pub) as sub:
            deadline = time.monotonic() + STARTUP_TIMEOUT
            while sub.recv(0.5) is None:
                if proc.poll() is not None:
                    pytest.fail(f"daemon exited with {proc.returncode} before publishing:\n{d.log_text()}")
                if time.monotonic() > deadline:
                    pytest.fail(f"no state within {STARTUP_TIMEOUT} s:\n{d.log_text()}")
        yield d
    finally:
        if proc.poll() is None:
            proc.terminate()
            try:
                proc.wait(10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()


@pytest.fixture
def sub(daemon: Daemon):
    """A subscriber to both topics that has already received a state (so events are flowing)."""
    with pc.Subscriber(daemon.pub) as s:
        s.wait_ready(STATE_TIMEOUT)
        yield s


@pytest.fixture
def req(daemon: Daemon):
    """A REQ command client."""
    with pc.CommandClient(daemon.cmd, timeout=REPLY_TIMEOUT) as c:
        yield c


# --------------------------------------------------------------------------- publisher


def test_state_rate_at_least_20hz(daemon: Daemon) -> None:
    with pc.Subscriber(daemon.pub, topics=["state"]) as s:
        first = s.wait_ready(STATE_TIMEOUT)
        start = time.monotonic()
        stamps = [first["t"]]
        for m in s.messages(2.0):
            stamps.append(m.body["t"])
        elapsed = time.monotonic() - start
    count = len(stamps) - 1
    assert count / elapsed >= 20.0, f"{count} states in {elapsed:.2f} s"
    # Daemon clock agrees: the messages span about the same time and t increases.
    assert all(b > a for a, b in itertools.pairwise(stamps)), "state t is not increasing"
    assert count / (stamps[-1] - stamps[0]) >= 20.0


def test_state_fields_and_types(daemon: Daemon) -> None:
    with pc.Subscriber(daemon.pub, topics=["state"]) as s:
        states = [s.wait_ready(STATE_TIMEOUT)] + [m.body for m in s.messages(1.5)]
    assert len(states) > 20
    problems = {p for st in states for p in check_state(st)}
    assert not problems, sorted(problems)
    last = states[-1]
    assert last["arm"]["backend"] == "kinematic"
    assert last["input"]["backend"] == "sim"
    assert last["task"] == "cup:top"


# --------------------------------------------------------------------------- commands


def test_status_reply(req: pc.CommandClient, daemon: Daemon) -> None:
    reply = req.status()
    assert reply["ok"] is True
    expected = {"version", "method", "arm", "arm_fault", "input", "input_connected", "planner",
                "stopped", "assist", "uptime_s", "scene", "task", "pid"}
    assert expected <= reply.keys(), expected - reply.keys()
    assert is_int(reply["version"]) and reply["version"] == pc.PROTOCOL_VERSION
    assert reply["method"] in METHODS
    assert reply["arm"] == "kinematic"
    assert reply["arm_fault"] is None or isinstance(reply["arm_fault"], str)
    assert reply["input"] == "sim"
    assert isinstance(reply["input_connected"], bool)
    planner = reply["planner"]  # "as in state"
    assert isinstance(planner, dict)
    assert {"pid", "status", "last_plan_ms", "restarts", "plans"} <= planner.keys()
    assert planner["status"] in PLANNER_STATUSES
    assert isinstance(reply["stopped"], bool) and isinstance(reply["assist"], bool)
    assert is_number(reply["uptime_s"]) and reply["uptime_s"] > 0
    assert reply["scene"] == "scene1"
    assert reply["task"] is None or isinstance(reply["task"], str)
    assert is_int(reply["pid"])


def test_request_id_is_ignored_and_not_echoed(req: pc.CommandClient) -> None:
    for rid in ("abc", 7, None, [1, 2], {"k": "v"}):
        reply = req.request({"cmd": "status", "id": rid})
        assert reply["ok"] is True, reply
        assert "id" not in reply


def test_stop_and_resume(req: pc.CommandClient, sub: pc.Subscriber) -> None:
    seen: list = []
    sent = time.monotonic()
    assert req.stop() == {"ok": True}
    msg = sub.wait_for(
        lambda m: m.topic == "state" and m.body["stopped"] is True
        and all(v == 0 for v in m.body["command_twist"]),
        timeout=STATE_TIMEOUT, seen=seen)
    assert msg.received - sent <= 0.5, f"stopped state after {msg.received - sent:.3f} s"
    # "commanded zero at once and every tick until resume"
    for m in sub.messages(0.3):
        seen.append(m)
        if m.topic == "state":
            assert m.body["stopped"] is True and all(v == 0 for v in m.body["command_twist"]), m.body
    event = find_event(seen, "stop") or sub.wait_event("stop", STATE_TIMEOUT)
    assert event["source"] == "command"
    assert is_number(event["t"])

    seen = []
    assert req.resume() == {"ok": True}
    sub.wait_state(lambda s: s["stopped"] is False, STATE_TIMEOUT, seen=seen)
    assert find_event(seen, "resume") or sub.wait_event("resume", STATE_TIMEOUT)
    assert req.status()["stopped"] is False


def test_answer_pending_question(req: pc.CommandClient, sub: pc.Subscriber) -> None:
    """With the policy method the planner asks; answering by command is accepted. The simulated
    user answers after ~1.5 s, so we answer as soon as the question event arrives."""
    question = sub.wait_event("question", timeout=15.0)
    assert isinstance(question["goal"], str) and isinstance(question["text"], str)
    seen: list = []
    reply = req.answer("no")
    assert reply == {"ok": True}, reply
    answer = sub.wait_event("answer", STATE_TIMEOUT, seen=seen)
    assert answer["goal"] == question["goal"]
    assert answer["value"] == "no"
    assert answer["source"] == "command"


def test_set_method_ho(req: pc.CommandClient, sub: pc.Subscriber) -> None:
    seen: list = []
    reply = req.set_method("ho")
    assert reply["ok"] is True and reply["method"] == "ho", reply
    sub.wait_state(lambda s: s["method"] == "ho", STATE_TIMEOUT, seen=seen)
    event = find_event(seen, "method") or sub.wait_event("method", STATE_TIMEOUT)
    assert event["method"] == "ho"
    assert req.status()["method"] == "ho"


def test_set_method_unknown_is_refused(req: pc.CommandClient) -> None:
    before = req.status()["method"]
    reply = req.set_method("teleport")
    assert reply["ok"] is False
    assert isinstance(reply["error"], str) and reply["error"]
    assert req.status()["method"] == before  # unchanged


def test_answer_without_pending_question_is_refused(req: pc.CommandClient, sub: pc.Subscriber) -> None:
    # Method "ho" (previous test) is not a question-asking policy; make sure nothing is pending.
    req.set_method("ho")
    deadline = time.monotonic() + 10.0
    quiet = 0
    while quiet < 10:  # ten consecutive states without a question
        state = sub.wait_state(timeout=max(0.1, deadline - time.monotonic()))
        quiet = quiet + 1 if state["question"] is None else 0
    reply = req.answer("yes")
    assert reply == {"ok": False, "error": "no question is pending"}


_SIZE_PAD = "x" * (70 * 1024)

MALFORMED = {
    "not_json": b"hello daemon",
    "empty": b"",
    "not_utf8": b'{"cmd": "status", "id": "\xff\xfe"}',
    "json_array": b'[{"cmd": "status"}]',
    "json_string": b'"status"',
    "json_null": b"null",
    "no_cmd": {"method": "ho"},
    "empty_object": {},
    "cmd_not_string": {"cmd": 5},
    "unknown_cmd": {"cmd": "fly"},
    "unknown_field": {"cmd": "status", "speed": 1},
    "wrong_type_method": {"cmd": "set_method", "method": 5},
    "wrong_type_answer": {"cmd": "answer", "value": True},
    "wrong_value_answer": {"cmd": "answer", "value": "maybe"},
    "missing_value": {"cmd": "set_method"},
    "70kB": json.dumps({"cmd": "status", "id": _SIZE_PAD}),
    "nested_20": json.dumps({"cmd": "status", "id": nested(19)}),
    "nan": b'{"cmd": "status", "id": NaN}',
    "infinity": b'{"cmd": "status", "id": Infinity}',
    "minus_infinity": b'{"cmd": "set_method", "method": -Infinity}',
    "bare_nan": b"NaN",
}


@pytest.mark.parametrize("request_", list(MALFORMED.values()), ids=list(MALFORMED))
def test_malformed_request_is_refused(req: pc.CommandClient, request_) -> None:
    reply = req.request(request_)
    assert reply["ok"] is False, reply
    assert isinstance(reply.get("error"), str) and reply["error"], reply
    assert set(reply) == {"ok", "error"}, reply
    assert req.status()["ok"] is True


def test_nesting_depth_limit(req: pc.CommandClient) -> None:
    """Far below the limit is accepted (the boundary itself is not pinned down by the document)."""
    assert req.request({"cmd": "status", "id": nested(3)})["ok"] is True
    assert req.request({"cmd": "status", "id": nested(20)})["ok"] is False


def test_far_oversized_request_gets_no_reply(daemon: Daemon) -> None:
    with pc.CommandClient(daemon.cmd) as c:
        with pytest.raises(pc.CommandTimeout):
            c.request(b"x" * (17 * MAX_REQUEST_BYTES), timeout=2.0)
        # The client re-created its socket; the daemon goes on.
        assert c.status()["ok"] is True


def test_dealer_client(daemon: Daemon) -> None:
    with pc.CommandClient(daemon.cmd, socket_type="dealer", timeout=REPLY_TIMEOUT) as c:
        reply = c.status()  # the client checks the [b"", json] framing
        assert reply["ok"] is True and reply["version"] == 2
        refusal = c.request(b"[]")
        assert refusal["ok"] is False and isinstance(refusal["error"], str)
        assert c.status()["ok"] is True


def test_cli_command(daemon: Daemon) -> None:
    out = subprocess.run(
        [sys.executable, str(ROOT / "examples" / "protocol_client.py"), "--cmd", daemon.cmd,
         "command", '{"cmd": "status"}'],
        check=False, capture_output=True, text=True, timeout=30)
    assert out.returncode == 0, out.stderr
    assert json.loads(out.stdout)["ok"] is True


# --------------------------------------------------------------------------- shutdown (last)


def test_sigterm_shuts_down_cleanly(daemon: Daemon, sub: pc.Subscriber) -> None:
    assert daemon.proc.poll() is None, "daemon ended early"
    seen: list = []
    daemon.proc.send_signal(signal.SIGTERM)
    deadline = time.monotonic() + 20.0
    while daemon.proc.poll() is None and time.monotonic() < deadline:
        m = sub.recv(0.1)
        if m is not None:
            seen.append(m)
    if daemon.proc.poll() is None:
        pytest.fail("daemon did not exit within 20 s of SIGTERM")
    seen.extend(sub.messages(0.5))  # anything still in flight
    assert daemon.proc.returncode == 0, daemon.log_text()
    types = [m.body.get("type") for m in seen if m.topic == "event"]
    assert {"shutdown", "stopped"} & set(types), f"events seen: {types}"
    shutdown = find_event(seen, "shutdown")
    if shutdown is not None:
        assert isinstance(shutdown["reason"], str)
    stopped = find_event(seen, "stopped")
    if stopped is not None:
        assert stopped["code"] == 0
