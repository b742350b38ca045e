"""The live view for Foxglove (issue 19, part 3): the messages built from the protocol's, the feed's rates,
a real daemon serving a WebSocket client written from the Foxglove WebSocket protocol's specification
(github.com/foxglove/ws-protocol, docs/spec.md), and the recording carrying the same topics and schemas.

Messages are decoded with ``protobuf`` from the schema the server advertises (a ``FileDescriptorSet``),
as Foxglove does: nothing here trusts the SDK's own decoder.
"""

from __future__ import annotations

import asyncio
import base64
import json
import math
import struct
import subprocess
import sys
from pathlib import Path

import aiohttp
import numpy as np
import pytest
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from helpers import CLI, DaemonProc, free_port, free_ports
from mcap.reader import make_reader

from sa_daemon.runtime.messages import scene as scene_reply
from sa_daemon.viz import messages as fx
from sa_daemon.viz.feed import VizFeed
from sa_daemon.world.goals import object_probabilities
from sa_daemon.world.scene import load_scene

SUBPROTOCOL = "foxglove.sdk.v1"  # the SDK's server accepts only this one (ws-protocol's v1 framing)
MESSAGE_DATA = 1  # the server's binary opcode for a message on a subscription


def decoder(schema_name: str, schema: bytes):
    """The protobuf message class named ``schema_name`` from a serialised ``FileDescriptorSet``."""
    fds = descriptor_pb2.FileDescriptorSet.FromString(schema)
    pool = descriptor_pool.DescriptorPool()
    for f in fds.file:
        pool.Add(f)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(schema_name))


def decode(msg) -> object:
    """A Foxglove SDK message decoded through its own published schema."""
    s = type(msg).get_schema()
    return decoder(s.name, s.data).FromString(msg.encode())


class _View:
    """What :func:`~sa_daemon.runtime.messages.scene` reads of a daemon."""

    def __init__(self, scene) -> None:
        self.scene_data = scene


SCENE1 = scene_reply(_View(load_scene("scene1")))


def _state(belief: dict[str, float], command=(0.1, 0.0, 0.0), user=(0.0, 0.0, 0.0), t=1.0) -> dict:
    return {"t": t, "gripper_pose": {"position": [0.3, 0.0, 0.3], "quat_wxyz": [0.0, 1.0, 0.0, 0.0]},
            "gripper_closed": False, "belief": [{"goal": g, "p": p} for g, p in belief.items()],
            "command_twist": [*command, 0, 0, 0], "user_twist": [*user, 0, 0, 0],
            "action": {"kind": "move", "goal": "cup:top"}, "question": None}


def _rotate_x(q) -> np.ndarray:
    """Where a protobuf ``Quaternion`` takes the unit x axis."""
    w, x, y, z = q.w, q.x, q.y, q.z
    return np.array([1 - 2 * (y * y + z * z), 2 * (x * y + w * z), 2 * (x * z - w * y)])


# -- the messages --------------------------------------------------------------------------------------------


def test_the_scene_has_the_table_every_object_and_every_grasp_pose_coloured_by_the_belief():
    targets = [g["target"] for g in SCENE1["goals"]]
    belief = {t: 0.0 for t in targets} | {"cup:top": 0.7, "cup:side": 0.2, "bowl:top": 0.1}
    up = decode(fx.scene_update(SCENE1, belief, 5_000_000_123))
    ents = {e.id: e for e in up.entities}
    assert set(ents) == {"table"} | {f"object/{o['name']}" for o in SCENE1["objects"]} | {f"grasps/{t}" for t in targets}
    assert all(e.frame_id == "base" and e.timestamp.seconds == 5 and e.timestamp.nanos == 123 for e in up.entities)
    for g in SCENE1["goals"]:
        arrows = ents[f"grasps/{g['target']}"].arrows
        assert len(arrows) == len(g["poses"])
        for a, pose in zip(arrows, g["poses"], strict=True):
            # The arrow ends at the grasp's TCP, pointing along its approach (tool z).
            w, x, y, z = pose["quat_wxyz"]
            approach = np.array([2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)])
            along = _rotate_x(a.pose.orientation)
            assert along == pytest.approx(approach, abs=1e-9)
            tip = np.array([a.pose.position.x, a.pose.position.y, a.pose.position.z]) + along * (a.shaft_length + a.head_length)
            assert tip == pytest.approx(pose["position"], abs=1e-9)
    red = {t: ents[f"grasps/{t}"].arrows[0].color for t in ("cup:top", "cup:side", "bowl:top", "chips can:side")}
    assert red["cup:top"].r > red["cup:side"].r > red["bowl:top"].r > red["chips can:side"].r  # the more likely, the redder
    assert red["cup:top"].a > red["chips can:side"].a
    # An object's share is its targets' sum, shown on its label.
    cup = ents["object/cup"]
    assert cup.texts[0].text == "cup 0.90" and len(cup.cylinders) == 1
    assert object_probabilities(belief)["cup"] == pytest.approx(0.9)
    assert not up.deletions
    replaced = decode(fx.scene_update(SCENE1, belief, 1, replace=True))
    assert len(replaced.deletions) == 1 and replaced.deletions[0].type == 1  # ALL: the old scene goes


