"""``sa-daemon keygen``: the CURVE key files of the daemon and its clients.

Layout of ``DIR`` (every file in ``zmq.auth.create_certificates`` format)::

    server.key                  daemon's public key      -> clients' zmq.curve_server_public
    server.key_secret    0600   daemon's key pair        -> daemon's zmq.curve_server_secret
    allowed_clients/NAME.key    a client's public key    -> daemon's zmq.curve_clients_dir (the directory)
    clients/NAME.key_secret 0600 a client's key pair     -> that client's zmq.curve_client_secret

Each pair is written in a private (0700) temporary directory inside ``DIR``, its secret file set to
0600, then renamed into place, so a secret is never readable by another user, not even briefly.
An existing server pair is kept (clients can be added later); an existing client is refused unless
``force`` (which also replaces the server pair, invalidating every client's ``curve_server_public``).
"""

from __future__ import annotations

import os
import re
import shutil
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import zmq.auth

SERVER = "server"
ALLOWED_DIR = "allowed_clients"
CLIENTS_DIR = "clients"
NAME_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,63}$")
SECRET_MODE = 0o600
PUBLIC_MODE = 0o644


class KeygenError(ValueError):
    """A refused ``keygen`` request (bad name, existing key, unwritable directory)."""


@dataclass
class KeygenResult:
    """What :func:`generate` wrote (absolute paths)."""

    directory: Path
    server_public: Path
    server_secret: Path
    server_created: bool
    allowed_dir: Path
    clients: dict[str, Path] = field(default_factory=dict)  # name -> its .key_secret file


def _write_pair(directory: Path, name: str, secret_dest: Path, public_dest: Path) -> None:
    """Create one key pair and move its files to ``secret_dest`` (0600) and ``public_dest`` (0644)."""
    tmp = Path(tempfile.mkdtemp(prefix=".keygen-", dir=directory))  # 0700: nobody else can look in
    try:
        public, secret = zmq.auth.create_certificates(tmp, name)
        os.chmod(secret, SECRET_MODE)
        os.chmod(public, PUBLIC_MODE)
        os.replace(secret, secret_dest)
        os.replace(public, public_dest)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def generate(directory: str | Path, clients: list[str], force: bool = False) -> KeygenResult:
    """Write the server pair (unless present) and one pair per name in ``clients`` under ``directory``.

    Everything is checked before the first file is written, so a refused request changes nothing.
    """
    d = Path(directory).expanduser().resolve()
    if len(set(clients)) != len(clients):
        raise KeygenError("a client name is given twice")
    for name in clients:
        if not NAME_RE.match(name):
            raise KeygenError(f"client name {name!r}: use 1-64 letters, digits, '_', '-' or '.', not starting with '.'")
    res = KeygenResult(d, d / f"{SERVER}.key", d / f"{SERVER}.key_secret", False, d / ALLOWED_DIR)
    server_parts = [p.exists() for p in (res.server_public, res.server_secret)]
    if any(server_parts) and not all(server_parts) and not force:
        raise KeygenError(f"{d} holds only half of the server key pair: remove it or use --force")
    for name in clients:
        secret = d / CLIENTS_DIR / f"{name}.key_secret"
        if (secret.exists() or (res.allowed_dir / f"{name}.key").exists()) and not force:
            raise KeygenError(f"client {name!r} already has keys in {d} (use --force to replace them)")
        res.clients[name] = secret
    try:
        d.mkdir(parents=True, exist_ok=True)
        res.allowed_dir.mkdir(exist_ok=True)
        (d / CLIENTS_DIR).mkdir(mode=0o700, exist_ok=True)
        os.chmod(d / CLIENTS_DIR, 0o700)  # holds secrets only
        if force or not all(server_parts):
            _write_pair(d, SERVER, res.server_secret, res.server_public)
            res.server_created = True
        for name, secret in res.clients.items():
            _write_pair(d, name, secret, res.allowed_dir / f"{name}.key")
    except OSError as e:
        raise KeygenError(f"cannot write keys in {d}: {e}") from None
    return res


WEB_TOKEN = "web.token"


def write_web_token(directory: str | Path, force: bool = False) -> tuple[Path, bool]:
    """``DIR/web.token`` (0600): a random access token for ``sa-daemon web`` (``web.token_file``), 256
    bits from :mod:`secrets`. An existing token is kept unless ``force``. Returns (path, written)."""
    import secrets

    d = Path(directory)
    try:
        d.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise KeygenError(f"cannot create {d}: {e}") from None
    path = d / WEB_TOKEN
    if path.exists() and not force:
        return path.resolve(), False
    tmp = Path(tempfile.mkdtemp(prefix=".keygen-", dir=d))  # 0700: nobody else can look in
    try:
        f = tmp / WEB_TOKEN
        fd = os.open(f, os.O_WRONLY | os.O_CREAT | os.O_EXCL, SECRET_MODE)
        with os.fdopen(fd, "w") as out:
            out.write(secrets.token_urlsafe(32) + "\n")
        os.replace(f, path)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return path.resolve(), True
