"""Security of the ZeroMQ sockets (docs/protocol.md section 5): loopback by default, CURVE to expose the
command socket, ``sa-daemon keygen``, and clients that are refused.

Real sockets throughout: in-process :class:`ZmqServer` instances for the socket-level rules, and one
``sa-daemon run`` subprocess bound to ``tcp://0.0.0.0`` with CURVE on for the end-to-end checks (clients
connect to it through 127.0.0.1, which works on machines without a routable address).
"""

from __future__ import annotations

import asyncio
import logging
import signal
import socket
import stat
import subprocess
import sys
import threading
import time
import tomllib
from pathlib import Path
from typing import Any, Self

import pytest
import zmq
import zmq.auth
from helpers import free_port
from zmq.auth.thread import AuthenticationThread

from sa_daemon import cli
from sa_daemon.cli import verbs
from sa_daemon.config import Config, ConfigError, config_from_dict
from sa_daemon.io import keygen
from sa_daemon.io.client import request, subscribe
from sa_daemon.io.security import (
    ClientCurve,
    KeyPair,
    ServerCurve,
    client_curve,
    is_loopback,
    load_keypair,
    load_public,
    server_curve,
)
from sa_daemon.io.server import ZmqServer

CLI = [sys.executable, "-m", "sa_daemon.cli"]
START_TIMEOUT_S = 60.0
REFUSED_WAIT_S = 2.0  # how long a refused client waits for the reply that never comes
# What a client without CURVE is told: "requires CURVE", or, when every attempt within its timeout lost
# the race between the daemon's error and its closing the connection, "does it require CURVE?".
PLAIN_REFUSED = r"(requires|does it require) CURVE.*zmq\.curve_client_secret"


def run_cli(*args: str, timeout_s: float = 60.0) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*CLI, *args], capture_output=True, text=True, timeout=timeout_s, check=False)


def port_is_free(port: int) -> bool:
    """Nothing listens on ``port`` on any address (we can bind the wildcard address to it)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        try:
            s.bind(("0.0.0.0", port))
        except OSError:
            return False
    return True


def snippets(stdout: str) -> dict[str, dict[str, Any]]:
    """The TOML blocks ``keygen`` prints, by their comment line: ``{"daemon": {...}, "NAME": {...}}``."""
    out = {}
    for block in stdout.split("\n\n"):
        if not block.startswith("# ") or "[zmq]" not in block:
            continue
        head = block.splitlines()[0]
        who = "daemon" if "the daemon's" in head else head.split("client ", 1)[1].split(" ", 1)[0]
        out[who] = tomllib.loads(block)
    return out


def auth_threads() -> int:
    return sum(isinstance(t, AuthenticationThread) and t.is_alive() for t in threading.enumerate())


# -- fixtures -------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def keydir(tmp_path_factory) -> tuple[Path, subprocess.CompletedProcess[str]]:
    """``sa-daemon keygen DIR --client operator --clients 1`` run once, as a user would."""
    d = tmp_path_factory.mktemp("keys") / "curve"
    r = run_cli("keygen", str(d), "--client", "operator", "--clients", "1")
    assert r.returncode == 0, r.stderr
    return d, r


@pytest.fixture(scope="module")
def operator(keydir) -> ClientCurve:
    d, _ = keydir
    return ClientCurve(load_keypair(d / "clients" / "operator.key_secret", "t"), load_public(d / "server.key", "t"))


@pytest.fixture(scope="module")
def outsider(keydir) -> ClientCurve:
    """A valid CURVE key pair that was never added to the daemon's allowed clients."""
    d, _ = keydir
    public, secret = zmq.curve_keypair()
    return ClientCurve(KeyPair(public, secret), load_public(d / "server.key", "t"))


@pytest.fixture(scope="module")
def server_keys(keydir) -> ServerCurve:
    d, _ = keydir
    cfg = config_from_dict({"zmq": {"curve_server_secret": str(d / "server.key_secret"),
                                    "curve_clients_dir": str(d / "allowed_clients")}})
    curve = server_curve(cfg.zmq, "tcp://0.0.0.0:5556")
    assert curve is not None
    return curve


