"""Map a function over work items on a Ray cluster: the ``ray`` backend of ``sa-daemon eval``.

:func:`ray_map` is the Ray counterpart of ``run_trials``' spawn pool: results in the order of the items,
a callback per finished item (the progress bar), a remote exception raised as its own type naming the
item. Ray comes from the ``ray`` extra (``pip install 'sa-daemon[ray]'``) and is imported only here, on
first use.

Which cluster:

* ``address=None``: a new local cluster just for this call (``ray.init(address="local")``; an already
  running ``ray start`` cluster or ``RAY_ADDRESS`` is *not* picked up, pass ``address="auto"`` for that),
  started quietly (no dashboard, workers' output not echoed, Ray's usage statistics off) and shut down,
  processes and all, before :func:`ray_map` returns or raises.
* ``address="auto"``, ``"host:6379"`` (a cluster's GCS) or ``"ray://host:10001"`` (Ray Client, which
  needs ``ray[client]`` on the driver): connect to that cluster, and on return only disconnect; the
  cluster keeps running.
* Ray already initialised in this process (``ray.is_initialized()``, e.g. a test fixture or a caller
  that ran ``ray.init`` with its own options): that connection is used as it is (``address`` is
  ignored) and left open.

What the workers need: each task unpickles ``fn`` and its item in a Ray worker process, so the modules
they live in must import there. On the local cluster the workers run this venv's interpreter, where
sa_daemon is installed. A remote cluster needs, on every node, the driver's Python minor version and
Ray version, and sa_daemon installed in the same version as the driver (with its dependencies:
pinocchio, mujoco, ...) - otherwise tasks fail with "No module named ..." or, worse, compute with other
code. ``ray_map`` passes no ``runtime_env``: Ray's ``py_modules`` could ship the driver's sa_daemon
source, but not its compiled dependencies, so it does not replace the install (to use one anyway,
``ray.init(address, runtime_env=...)`` first; ``ray_map`` then reuses that connection). Paths inside
items (``run_trials``' ``plots``) are written on whichever node runs the task.

Exposure: even a local cluster's services listen on every interface while a sweep runs (measured with
Ray 2.60: GCS and raylet on ``*``; ``_node_ip_address="127.0.0.1"`` does not change that). Ray 2.60
enables token authentication by default (``~/.ray/auth_token``); older Ray allowed by ``ray>=2.9`` does
not. On a machine that must expose nothing (the wheelchair's computer), keep the default local
backend, which opens no socket.
"""

from __future__ import annotations

import contextlib
import inspect
import logging
import os
import signal
import threading
from collections.abc import Callable, Iterable
from typing import Any

from ..extras import require

_REPR_MAX = 200  # characters of an item's repr in error notes


def _call(fn: Callable[[Any], Any], item: Any) -> Any:
    """The remote task: any picklable callable (partials too, which ``ray.remote`` refuses)."""
    return fn(item)


def _describe(i: int, item: Any) -> str:
    r = repr(item)
    return f"item {i}: {r if len(r) <= _REPR_MAX else r[: _REPR_MAX - 3] + '...'}"


@contextlib.contextmanager
def _quiet_auth_notice():
    """Drop the warning Ray logs that token authentication is on (its default for a local cluster, kept).

    (``RAY_AUTH_MODE=token`` in the environment silences it too, but set here it would come too late:
    the driver has read its configuration at ``import ray``, would start a cluster that wants a token
    and then not send one - it never connects.)
    """
    log = logging.getLogger("ray._private.authentication.authentication_token_setup")
    drop = _DropAuthNotice()
    log.addFilter(drop)
    try:
        yield
    finally:
        log.removeFilter(drop)


class _DropAuthNotice(logging.Filter):
    def filter(self, record: logging.LogRecord) -> bool:
        return not record.getMessage().startswith("Token authentication is enabled")