def test_the_gripper_shows_its_axes_and_the_commanded_and_users_velocities():
    up = decode(fx.gripper_update(_state({"cup:top": 1.0}, command=(0.0, 0.2, 0.0), user=(0.0, 0.0, -0.05)), 0))
    (g,) = up.entities
    assert g.id == "gripper" and g.spheres[0].pose.position.z == pytest.approx(0.3)
    axes, command, user = g.arrows[:3], g.arrows[3], g.arrows[4]
    # quat_wxyz (0, 1, 0, 0): half a turn about x, so tool x = base x, tool y = -y, tool z = -z.
    assert [_rotate_x(a.pose.orientation) for a in axes] == [pytest.approx(v, abs=1e-9) for v in
                                                             ([1, 0, 0], [0, -1, 0], [0, 0, -1])]
    assert _rotate_x(command.pose.orientation) == pytest.approx([0, 1, 0], abs=1e-9)
    assert command.shaft_length + command.head_length == pytest.approx(0.2 * fx.TWIST_ARROW_S)
    assert _rotate_x(user.pose.orientation) == pytest.approx([0, 0, -1], abs=1e-9)
    assert user.shaft_length + user.head_length == pytest.approx(0.05 * fx.TWIST_ARROW_S)
    still = decode(fx.gripper_update(_state({"cup:top": 1.0}, command=(0, 0, 0)), 0))
    assert len(still.entities[0].arrows) == 3  # no velocity, no arrow
    assert not decode(fx.gripper_update({"gripper_pose": None}, 0)).entities


def test_belief_and_log_messages():
    b = fx.belief_message(_state({"cup:top": 0.6, "chips can:side": 0.4}))
    assert b["p"] == {"cup_top": 0.6, "chips can_side": 0.4} and b["top"] == "cup:top" and b["top_p"] == 0.6
    assert b["action"] == "move cup:top"
    assert fx.event_log({"t": 1.0, "type": "plan"}, 0) is None
    q = decode(fx.event_log({"t": 1.0, "type": "question", "goal": "cup:top", "text": "Do you want the cup?"}, 7))
    assert q.level == 2 and q.message.startswith("question goal=cup:top") and q.timestamp.nanos == 7  # INFO
    assert decode(fx.event_log({"type": "stop", "source": "button"}, 0)).level == 3  # WARNING
    assert decode(fx.event_log({"type": "fault", "source": "arm", "detail": "C24"}, 0)).level == 4  # ERROR


def test_the_feed_sends_the_bulky_scene_only_when_it_changed_or_is_due():
    clock = [0]
    got: list[tuple[str, object]] = []
    feed = VizFeed(SCENE1, [lambda topic, msg, t: got.append((topic, msg))], scene_period_s=1.0, belief_step=0.01,
                   clock_ns=lambda: clock[0])
    uniform = {g["target"]: 1 / len(SCENE1["goals"]) for g in SCENE1["goals"]}

    def sent(belief):
        got.clear()
        feed.state(_state(belief))
        return [(t, len(decode(m).entities) if t == "/scene" else m) for t, m in got]

    first = sent(uniform)
    assert [t for t, _ in first] == ["/scene", "/scene", "/belief"] and first[0][1] > 1 and first[1][1] == 1
    clock[0] = 500_000_000
    assert [t for t, _ in sent(uniform)] == ["/scene", "/belief"]  # the gripper only
    moved = dict(uniform, **{"cup:top": uniform["cup:top"] + 0.02, "bowl:top": uniform["bowl:top"] - 0.02})
    assert sent(moved)[0][1] > 1  # the belief moved by more than 0.01: redrawn
    clock[0] = 600_000_000
    again = dict(moved, **{"cup:top": moved["cup:top"] + 0.05, "bowl:top": moved["bowl:top"] - 0.05})
    assert [t for t, _ in sent(again)] == ["/scene", "/belief"]  # moved, but 0.1 s after the last drawing
    clock[0] = 800_000_000
    assert sent(again)[0][1] > 1  # 0.2 s after it
    clock[0] = 1_400_000_000
    assert [t for t, _ in sent(again)] == ["/scene", "/belief"]  # unchanged since
    clock[0] = 1_800_000_000
    assert sent(again)[0][1] > 1  # a second after the last drawing: redrawn for late viewers
    feed.new_scene(SCENE1)
    got.clear()
    feed.state(_state(again))
    assert len(decode(got[0][1]).deletions) == 1
    got.clear()
    feed.event({"type": "plan"})
    feed.event({"type": "answer", "goal": "cup:top", "value": "yes"})
    assert [t for t, _ in got] == ["/log"]