class ServerThread:
    """A :class:`ZmqServer` serving in its own thread and event loop; ``ticker`` publishes a state every
    20 ms (so a subscriber that joins late still gets messages). Records the commands it handled."""

    def __init__(self, ticker: bool = False, **kw: Any) -> None:
        self.calls: list[str] = []
        self.error: BaseException | None = None
        self._ready = threading.Event()
        self._ticker = ticker
        self.thread = threading.Thread(target=self._run, args=(kw,), daemon=True, name="test-zmq-server")
        self.thread.start()
        assert self._ready.wait(10), "server thread did not start"
        if self.error is not None:
            raise self.error

    def _handle(self, req: Any) -> dict[str, Any]:
        self.calls.append(req.cmd)
        return {"handled": req.cmd}

    async def _tick(self) -> None:
        n = 0
        while True:
            self.server.publish(b"state", {"n": n})
            n += 1
            await asyncio.sleep(0.02)

    def _run(self, kw: dict[str, Any]) -> None:
        loop = asyncio.new_event_loop()
        try:
            self.server = ZmqServer(**kw)
        except BaseException as e:  # noqa: BLE001 - handed to the constructor's caller
            self.error = e
            self._ready.set()
            loop.close()
            return

        async def main() -> None:
            jobs = [asyncio.ensure_future(self.server.serve(self._handle))]
            if self._ticker:
                jobs.append(asyncio.ensure_future(self._tick()))
            self._jobs = jobs
            self._ready.set()
            await asyncio.gather(*jobs, return_exceptions=True)

        self.loop = loop
        try:
            loop.run_until_complete(main())
        finally:
            self.server.close()
            loop.close()

    @property
    def cmd(self) -> str:
        return self.server.cmd_endpoint.replace("0.0.0.0", "127.0.0.1")

    @property
    def pub(self) -> str:
        return self.server.pub_endpoint.replace("0.0.0.0", "127.0.0.1")

    def close(self) -> None:
        for j in self._jobs:
            self.loop.call_soon_threadsafe(j.cancel)
        self.thread.join(10)
        assert not self.thread.is_alive()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


# -- which endpoints are loopback -----------------------------------------------------------------------


@pytest.mark.parametrize("endpoint", [
    "tcp://127.0.0.1:5556", "tcp://127.1.2.3:5556", "tcp://127.0.0.1:*", "tcp://[::1]:5556",
    "tcp://localhost:5556", "TCP://LOCALHOST:5556", "tcp://[::ffff:127.0.0.1]:5556",
    "ipc:///run/sa-daemon/cmd", "ipc://@abstract", "inproc://cmd",
])
def test_local_endpoints(endpoint):
    assert is_loopback(endpoint)


@pytest.mark.parametrize("endpoint", [
    "tcp://0.0.0.0:5556", "tcp://*:5556", "tcp://[::]:5556", "tcp://192.168.1.10:5556", "tcp://10.0.0.1:5556",
    "tcp://eth0:5556", "tcp://lo:5556", "tcp://robot.local:5556", "tcp://127.0.0.1.example.com:5556",
    "tcp://[::ffff:10.0.0.1]:5556", "ws://127.0.0.1:5556", "pgm://eth0;239.192.1.1:5556", "127.0.0.1:5556",
    "tcp://", "",
])
def test_exposed_endpoints(endpoint):
    assert not is_loopback(endpoint)


# -- keygen ---------------------------------------------------------------------------------------------


