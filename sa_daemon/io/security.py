"""Who may talk to the daemon: loopback endpoints, CURVE keys and the ZAP authenticator.

The command socket moves the arm, so it binds to loopback unless CURVE authentication is configured:
then every peer must prove it holds a secret key whose public half is in ``zmq.curve_clients_dir``
(checked by a ZAP handler, pyzmq's thread authenticator), and the traffic is encrypted. The PUB socket
is read-only (ZeroMQ never delivers anything a subscriber sends to a PUB socket), so it may be exposed
without CURVE; with CURVE on it is protected too unless ``zmq.curve_pub`` is false.

Keys are the Z85 text files that ``sa-daemon keygen`` writes (``zmq.auth.create_certificates``
format): ``NAME.key`` holds a public key, ``NAME.key_secret`` both halves. Every error is a
:class:`~sa_daemon.config.ConfigError` naming the config key it comes from.
"""

from __future__ import annotations

import ipaddress
import logging
import stat
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import zmq
import zmq.auth
from zmq.auth.thread import ThreadAuthenticator
from zmq.utils import z85

from ..config import ConfigError

if TYPE_CHECKING:
    from ..config import ZmqConfig

log = logging.getLogger(__name__)

#: Transports that never leave the machine.
LOCAL_TRANSPORTS = ("ipc", "inproc")
Z85_KEY_CHARS = 40  # a 32-byte Curve25519 key in Z85 text
_MAX_WARNED_KEYS = 64  # refused keys logged once each, up to this many (a flood cannot fill the log)


def is_loopback(endpoint: str) -> bool:
    """``endpoint`` can only be reached from this machine.

    ``ipc://`` and ``inproc://`` are local; ``tcp://`` is local when its host is ``localhost`` or a
    loopback address (``127.0.0.0/8``, ``[::1]``, ``[::ffff:127.x.y.z]``). ``tcp://*``,
    ``tcp://0.0.0.0``, interface names and every other address or transport are not.
    """
    transport, sep, address = endpoint.partition("://")
    if not sep:
        return False
    transport = transport.lower()
    if transport in LOCAL_TRANSPORTS:
        return True
    if transport != "tcp" or ";" in address:
        return False
    host = address.rpartition(":")[0]
    if host.startswith("[") and host.endswith("]"):
        host = host[1:-1]
    if host.lower() == "localhost":
        return True
    try:
        ip = ipaddress.ip_address(host)
    except ValueError:
        return False  # an interface name, a host name or "*"
    if isinstance(ip, ipaddress.IPv6Address) and ip.ipv4_mapped is not None:
        ip = ip.ipv4_mapped
    return ip.is_loopback


@dataclass(frozen=True)
class KeyPair:
    """A Curve25519 key pair, both halves as 40-character Z85 bytes."""

    public: bytes
    secret: bytes


@dataclass(frozen=True)
class ServerCurve:
    """The daemon's CURVE settings: its key pair and the client public keys (Z85) it accepts."""

    keys: KeyPair
    allowed: frozenset[bytes]
    pub: bool = True  # the PUB socket is a CURVE server too


@dataclass(frozen=True)
class ClientCurve:
    """A client's CURVE settings: its own key pair and the daemon's public key (Z85)."""

    keys: KeyPair
    server_public: bytes


def _need_curve(key: str) -> None:
    if not zmq.has("curve"):
        raise ConfigError(f"zmq.{key}: this libzmq ({zmq.zmq_version()}) was built without CURVE support")


def _check_key(text: bytes, path: Path, key: str, what: str) -> bytes:
    if len(text) != Z85_KEY_CHARS:
        raise ConfigError(f"zmq.{key}: {path}: the {what} key is not a {Z85_KEY_CHARS}-character Z85 key")
    try:
        z85.decode(text)
    except (ValueError, KeyError, IndexError):
        raise ConfigError(f"zmq.{key}: {path}: the {what} key is not valid Z85 text") from None
    return text


def _read_certificate(path: Path, key: str) -> tuple[bytes, bytes | None]:
    if not path.is_file():
        raise ConfigError(f"zmq.{key}: key file {path} does not exist (make keys with: sa-daemon keygen DIR)")
    try:
        return zmq.auth.load_certificate(path)
    except (OSError, ValueError) as e:
        raise ConfigError(f"zmq.{key}: cannot read key file {path}: {e}") from None


def load_keypair(path: str | Path, key: str) -> KeyPair:
    """The key pair in a ``.key_secret`` file; ``key`` is the config key that named the file."""
    p = Path(path).expanduser()
    public, secret = _read_certificate(p, key)
    if secret is None:
        raise ConfigError(
            f"zmq.{key}: {p} holds a public key only: give the .key_secret file written by sa-daemon keygen"
        )
    pair = KeyPair(_check_key(public, p, key, "public"), _check_key(secret, p, key, "secret"))
    if zmq.curve_public(pair.secret) != pair.public:
        raise ConfigError(f"zmq.{key}: {p}: the public key is not the secret key's public half")
    if p.stat().st_mode & (stat.S_IRWXG | stat.S_IRWXO):
        log.warning("zmq.%s: %s can be read by other users (chmod 600 it)", key, p)
    return pair