# -- a real daemon, a client from the protocol's spec ----------------------------------------------------------


async def _watch(url: str, seconds: float, on_connect=None) -> tuple[dict, dict[str, list]]:
    """Connect like Foxglove: read ``serverInfo`` and ``advertise``, subscribe to every channel, decode
    every message for ``seconds`` s; ``(channels by topic, decoded messages by topic)``."""
    got: dict[str, list] = {}
    async with aiohttp.ClientSession() as http, http.ws_connect(url, protocols=(SUBPROTOCOL,)) as ws:
        assert ws.protocol == SUBPROTOCOL
        info = await ws.receive_json(timeout=10)
        assert info["op"] == "serverInfo" and info["name"] == "sa-daemon"
        channels: dict[str, dict] = {}
        while set(channels) != {"/scene", "/belief", "/log"}:
            msg = await ws.receive_json(timeout=10)
            if msg["op"] == "advertise":
                channels.update({c["topic"]: c for c in msg["channels"]})
        subs, decoders = [], {}
        for i, c in enumerate(channels.values()):
            subs.append({"id": i, "channelId": c["id"]})
            if c["encoding"] == "protobuf":
                cls = decoder(c["schemaName"], base64.b64decode(c["schema"]))
                decoders[i] = (c["topic"], cls.FromString)
            else:
                decoders[i] = (c["topic"], json.loads)
        await ws.send_json({"op": "subscribe", "subscriptions": subs})
        first = await ws.receive(timeout=10)  # the subscription is in force from here on
        if on_connect is not None:
            await on_connect()
        end = asyncio.get_running_loop().time() + seconds
        pending = [first]
        while (left := end - asyncio.get_running_loop().time()) > 0:
            try:
                m = pending.pop() if pending else await ws.receive(timeout=left)
            except TimeoutError:
                break
            if m.type == aiohttp.WSMsgType.BINARY and m.data[0] == MESSAGE_DATA:
                sub, _t_ns = struct.unpack_from("<IQ", m.data, 1)
                topic, dec = decoders[sub]
                got.setdefault(topic, []).append(dec(m.data[13:]))
    return channels, got


@pytest.fixture(scope="module")
def foxglove_daemon(tmp_path_factory):
    """A daemon with the live view on and a recording, its simulated user driving to the cup."""
    d = DaemonProc(tmp_path_factory.mktemp("fox"), "--foxglove", "--foxglove-port", str(free_port()), "--record",
                   "rec.mcap", "--no-speech", "--duration", "600")
    try:
        d.ready = d.wait_ready()
        yield d
    finally:
        d.close()