def test_keygen_writes_loadable_keys_with_private_secrets(keydir):
    d, _ = keydir
    secrets = [d / "server.key_secret", d / "clients" / "operator.key_secret", d / "clients" / "client1.key_secret"]
    for f in secrets:
        assert stat.S_IMODE(f.stat().st_mode) == 0o600, f
        public, secret = zmq.auth.load_certificate(f)
        assert secret is not None and zmq.curve_public(secret) == public
    assert stat.S_IMODE((d / "clients").stat().st_mode) == 0o700
    # Every client's public key, and nothing else, is in the allowed directory.
    allowed = {p.name: zmq.auth.load_certificate(p) for p in (d / "allowed_clients").iterdir()}
    assert set(allowed) == {"operator.key", "client1.key"}
    for name, (public, secret) in allowed.items():
        assert secret is None
        assert public == zmq.auth.load_certificate(d / "clients" / f"{name}_secret")[0]
    server_public, no_secret = zmq.auth.load_certificate(d / "server.key")
    assert no_secret is None and server_public == zmq.auth.load_certificate(secrets[0])[0]
    assert not list(d.glob(".keygen-*")), "temporary directories left behind"


def test_keygen_prints_the_config_keys_to_set(keydir):
    _, r = keydir
    blocks = snippets(r.stdout)
    assert set(blocks) == {"daemon", "operator", "client1"}
    daemon_cfg = config_from_dict(blocks["daemon"])
    curve = server_curve(daemon_cfg.zmq, "tcp://0.0.0.0:5556")  # now allowed off loopback
    assert curve is not None and len(curve.allowed) == 2
    client = client_curve(config_from_dict(blocks["operator"]).zmq)
    assert client is not None
    assert client.server_public == curve.keys.public
    assert client.keys.public in curve.allowed


def test_keygen_refuses_to_overwrite_a_client_and_keeps_the_server(tmp_path):
    d = tmp_path / "curve"
    assert run_cli("keygen", str(d), "--client", "tablet").returncode == 0
    server_before = (d / "server.key_secret").read_bytes()
    tablet_before = (d / "clients" / "tablet.key_secret").read_bytes()
    again = run_cli("keygen", str(d), "--client", "tablet", "--client", "laptop")
    assert again.returncode == 2
    assert "tablet" in again.stderr and "--force" in again.stderr
    assert not (d / "clients" / "laptop.key_secret").exists(), "a refused request wrote something"
    # Adding a client keeps the server pair, so existing clients keep working.
    add = run_cli("keygen", str(d), "--client", "laptop")
    assert add.returncode == 0, add.stderr
    assert "kept" in add.stdout
    assert (d / "server.key_secret").read_bytes() == server_before
    assert (d / "clients" / "tablet.key_secret").read_bytes() == tablet_before
    forced = run_cli("keygen", str(d), "--client", "tablet", "--force")
    assert forced.returncode == 0, forced.stderr
    assert (d / "clients" / "tablet.key_secret").read_bytes() != tablet_before
    assert (d / "server.key_secret").read_bytes() != server_before


@pytest.mark.parametrize("name", ["../escape", "a/b", ".hidden", "", "x" * 65])
def test_keygen_refuses_bad_client_names(tmp_path, name):
    with pytest.raises(keygen.KeygenError, match="client name"):
        keygen.generate(tmp_path / "curve", [name])
    assert not (tmp_path / "curve").exists()


# -- config errors name the key -------------------------------------------------------------------------


@pytest.mark.parametrize(("zmq_cfg", "key"), [
    ({"curve_server_secret": "/k/server.key_secret"}, "zmq.curve_clients_dir"),
    ({"curve_clients_dir": "/k/allowed_clients"}, "zmq.curve_clients_dir"),
    ({"curve_client_secret": "/k/clients/a.key_secret"}, "zmq.curve_server_public"),
    ({"curve_server_public": "/k/server.key"}, "zmq.curve_server_public"),
    ({"curve_pub": "sometimes"}, "zmq.curve_pub"),
    ({"curve_server_secret": 3, "curve_clients_dir": "/k"}, "zmq.curve_server_secret"),
    ({"curve_secret": "/k/server.key_secret"}, "zmq.curve_secret"),
])
def test_half_configured_curve_is_refused_naming_the_key(zmq_cfg, key):
    with pytest.raises(ConfigError, match=key.replace(".", r"\.")):
        config_from_dict({"zmq": zmq_cfg})


def _zcfg(**zmq_cfg: str) -> Any:
    return config_from_dict({"zmq": zmq_cfg}).zmq