def load_public(path: str | Path, key: str) -> bytes:
    """The public key in a ``.key`` (or ``.key_secret``) file, as Z85 bytes."""
    p = Path(path).expanduser()
    public, _ = _read_certificate(p, key)
    return _check_key(public, p, key, "public")


def load_allowed(directory: str | Path, key: str) -> frozenset[bytes]:
    """The public keys of every ``*.key`` file in ``directory``; at least one (else nobody could connect)."""
    d = Path(directory).expanduser()
    if not d.is_dir():
        raise ConfigError(f"zmq.{key}: {d} is not a directory of client public keys (*.key)")
    try:
        files = sorted(d.glob("*.key"))
    except OSError as e:
        raise ConfigError(f"zmq.{key}: cannot list {d}: {e}") from None
    allowed = frozenset(load_public(f, key) for f in files)
    if not allowed:
        raise ConfigError(
            f"zmq.{key}: no client public keys (*.key) in {d}, so no client could connect "
            "(add one with: sa-daemon keygen DIR --client NAME)"
        )
    return allowed


def exposure_error(cmd: str, curve: ServerCurve | None) -> ConfigError | None:
    """The error for a command endpoint reachable from other machines without CURVE (``None``: fine)."""
    if curve is not None or is_loopback(cmd):
        return None
    return ConfigError(
        f"zmq.cmd: {cmd} is not a loopback endpoint, and the command socket is only exposed with CURVE "
        "authentication: make keys with `sa-daemon keygen DIR` and set zmq.curve_server_secret and "
        "zmq.curve_clients_dir, or bind zmq.cmd (--cmd) to tcp://127.0.0.1:PORT"
    )


def server_curve(zcfg: ZmqConfig, cmd: str | None = None) -> ServerCurve | None:
    """The daemon's CURVE settings from ``zcfg`` (``None``: CURVE off), its keys loaded and checked.

    ``cmd`` is the effective command endpoint (``--cmd`` over ``zmq.cmd``); a non-loopback one
    without CURVE is refused here, before anything starts.
    """
    if not zcfg.curve_server_secret:
        err = exposure_error(cmd or zcfg.cmd, None)
        if err is not None:
            raise err
        return None
    _need_curve("curve_server_secret")
    keys = load_keypair(zcfg.curve_server_secret, "curve_server_secret")
    allowed = load_allowed(zcfg.curve_clients_dir, "curve_clients_dir")
    return ServerCurve(keys, allowed, pub=zcfg.curve_pub)


def client_curve(zcfg: ZmqConfig) -> ClientCurve | None:
    """The CURVE settings of ``answer``/``monitor`` from ``zcfg`` (``None``: plain connection)."""
    if not zcfg.curve_client_secret:
        return None
    _need_curve("curve_client_secret")
    keys = load_keypair(zcfg.curve_client_secret, "curve_client_secret")
    return ClientCurve(keys, load_public(zcfg.curve_server_public, "curve_server_public"))


def apply_server(sock: zmq.Socket, keys: KeyPair) -> None:
    """Make ``sock`` a CURVE server (call before ``bind``)."""
    sock.setsockopt(zmq.CURVE_SECRETKEY, keys.secret)
    sock.setsockopt(zmq.CURVE_PUBLICKEY, keys.public)
    sock.setsockopt(zmq.CURVE_SERVER, 1)


def apply_client(sock: zmq.Socket, curve: ClientCurve) -> None:
    """Make ``sock`` a CURVE client of the daemon (call before ``connect``)."""
    sock.setsockopt(zmq.CURVE_SERVERKEY, curve.server_public)
    sock.setsockopt(zmq.CURVE_PUBLICKEY, curve.keys.public)
    sock.setsockopt(zmq.CURVE_SECRETKEY, curve.keys.secret)


class AllowList:
    """ZAP credentials provider: accept exactly the configured client public keys.

    Called from the authenticator's thread for every CURVE handshake. Counts refusals and logs each
    refused key once (a client retrying every 100 ms cannot flood the log).
    """

    def __init__(self, allowed: frozenset[bytes]) -> None:
        self.allowed = allowed
        self.refused = 0
        self._warned: set[bytes] = set()
        self._lock = threading.Lock()

    def callback(self, domain: str, key: bytes) -> bool:
        if key in self.allowed:
            return True
        with self._lock:
            self.refused += 1
            first = key not in self._warned and len(self._warned) < _MAX_WARNED_KEYS
            if first:
                self._warned.add(key)
        if first:
            log.warning("refused a CURVE client whose key is not in zmq.curve_clients_dir: %s", key.decode())
        return False


def start_authenticator(ctx: zmq.Context, allowed: AllowList) -> ThreadAuthenticator:
    """Start the ZAP handler of ``ctx`` allowing only ``allowed``; bind CURVE sockets after this.

    Without a ZAP handler libzmq lets any CURVE client in, so the caller must keep it running for as
    long as its sockets are bound, and ``stop()`` it before terminating the context.
    """
    auth = ThreadAuthenticator(ctx, log=logging.getLogger(__name__ + ".zap"))
    auth.start()
    auth.configure_curve_callback("*", allowed)
    return auth