def _connect(ray: Any, address: str | None, num_cpus: int | None) -> Callable[[], None] | None:
    """Make sure Ray is initialised; return what undoes it, or ``None`` if it was already (leave it)."""
    if ray.is_initialized():
        return None
    sigterm = signal.getsignal(signal.SIGTERM)  # ray.init installs its own: put this one back after
    quiet = {"log_to_driver": False, "logging_level": logging.WARNING}
    try:
        with _quiet_auth_notice():
            if address is None:
                os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")  # read by the processes ray.init starts
                ray.init(address="local", num_cpus=num_cpus, include_dashboard=False, **quiet)
            else:
                ray.init(address=address, **quiet)
    except BaseException:
        ray.shutdown()  # whatever a failed start left running (a no-op if nothing)
        raise

    def disconnect() -> None:
        """Shut down the local cluster (all its processes) or, for one connected to, just disconnect."""
        if "wait_for_processes" in inspect.signature(ray.shutdown).parameters:  # newer Ray only
            ray.shutdown(wait_for_processes=True)
        else:
            ray.shutdown()
        if sigterm is not None and threading.current_thread() is threading.main_thread():
            signal.signal(signal.SIGTERM, sigterm)

    return disconnect


def _raise_for(ray: Any, e: Exception, i: int, item: Any) -> None:
    """Raise the failure of item ``i``: the task's own exception where Ray kept it, with a note."""
    note = f"ray_map: {_describe(i, item)}"
    cause = getattr(e, "cause", None)
    own = isinstance(cause, Exception) and not isinstance(cause, ray.exceptions.RayError)
    if isinstance(e, ray.exceptions.RayTaskError) and own:
        cause.add_note(note)
        raise cause from e  # e (the chained cause) carries the remote traceback
    e.add_note(note)
    if "No module named" in str(e):
        e.add_note(
            "ray_map: a Ray worker could not import a module the task needs; every node needs "
            "sa_daemon (and whatever defines fn) installed, in the driver's version"
        )
    raise e


def ray_map(
    fn: Callable[[Any], Any],
    items: Iterable[Any],
    address: str | None = None,
    num_cpus: int | None = None,
    on_result: Callable[[], Any] | None = None,
) -> list:
    """``[fn(x) for x in items]``, each call a Ray task; results in the order of ``items``.

    ``fn`` and the items must pickle (cloudpickle: a top-level function of an installed module, or a
    lambda/closure/partial, pickled by value). ``address``: which cluster (module docstring; ``None``
    starts a local one for this call and shuts it down after). ``num_cpus``: the size of that local
    cluster (``None``: Ray counts the machine's CPUs); on a cluster connected to or reused it caps how
    many items run at once instead. ``on_result()`` is called once per item as each finishes, in
    finishing order.

    The first failing item (in finishing order) stops the map: no further item is submitted, and its
    exception is raised as the type ``fn`` raised (not Ray's wrapper; that is chained as
    ``__cause__`` with the remote traceback), with a PEP 678 note naming the item's index and repr.
    Failures of Ray itself (a worker that died, a module that would not import) raise Ray's exception
    with the same note. The items still running then are not cancelled: Ray's cancel can abort the
    driver when it meets a task that is just finishing (measured with Ray 2.60 in this project's tests:
    ``Check failed: it != submissible_tasks_.end() Tried to complete task that was not pending``, the
    race of ray-project/ray#54798). They stop with a cluster ``ray_map`` started; on one it connected to
    or reused they run to their end and their results are dropped.
    """
    ray = require("ray", "ray")
    items = list(items)
    if not items:
        return []
    if num_cpus is not None and num_cpus < 1:
        raise ValueError(f"num_cpus must be >= 1, got {num_cpus}")
    disconnect = _connect(ray, address, num_cpus)
    index: dict[Any, int] = {}  # running task -> its item's index
    try:
        task = ray.remote(_call)
        fn_ref = ray.put(fn)  # shipped once, not with every item
        out: list = [None] * len(items)
        window = len(items) if num_cpus is None else num_cpus
        todo = iter(range(len(items)))

        def submit() -> None:
            i = next(todo, None)
            if i is not None:
                index[task.remote(fn_ref, items[i])] = i

        for _ in range(window):
            submit()
        while index:
            [ref], _ = ray.wait(list(index), num_returns=1)
            i = index.pop(ref)
            try:
                out[i] = ray.get(ref)
            except ray.exceptions.RayError as e:
                _raise_for(ray, e, i, items[i])
            submit()
            if on_result is not None:
                on_result()
        return out
    finally:
        if disconnect is not None:
            disconnect()