def test_missing_and_wrong_key_files_name_the_key(keydir, tmp_path):
    d, _ = keydir
    allowed = str(d / "allowed_clients")
    with pytest.raises(ConfigError, match=r"zmq\.curve_server_secret: key file .*nope.* does not exist"):
        server_curve(_zcfg(curve_server_secret=str(tmp_path / "nope"), curve_clients_dir=allowed))
    with pytest.raises(ConfigError, match=r"zmq\.curve_server_secret: .* public key only"):
        server_curve(_zcfg(curve_server_secret=str(d / "server.key"), curve_clients_dir=allowed))
    garbled = tmp_path / "garbled.key_secret"
    garbled.write_text('public-key = "short"\nsecret-key = "short"\n')
    with pytest.raises(ConfigError, match=r"zmq\.curve_server_secret: .*40-character"):
        server_curve(_zcfg(curve_server_secret=str(garbled), curve_clients_dir=allowed))
    empty = tmp_path / "empty"
    empty.mkdir()
    secret = str(d / "server.key_secret")
    with pytest.raises(ConfigError, match=r"zmq\.curve_clients_dir: no client public keys"):
        server_curve(_zcfg(curve_server_secret=secret, curve_clients_dir=str(empty)))
    with pytest.raises(ConfigError, match=r"zmq\.curve_clients_dir: .* is not a directory"):
        server_curve(_zcfg(curve_server_secret=secret, curve_clients_dir=str(tmp_path / "absent")))
    with pytest.raises(ConfigError, match=r"zmq\.curve_server_public: key file"):
        client_curve(_zcfg(curve_client_secret=str(d / "clients" / "operator.key_secret"),
                           curve_server_public=str(tmp_path / "absent.key")))


def test_client_verbs_exit_2_naming_a_missing_client_key(tmp_path, capsys):
    cfg = tmp_path / "client.toml"
    cfg.write_text(f'[zmq]\ncurve_client_secret = "{tmp_path}/gone.key_secret"\n'
                   f'curve_server_public = "{tmp_path}/server.key"\n')
    assert cli.main(["--config", str(cfg), "answer", "yes", "--timeout", "0.2"]) == 2
    assert "zmq.curve_client_secret" in capsys.readouterr().err
    assert cli.main(["--config", str(cfg), "monitor", "--once"]) == 2
    assert "zmq.curve_client_secret" in capsys.readouterr().err


def test_build_daemon_refuses_an_exposed_cmd_before_anything_exists(tmp_path):
    """The --cmd flag overrides zmq.cmd, and the effective endpoint is the one checked."""
    args = cli.build_parser().parse_args(
        ["run", "--arm", "kinematic", "--scene", "scene1", "--cmd", "tcp://0.0.0.0:5556", "--no-speech"])
    with pytest.raises(ConfigError, match=r"zmq\.cmd: tcp://0\.0\.0\.0:5556 is not a loopback endpoint"):
        verbs.build_daemon(args)


def test_loopback_default_needs_no_keys():
    assert server_curve(Config().zmq) is None
    assert client_curve(Config().zmq) is None


# -- the sockets ----------------------------------------------------------------------------------------


def test_server_refuses_an_exposed_cmd_without_curve():
    port = free_port()
    with pytest.raises(ConfigError, match=r"zmq\.cmd") as e:
        ZmqServer("tcp://127.0.0.1:*", f"tcp://0.0.0.0:{port}")
    assert "keygen" in str(e.value) and "curve_server_secret" in str(e.value)
    assert port_is_free(port)


@pytest.mark.parametrize("cmd", ["tcp://127.0.0.1:*", "ipc://{tmp}/cmd.sock"])
def test_loopback_server_works_without_keys(cmd, tmp_path):
    with ServerThread(pub="tcp://127.0.0.1:*", cmd=cmd.format(tmp=tmp_path)) as srv:
        assert srv.server.auth is None
        assert request(srv.cmd, {"cmd": "status"}, timeout_s=5)["ok"] is True
    assert srv.calls == ["status"]


