"""A load beside the daemon in a spawned process (its work is not the daemon's process's work): the
subscribers of :mod:`.subscribers`, the Foxglove viewer of :mod:`.viewer`."""

from __future__ import annotations

import multiprocessing as mp
from collections.abc import Callable
from typing import Any


class LoadProcess:
    """Runs ``target(*args, ready, stop, out)`` in a spawned process: the target sets ``ready`` once it is
    connected, works until ``stop`` is set, then sends its figures (a dict) on ``out``.
    :meth:`start` waits for ``ready``; :meth:`stop` returns the figures."""

    def __init__(self, target: Callable[..., None], args: tuple, name: str) -> None:
        ctx = mp.get_context("spawn")
        self._ready, self._stop = ctx.Event(), ctx.Event()
        self._recv, self._send = ctx.Pipe(duplex=False)
        self._proc = ctx.Process(target=target, args=(*args, self._ready, self._stop, self._send), name=name,
                                 daemon=True)

    def start(self, timeout_s: float = 30.0) -> None:
        """Spawn the process and wait (up to ``timeout_s``) until it is ready."""
        self._proc.start()
        self._send.close()  # the child's copy is the only writer now: its death reads as EOF
        if not self._ready.wait(timeout_s):
            self._proc.kill()
            raise TimeoutError(f"{self._proc.name} not ready within {timeout_s} s")

    def stop(self, timeout_s: float = 30.0) -> dict[str, Any]:
        """Stop the load and return its figures (``{"error": ...}`` if the process died or did not answer
        within ``timeout_s``)."""
        self._stop.set()
        figs: dict[str, Any] | None = None
        try:
            if self._recv.poll(timeout_s):
                figs = self._recv.recv()
        except EOFError:
            pass
        self._proc.join(5.0)
        if self._proc.is_alive():
            self._proc.kill()
            self._proc.join()
        return figs if figs is not None else {"error": f"{self._proc.name} gave no figures (exit {self._proc.exitcode})"}
