"""systemd's notify protocol (``sd_notify``): one datagram per state change to ``$NOTIFY_SOCKET``.

Written here rather than taken from a package: it is one ``sendto`` on an ``AF_UNIX`` datagram socket
(the ``sdnotify``/``systemd-python`` packages add a dependency - the latter a C build - for the same
call). ``READY=1`` once arm, input and planner are up, ``WATCHDOG=1`` from the control loop while it is
healthy, ``STOPPING=1`` on shutdown, ``STATUS=...`` for ``systemctl status``.
"""

from __future__ import annotations

import os
import socket


class Notifier:
    """Send notify messages when run by systemd (``$NOTIFY_SOCKET`` set); otherwise do nothing."""

    def __init__(self, env: dict[str, str] | None = None) -> None:
        env = dict(os.environ if env is None else env)
        addr = env.get("NOTIFY_SOCKET", "")
        if addr.startswith("@"):
            addr = "\0" + addr[1:]  # abstract namespace
        self._addr = addr or None
        self._sock: socket.socket | None = None
        if self._addr:
            self._sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM | socket.SOCK_CLOEXEC)
            self._sock.setblocking(False)
        usec = env.get("WATCHDOG_USEC", "")
        pid = env.get("WATCHDOG_PID", "")
        mine = not pid or pid == str(os.getpid())
        #: Interval (s) at which to send ``WATCHDOG=1``: half of ``$WATCHDOG_USEC``; ``None`` = no watchdog.
        self.watchdog_interval_s = int(usec) / 2e6 if usec.isdigit() and int(usec) > 0 and mine else None
        self.sent: int = 0

    @property
    def enabled(self) -> bool:
        return self._sock is not None

    def notify(self, *fields: str) -> bool:
        """Send ``fields`` (e.g. ``"READY=1"``) as one datagram; ``False`` if not sent."""
        if self._sock is None or self._addr is None:
            return False
        try:
            self._sock.sendto("\n".join(fields).encode(), self._addr)
        except OSError:
            return False
        self.sent += 1
        return True

    def close(self) -> None:
        if self._sock is not None:
            self._sock.close()
            self._sock = None