def test_curve_client_against_a_plain_server_is_told_why(operator):
    """The mechanism mismatch says so; when the server closed every attempt before its greeting was read
    (seen under load) the reason still names a daemon socket without CURVE among its two causes."""
    with (ServerThread(pub="tcp://127.0.0.1:*", cmd="tcp://127.0.0.1:*") as srv,
          pytest.raises(TimeoutError, match=r"daemon's socket (does not|use CURVE)")):
        request(srv.cmd, {"cmd": "status"}, timeout_s=REFUSED_WAIT_S, curve=operator)
    assert srv.calls == []


def test_exposed_pub_never_takes_commands(caplog):
    """A PUB socket bound to every address without CURVE is allowed (read-only), logged, and nothing a
    peer sends to it reaches the command handler."""
    with caplog.at_level(logging.WARNING, logger="sa_daemon.io.server"):
        srv = ServerThread(pub="tcp://0.0.0.0:*", cmd="tcp://127.0.0.1:*")
    with srv:
        assert any("zmq.pub" in r.getMessage() and "read" in r.getMessage() for r in caplog.records)
        ctx = zmq.Context.instance()
        peers = []
        for kind in (zmq.REQ, zmq.DEALER, zmq.PUB, zmq.XSUB):
            s = ctx.socket(kind)
            s.setsockopt(zmq.LINGER, 0)
            s.connect(srv.pub)
            peers.append(s)
        time.sleep(0.3)
        for s in peers:
            try:
                if s.type == zmq.DEALER:
                    s.send_multipart([b"", b'{"cmd": "stop"}'], zmq.NOBLOCK)
                else:
                    s.send(b'{"cmd": "stop"}', zmq.NOBLOCK)
            except zmq.Again:
                pass  # no compatible peer: the message cannot even be queued
        raw = socket.create_connection(("127.0.0.1", int(srv.pub.rsplit(":", 1)[1])), timeout=2)
        raw.sendall(b'{"cmd": "stop"}\n' * 10)
        time.sleep(0.5)
        raw.close()
        for s in peers:
            s.close()
        assert request(srv.cmd, {"cmd": "status"}, timeout_s=5)["ok"] is True  # still serving
    assert srv.calls == ["status"], "something sent to the PUB socket reached the command handler"


def test_curve_server_admits_only_allowed_keys(server_keys, operator, outsider):
    with ServerThread(ticker=True, pub="tcp://0.0.0.0:*", cmd="tcp://0.0.0.0:*", curve=server_keys) as srv:
        assert request(srv.cmd, {"cmd": "status"}, timeout_s=5, curve=operator) == {"ok": True, "handled": "status"}
        with pytest.raises(TimeoutError, match=PLAIN_REFUSED):
            request(srv.cmd, {"cmd": "stop"}, timeout_s=REFUSED_WAIT_S)
        with pytest.raises(TimeoutError, match="refused this client's CURVE key"):
            request(srv.cmd, {"cmd": "stop"}, timeout_s=REFUSED_WAIT_S, curve=outsider)
        assert srv.server.allow is not None and srv.server.allow.refused >= 1
        # The PUB stream is CURVE-protected too (zmq.curve_pub defaults to true).
        topic, msg = next(subscribe(srv.pub, timeout_s=5, curve=operator))
        assert topic == "state" and "n" in msg
        with pytest.raises(TimeoutError, match=PLAIN_REFUSED):
            next(subscribe(srv.pub, timeout_s=REFUSED_WAIT_S))
        with pytest.raises(TimeoutError, match="refused"):
            next(subscribe(srv.pub, timeout_s=REFUSED_WAIT_S, curve=outsider))
        assert request(srv.cmd, {"cmd": "status"}, timeout_s=5, curve=operator)["ok"] is True
    assert srv.calls == ["status", "status"], "a refused client's command was handled"


def test_curve_pub_off_leaves_the_stream_readable_but_commands_authenticated(server_keys, operator):
    open_pub = ServerCurve(server_keys.keys, server_keys.allowed, pub=False)
    with ServerThread(ticker=True, pub="tcp://127.0.0.1:*", cmd="tcp://0.0.0.0:*", curve=open_pub) as srv:
        topic, _ = next(subscribe(srv.pub, timeout_s=5))
        assert topic == "state"
        with pytest.raises(TimeoutError):
            request(srv.cmd, {"cmd": "stop"}, timeout_s=REFUSED_WAIT_S)
        assert request(srv.cmd, {"cmd": "status"}, timeout_s=5, curve=operator)["ok"] is True
    assert srv.calls == ["status"]