def test_a_foxglove_client_sees_the_scene_the_gripper_the_belief_and_the_log(foxglove_daemon):
    d = foxglove_daemon
    url = d.ready["foxglove"]
    assert url.startswith("ws://127.0.0.1:")
    status = d.request({"cmd": "status"})
    assert status["foxglove"]["url"] == url

    async def stop_and_resume():
        assert d.request({"cmd": "stop"})["ok"]
        assert d.request({"cmd": "resume"})["ok"]

    channels, got = asyncio.run(_watch(url, 2.5, stop_and_resume))
    assert channels["/scene"]["schemaName"] == "foxglove.SceneUpdate" and channels["/scene"]["encoding"] == "protobuf"
    assert channels["/log"]["schemaName"] == "foxglove.Log"
    assert channels["/belief"]["encoding"] == "json" and channels["/belief"]["schemaName"] == "sa_daemon.Belief"
    ids = {e.id for u in got["/scene"] for e in u.entities}
    assert {"table", "gripper", "object/cup", "object/bowl", "grasps/cup:top", "grasps/cup:side"} <= ids
    grippers = [e for u in got["/scene"] for e in u.entities if e.id == "gripper"]
    assert len(grippers) >= 30  # ~30 Hz for 2.5 s (publish_hz), at least one a state the client saw
    state = d.collector.latest_state()
    assert math.dist([grippers[-1].spheres[0].pose.position.x, grippers[-1].spheres[0].pose.position.y,
                      grippers[-1].spheres[0].pose.position.z], state["gripper_pose"]["position"]) < 0.05
    beliefs = got["/belief"]
    assert len(beliefs) >= 30 and all(sum(b["p"].values()) == pytest.approx(1.0) for b in beliefs)
    assert set(beliefs[-1]["p"]) == {g.replace(":", "_") for g in (b["goal"] for b in state["belief"])}
    logs = [(m.level, m.message) for m in got["/log"]]
    assert (3, "stop source=command") in logs and (2, "resume") in logs


def test_the_recording_carries_the_live_topics_with_the_same_schemas(foxglove_daemon):
    d = foxglove_daemon
    channels, _ = asyncio.run(_watch(d.ready["foxglove"], 0.2))
    d.stop()
    with open(d.dir / "rec.mcap", "rb") as f:
        summary = make_reader(f).get_summary()
    recorded = {c.topic: (c, summary.schemas[c.schema_id]) for c in summary.channels.values()}
    for topic, live in channels.items():
        c, s = recorded[topic]
        assert (c.message_encoding, s.name, s.encoding) == (live["encoding"], live["schemaName"], live["schemaEncoding"])
        data = base64.b64decode(live["schema"]) if live["schemaEncoding"] == "protobuf" else live["schema"].encode()
        assert s.data == data
        assert summary.statistics.channel_message_counts[c.id] > 0
    with open(d.dir / "rec.mcap", "rb") as f:
        for _, ch, msg in make_reader(f).iter_messages(topics=["/scene"]):
            up = decoder(recorded["/scene"][1].name, recorded["/scene"][1].data).FromString(msg.data)
            if any(e.id == "grasps/cup:top" for e in up.entities):
                break
        else:
            raise AssertionError("no scene drawing in the recording")


def test_a_port_in_use_is_a_clear_error_and_nothing_starts(tmp_path):
    port, pub, cmd = free_ports(3)  # distinct: two free_port() calls can return the same released port
    busy = DaemonProc(tmp_path / "a", "--foxglove", "--foxglove-port", str(port), "--no-speech",
                      "--duration", "60")
    try:
        busy.wait_ready()
        r = subprocess.run([*CLI, "run", "--arm", "kinematic", "--input", "sim", "--foxglove", "--foxglove-port",
                            str(port), "--pub", f"tcp://127.0.0.1:{pub}", "--cmd",
                            f"tcp://127.0.0.1:{cmd}", "--no-speech"],
                           capture_output=True, text=True, timeout=120, cwd=tmp_path, check=False)
        assert r.returncode != 0 and f"foxglove.port {port}" in r.stderr, r.stderr[-2000:]
        assert "] ready " not in r.stderr and "] task " not in r.stderr  # (the event lines without --quiet)
    finally:
        busy.close()


def _listening(port: int) -> list[str]:
    """The local addresses (hex, as in /proc/net/tcp and tcp6) of the sockets listening on ``port``."""
    out = []
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        try:
            lines = Path(table).read_text().splitlines()[1:]
        except OSError:
            continue
        for line in lines:
            local, state = line.split()[1], line.split()[3]
            addr, hex_port = local.split(":")
            if state == "0A" and int(hex_port, 16) == port:  # 0A: LISTEN
                out.append(addr)
    return out


@pytest.mark.skipif(sys.platform != "linux", reason="reads the kernel's socket tables in /proc/net")
def test_the_live_view_listens_on_the_loopback_interface_only():
    from sa_daemon.viz.live import LiveView

    view = LiveView(0)
    try:
        assert view.url.startswith("ws://127.0.0.1:")
        assert _listening(view.port) == ["0100007F"]  # 127.0.0.1, little-endian hex; nothing on 0.0.0.0 or ::
    finally:
        view.close()
    assert _listening(view.port) == []