def test_authenticator_lives_and_dies_with_the_server(server_keys):
    before = auth_threads()
    srv = ServerThread(pub="tcp://127.0.0.1:*", cmd="tcp://127.0.0.1:*", curve=server_keys)
    auth = srv.server.auth
    assert auth is not None and auth.is_alive()
    assert auth_threads() == before + 1
    srv.close()
    assert not auth.is_alive() and srv.server.auth is None
    assert auth_threads() == before
    # A failed bind stops the authenticator it started.
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        with pytest.raises(OSError, match="cannot bind"):
            ZmqServer("tcp://127.0.0.1:*", f"tcp://127.0.0.1:{port}", curve=server_keys)
    assert auth_threads() == before


# -- the daemon -----------------------------------------------------------------------------------------


def _run_args(pub: str, cmd: str, *extra: str) -> list[str]:
    return ["run", "--arm", "kinematic", "--input", "sim", "--scene", "scene1", "--task", "cup:top", "--method",
            "manual", "--pub", pub, "--cmd", cmd, "--quiet", "--no-speech", "--duration", "600", *extra]


@pytest.mark.parametrize("via", ["flag", "config"])
def test_daemon_refuses_to_expose_cmd_without_curve(tmp_path, via):
    pub_port, cmd_port = free_port(), free_port()
    record = tmp_path / "session.mcap"
    cmd = f"tcp://0.0.0.0:{cmd_port}" if via == "flag" else f"tcp://*:{cmd_port}"
    args = _run_args(f"tcp://127.0.0.1:{pub_port}", cmd, "--record", str(record))
    if via == "config":
        cfg = tmp_path / "config.toml"
        cfg.write_text(f'[zmq]\ncmd = "{cmd}"\n')
        args = ["--config", str(cfg), *[a for a in args if a not in ("--cmd", cmd)]]
    t0 = time.monotonic()
    r = run_cli(*args)
    assert r.returncode == 2, r.stderr
    assert f"zmq.cmd: {cmd} is not a loopback endpoint" in r.stderr
    assert "sa-daemon keygen" in r.stderr and "Traceback" not in r.stderr
    assert time.monotonic() - t0 < 30
    assert not record.exists(), "the daemon got as far as recording"
    assert port_is_free(cmd_port) and port_is_free(pub_port)


class SecuredDaemon:
    """``sa-daemon run`` with CURVE on, cmd and pub bound to every address."""

    def __init__(self, workdir: Path, keys: Path) -> None:
        self.pub_port, self.cmd_port = free_port(), free_port()
        self.pub = f"tcp://127.0.0.1:{self.pub_port}"
        self.cmd = f"tcp://127.0.0.1:{self.cmd_port}"
        cfg = workdir / "daemon.toml"
        cfg.write_text(f'[zmq]\ncurve_server_secret = "{keys / "server.key_secret"}"\n'
                       f'curve_clients_dir = "{keys / "allowed_clients"}"\n')
        self.stderr_path = workdir / "stderr.txt"
        self.stderr = open(self.stderr_path, "wb")  # noqa: SIM115
        self.proc = subprocess.Popen(
            [*CLI, "--config", str(cfg),
             *_run_args(f"tcp://0.0.0.0:{self.pub_port}", f"tcp://0.0.0.0:{self.cmd_port}")],
            cwd=workdir, stdout=subprocess.DEVNULL, stderr=self.stderr)

    @property
    def log(self) -> str:
        if not self.stderr.closed:
            self.stderr.flush()
        return self.stderr_path.read_text(errors="replace")

    def wait_ready(self, curve: ClientCurve) -> dict[str, Any]:
        deadline = time.monotonic() + START_TIMEOUT_S
        while time.monotonic() < deadline:
            assert self.proc.poll() is None, f"daemon exited {self.proc.returncode}: {self.log[-3000:]}"
            try:
                return request(self.cmd, {"cmd": "status"}, timeout_s=1.0, curve=curve)
            except TimeoutError:
                pass
        raise AssertionError(f"secured daemon not ready: {self.log[-3000:]}")

    def stop(self) -> int:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
        try:
            return self.proc.wait(30)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            return self.proc.wait()
        finally:
            if not self.stderr.closed:
                self.stderr.close()


@pytest.fixture(scope="module")
def secured(tmp_path_factory, keydir, operator):
    d = SecuredDaemon(tmp_path_factory.mktemp("secured"), keydir[0])
    try:
        d.wait_ready(operator)
        yield d
    finally:
        d.stop()


def test_allowed_client_gets_status(secured, operator):
    reply = request(secured.cmd, {"cmd": "status"}, timeout_s=5, curve=operator)
    assert reply["ok"] is True and reply["pid"] == secured.proc.pid


def test_client_without_curve_gets_no_reply(secured, operator):
    with pytest.raises(TimeoutError, match=PLAIN_REFUSED):
        request(secured.cmd, {"cmd": "stop"}, timeout_s=REFUSED_WAIT_S)
    reply = request(secured.cmd, {"cmd": "status"}, timeout_s=5, curve=operator)
    assert reply["ok"] is True and reply["stopped"] is False, "the refused stop was obeyed"


def test_client_with_unlisted_key_gets_no_reply_and_is_logged(secured, operator, outsider):
    with pytest.raises(TimeoutError, match="refused this client's CURVE key"):
        request(secured.cmd, {"cmd": "stop"}, timeout_s=REFUSED_WAIT_S, curve=outsider)
    reply = request(secured.cmd, {"cmd": "status"}, timeout_s=5, curve=operator)
    assert reply["ok"] is True and reply["stopped"] is False, "the refused stop was obeyed"
    deadline = time.monotonic() + 10
    while outsider.keys.public.decode() not in secured.log:
        assert time.monotonic() < deadline, f"refusal not logged: {secured.log[-2000:]}"
        time.sleep(0.1)


def test_client_with_wrong_server_key_gets_no_reply(secured, operator):
    wrong = ClientCurve(operator.keys, zmq.curve_keypair()[0])
    with pytest.raises(TimeoutError, match="curve_server_public"):
        request(secured.cmd, {"cmd": "status"}, timeout_s=REFUSED_WAIT_S, curve=wrong)


def test_state_stream_needs_an_allowed_key(secured, operator, outsider):
    topic, _ = next(subscribe(secured.pub, timeout_s=10, curve=operator))
    assert topic in ("state", "event")
    for curve in (None, outsider):
        with pytest.raises(TimeoutError):
            next(subscribe(secured.pub, timeout_s=REFUSED_WAIT_S, curve=curve))


def test_cli_verbs_use_the_client_keys(secured, keydir, tmp_path):
    _, r = keydir
    client_cfg = tmp_path / "client.toml"  # the block keygen printed for this client, as printed
    client_cfg.write_text(next(b for b in r.stdout.split("\n\n") if b.startswith("# config.toml of client operator")))
    answer = run_cli("--config", str(client_cfg), "answer", "yes", "--cmd", secured.cmd, "--timeout", "5")
    assert answer.returncode == 1, answer.stderr  # authenticated: the daemon itself refuses (no question)
    assert "no question is pending" in answer.stdout
    mon = run_cli("--config", str(client_cfg), "monitor", "--pub", secured.pub, "--once")
    assert mon.returncode == 0, mon.stderr
    assert "belief:" in mon.stdout
    plain = run_cli("answer", "yes", "--cmd", secured.cmd, "--timeout", "1")
    assert plain.returncode == 2
    assert "CURVE" in plain.stderr and "zmq.curve_client_secret" in plain.stderr


def test_secured_daemon_stops_cleanly(secured):
    assert secured.stop() == 0, secured.log[-3000:]
    assert "Traceback" not in secured.log

