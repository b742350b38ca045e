"""The real UFactory xArm-6 through the xArm Python SDK (``--arm xarm``, ``pip install ".[xarm]"``).

Design (``docs/xarm.md``):

* **One I/O thread owns the SDK object.** Every SDK call can block for up to 2 s (reply timeout), so
  none happens on the caller's thread: :meth:`XArm.read` returns the state the thread cached last,
  :meth:`XArm.command_twist` / :meth:`XArm.command_gripper` / :meth:`XArm.reset_fault` only hand a
  request over and wake the thread through a condition variable.
* **Velocity commands carry a dead-man duration.** Each twist is sent once as
  ``vc_set_cartesian_velocity(speeds mm/s + rad/s, is_radian=True, is_tool_coord=False,
  duration=command_periods / control_hz)``: the controller zeroes the speed by itself when the daemon
  stops commanding (crash, hang, cable), so the thread never re-sends an old twist. Only the latest
  twist is sent (older ones are superseded), at most 250 Hz (the SDK's documented limit).
* **Faults latch.** A controller error (callback, a refused command or found after connecting) stops
  the stream and latches ``"xArm error 22: self collision"``; a lost connection latches
  ``"disconnected"`` and the thread reconnects with exponential backoff. Nothing moves again until
  :meth:`XArm.reset_fault` (an explicit resume) runs the recovery sequence.

SI units everywhere outside this module; mm, mm/s and the SDK's angle flags only at the SDK boundary.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from ..config import Config
from ..geometry import FloatArray, Pose
from .base import Arm, ArmState, Kinematics, commanded_twist
from .xarm_limits import apply_limits, compare, expected_limits, read_limits
from .xarm_sdk import (
    CODE_HAS_ERROR,
    CODE_NOT_CONNECTED,
    CODE_NOT_READY,
    GRIPPER_CLOSED_POS,
    GRIPPER_OPEN_POS,
    LINK_CODES,
    MAX_COMMAND_HZ,
    MODE_CARTESIAN_VELOCITY,
    READY_STATES,
    error_text,
    firmware_of,
    pose_from_sdk,
    sdk_factory,
    twist_to_speeds,
)

if TYPE_CHECKING:
    from ..world.scene import Scene

log = logging.getLogger(__name__)

#: A pose older than this (s) while connected latches a fault: the safety pipeline needs a fresh pose.
STALE_POSE_S = 0.5
#: How long the constructor waits for the first connection and pose (the SDK's own connect timeout is
#: shorter), and how long :meth:`XArm.close` waits for the I/O thread (two SDK reply timeouts + margin).
STARTUP_TIMEOUT_S = 30.0
JOIN_TIMEOUT_S = 5.0

#: Fault texts of the link (controller errors read as :func:`~.xarm_sdk.error_text`).
DISCONNECTED = "disconnected"
RECONNECTED = "disconnected (reconnected; resume to re-enable)"
CLOSED = "closed"


class _LinkLost(Exception):
    """The SDK says the connection is gone (code -1 or 3, or an exception)."""


@dataclass
class _Work:
    """What the I/O thread does next (taken under the lock, done outside it)."""

    link_lost: str | None = None
    zero: bool = False
    reset: bool = False
    gripper: bool | None = None
    twist: tuple[list[float], float] | None = None  # SDK speeds, handover time (monotonic s)
    poll: bool = False

    def any(self) -> bool:
        return bool(self.link_lost or self.zero or self.reset or self.gripper is not None or self.twist or self.poll)


def _default_kinematics(cfg: Config) -> Kinematics | None:
    """The xArm-6 model (``kinematics.py``, Pinocchio) for the safety pipeline's joint stages, or
    ``None`` where that module is not available."""
    try:
        from .kinematics import ArmKinematics
    except ImportError:
        return None
    return ArmKinematics(joint_margin=cfg.safety.joint_margin_rad)


class XArm(Arm):
    """The xArm-6 in Cartesian velocity mode (mode 5), driven from one I/O thread.

    ``api_factory`` returns an ``XArmAPI``-like object (connected or not); tests pass the fake. The
    constructor connects, enables the arm and reads the first pose, and raises ``ConnectionError`` when
    it cannot connect or read a pose; a controller error present at start-up is a latched fault instead.
    ``kinematics`` defaults to the xArm-6 model; its TCP must match the TCP offset set on the controller.
    """

    name = "xarm"
    realtime = True

    @classmethod
    def from_config(cls, scene: Scene, cfg: Config) -> XArm:
        return cls(cfg)  # the real arm is where it is: the scene does not place it

    def __init__(self, cfg: Config, api_factory: Callable[[], Any] | None = None,
                 kinematics: Kinematics | None = None) -> None:
        self.kinematics = kinematics if kinematics is not None else _default_kinematics(cfg)
        xc = cfg.arm.xarm
        self._xc = xc
        self._limits = cfg.limits
        #: The controller limits config asks for (``xarm_limits.py``), set or verified at every enabling.
        self.controller_limits = expected_limits(cfg)
        #: Command and poll rate (Hz): the control rate, capped at the SDK's 250 Hz.
        self.rate_hz = min(float(cfg.runtime.control_hz), MAX_COMMAND_HZ)
        #: ``duration`` of each velocity command (s): the arm stops this long after the last command.
        self.duration_s = xc.command_periods / self.rate_hz
        self._period_s = 1.0 / self.rate_hz

        self._cv = threading.Condition()
        # Held by the I/O thread across each velocity command's SDK call, so halt() can wait for one in flight.
        self._sending = threading.Lock()
        # Shared with the callers and the SDK's callback thread; guarded by _cv, never held in an SDK call.
        self._closing = False
        self._connected = False
        self._fault: str | None = None
        self._fault_seq = 0
        self._twist: tuple[list[float], float] | None = None
        self._gripper_req: bool | None = None
        self._reset_req = False
        self._zero_req = False
        self._halted = False  # set by halt(): only zeros are sent from then on
        self._link_lost_req: str | None = None
        self._pose: Pose | None = None
        self._joints: FloatArray | None = None
        self._gripper_closed = False
        self._poll_t = 0.0
        self._in_call: tuple[str, float] | None = None  # the SDK call in progress and when it started
        self._next_send_t = 0.0
        self._stats: dict[str, Any] = {
            "error_code": 0,
            "warn_code": 0,
            "commands_sent": 0,
            "commands_refused": 0,
            "twists_dropped": 0,
            "last_send_latency_s": None,
            "max_send_latency_s": 0.0,
            "last_call_s": None,
            "poll_errors": 0,
            "connect_attempts": 0,
            "reconnects": 0,
            "disconnect_reason": None,
            "recovering": False,
            "gripper_code": 0,
            "firmware": None,
            "note": None,
            "controller_limits": None,
        }

        self._api = (api_factory or sdk_factory(xc.ip, xc.sdk))()
        self._api.register_error_warn_changed_callback(self._on_error_warn)
        self._api.register_connect_changed_callback(self._on_connect_changed)

        self._started = threading.Event()
        self._startup_error: str | None = None
        self._thread = threading.Thread(target=self._run, name="xarm-io", daemon=True)
        self._thread.start()
        if not self._started.wait(STARTUP_TIMEOUT_S) or self._startup_error is not None:
            reason = self._startup_error or f"no answer within {STARTUP_TIMEOUT_S:.0f} s"
            self.close()
            raise ConnectionError(f"xArm at {xc.ip}: {reason}")

    # -- Arm interface (never blocks) -----------------------------------------------------------------

    @property
    def api(self) -> Any:
        """The SDK object (the fake's fault-injection API in tests). Do not call it: the I/O thread owns it."""
        return self._api

    def read(self) -> ArmState:
        with self._cv:
            assert self._pose is not None  # the constructor guarantees a first pose
            if self._in_call is not None and self._fault is None and not self._closing:
                name, since = self._in_call
                waited = time.monotonic() - since
                if waited > STALE_POSE_S:  # no reply yet (the SDK waits up to 2 s): the pose is that old
                    self._latch(f"xArm not answering: no reply to {name} for {waited:.1f} s")
                    self._zero_req = True  # sent once the I/O thread is free again
            return ArmState(self._pose, self._gripper_closed, self._fault, self._joints)

    def command_twist(self, twist: FloatArray) -> None:
        """Hand ``twist`` (m/s, rad/s, base frame) to the I/O thread; it holds for ``duration_s``.

        Raises ``ValueError`` (and changes nothing) unless it is 6 finite numbers. Ignored while a fault
        is latched or after :meth:`close`; clipped to the configured per-axis limits as a last guard.
        """
        speeds = twist_to_speeds(commanded_twist(twist, self._limits))
        with self._cv:
            if self._fault is not None or self._closing or (self._halted and any(speeds)):
                self._stats["twists_dropped"] += 1
                return
            self._twist = (speeds, time.monotonic())
            self._cv.notify_all()

    def halt(self, timeout_s: float = 0.1) -> bool:
        """Stop for good: a zero is queued, moving commands are refused from now on (also one the I/O thread
        has taken but not sent yet), and this returns once a moving command already in the SDK's hands has
        had its reply, or after ``timeout_s`` s (then ``False``). The zero follows on the I/O thread."""
        with self._cv:
            self._halted = True
            self._twist = None
            self._zero_req = True
            self._cv.notify_all()
        if not self._sending.acquire(timeout=timeout_s):
            return False
        self._sending.release()
        return True

    def command_gripper(self, closed: bool) -> None:
        """Close (position 0) or open (850) the gripper, from the I/O thread; ignored while faulted."""
        with self._cv:
            if self._fault is not None or self._closing:
                return
            self._gripper_req = bool(closed)
            self._cv.notify_all()

    def reset_fault(self) -> None:
        """Ask the I/O thread to recover (``clean_error``, ``motion_enable(True)``, ``set_mode(5)``,
        ``set_state(0)``); returns at once. The fault clears in :meth:`read` once the arm is ready again,
        or changes to the reason recovery failed. Ignored while disconnected or without a fault."""
        with self._cv:
            if self._fault is None or self._closing:
                return
            self._reset_req = True
            self._cv.notify_all()

    def close(self) -> None:
        """Command zero velocity, stop the I/O thread, disconnect. Idempotent; waits at most ~5 s."""
        with self._cv:
            self._closing = True
            self._twist = None
            self._cv.notify_all()
        if self._thread.is_alive() and threading.current_thread() is not self._thread:
            self._thread.join(JOIN_TIMEOUT_S)

    def status(self) -> dict[str, Any]:
        """Diagnostics for the daemon to publish (JSON-ready): connection, fault, controller codes,
        command counters, the latest and worst handover-to-reply latency of a velocity command (s), the
        duration of the last SDK call (s), the age of the cached pose (s), reconnects."""
        with self._cv:
            s = dict(self._stats)
            s.update(
                connected=self._connected,
                fault=self._fault,
                rate_hz=self.rate_hz,
                duration_s=self.duration_s,
                pose_age_s=time.monotonic() - self._poll_t if self._poll_t else None,
                closed=self._closing,
            )
            return s

    # -- SDK callbacks (SDK report thread): flags only -------------------------------------------------

    def _on_error_warn(self, data: dict) -> None:
        code = int(data.get("error_code") or 0)
        with self._cv:
            self._stats["error_code"] = code
            self._stats["warn_code"] = int(data.get("warn_code") or 0)
            if code != 0 and not self._closing:
                self._latch(error_text(code))
                self._zero_req = True
                self._cv.notify_all()

    def _on_connect_changed(self, data: dict) -> None:
        if data.get("connected", True):
            return
        with self._cv:
            if self._connected and not self._closing:
                self._link_lost_req = "connection lost (SDK callback)"
                self._latch(DISCONNECTED)
                self._cv.notify_all()

    def _latch(self, text: str) -> None:
        """Latch fault ``text`` and drop pending motion requests (caller holds ``_cv``)."""
        self._fault = text
        self._fault_seq += 1
        self._twist = None
        self._gripper_req = None

    # -- I/O thread -----------------------------------------------------------------------------------

    def _run(self) -> None:
        try:
            try:
                self._startup_error = self._start()
            except _LinkLost as e:
                self._startup_error = f"cannot connect: {e}"
            self._started.set()
            if self._startup_error is None:
                self._loop()
        except Exception as e:
            log.exception("xArm I/O thread failed")
            with self._cv:
                self._latch(f"xArm driver error: {type(e).__name__}: {e}")
            if self._startup_error is None and not self._started.is_set():
                self._startup_error = f"driver error: {type(e).__name__}: {e}"
        finally:
            self._started.set()
            self._shutdown()

    def _start(self) -> str | None:
        """Connect, enable, set up the gripper, read the first pose; the reason it failed or ``None``."""
        self._connect()
        with self._cv:
            faulted = self._fault is not None
        if not faulted:  # an error present at start-up stays latched: enabling is the user's resume
            failure = self._enable(recovering=False)
            if failure is not None:
                with self._cv:
                    self._latch(failure)
        if not self._poll():
            return "cannot read the pose (get_position / get_servo_angle failed)"
        return None

    def _loop(self) -> None:
        next_poll = time.monotonic()
        while True:
            work = self._next_work(next_poll)
            if work is None:
                return
            try:
                self._do(work)
                if work.poll:
                    self._poll()
                    next_poll += self._period_s
                    if next_poll < time.monotonic():
                        next_poll = time.monotonic() + self._period_s
            except _LinkLost as e:
                self._lose_link(str(e))
                if not self._reconnect():
                    return
                next_poll = time.monotonic()

    def _next_work(self, next_poll: float) -> _Work | None:
        """Wait for a request or the next poll; ``None`` when closing."""
        with self._cv:
            while True:
                if self._closing:
                    return None
                now = time.monotonic()
                w = _Work(link_lost=self._link_lost_req, zero=self._zero_req, reset=self._reset_req,
                          gripper=self._gripper_req, poll=now >= next_poll)
                self._link_lost_req, self._zero_req, self._reset_req, self._gripper_req = None, False, False, None
                if self._twist is not None and now >= self._next_send_t:
                    w.twist, self._twist = self._twist, None
                if w.any():
                    return w
                timeout = next_poll - now
                if self._twist is not None:
                    timeout = min(timeout, self._next_send_t - now)
                self._cv.wait(max(timeout, 0.0))

    def _do(self, w: _Work) -> None:
        if w.link_lost:
            raise _LinkLost(w.link_lost)
        if w.zero:
            self._send([0.0] * 6, None)
        if w.reset:
            self._recover()
        if w.gripper is not None:
            self._send_gripper(w.gripper)
        if w.twist is not None:
            with self._sending:
                with self._cv:  # a fault latched, or a halt, after the twist was taken
                    stale = self._fault is not None or (self._halted and any(w.twist[0]))
                if not stale:
                    self._send(*w.twist)

    def _call(self, name: str, *args: Any, **kwargs: Any) -> Any:
        """One SDK call; raises ``_LinkLost`` on an exception or a code of -1 or 3."""
        t0 = time.monotonic()
        with self._cv:
            self._in_call = (name, t0)
        try:
            ret = getattr(self._api, name)(*args, **kwargs)
        except Exception as e:  # the SDK raises on socket errors
            raise _LinkLost(f"{name}: {type(e).__name__}: {e}") from e
        finally:
            with self._cv:
                self._in_call = None
        code = ret[0] if isinstance(ret, (tuple, list)) else ret
        with self._cv:
            self._stats["last_call_s"] = time.monotonic() - t0
        if code in LINK_CODES:
            what = "not connected" if code == CODE_NOT_CONNECTED else "reply timeout"
            raise _LinkLost(f"{name}: code {code} ({what})")
        return ret

    def _send(self, speeds: list[float], handed_at: float | None) -> None:
        """Send one velocity command; a zero (``handed_at is None``) is sent whatever the reply."""
        code = self._call("vc_set_cartesian_velocity", speeds, is_radian=True, is_tool_coord=False,
                          duration=self.duration_s)
        done = time.monotonic()
        with self._cv:
            self._next_send_t = done + 1.0 / MAX_COMMAND_HZ
            self._stats["commands_sent"] += 1
            if handed_at is not None:
                latency = done - handed_at
                self._stats["last_send_latency_s"] = latency
                self._stats["max_send_latency_s"] = max(self._stats["max_send_latency_s"], latency)
            if code != 0:
                self._stats["commands_refused"] += 1
        if code == 0 or handed_at is None:
            return
        if code == CODE_HAS_ERROR:
            err = self._controller_error()
            text = error_text(err) if err else "xArm error: velocity command refused (uncleared error)"
        elif code == CODE_NOT_READY:
            text = "xArm not ready (code 9): velocity command refused"
        else:
            text = f"xArm velocity command refused (code {code})"
        with self._cv:
            self._latch(text)

    def _send_gripper(self, closed: bool) -> None:
        with self._cv:
            if self._fault is not None:
                return
        code = self._call("set_gripper_position", GRIPPER_CLOSED_POS if closed else GRIPPER_OPEN_POS, wait=False)
        with self._cv:
            self._stats["gripper_code"] = code
            if code == 0:
                self._gripper_closed = closed

    def _controller_error(self) -> int:
        """The controller's error code now (0 if none or unknown)."""
        code, ew = self._call("get_err_warn_code")
        if code != 0 or not ew:
            return 0
        with self._cv:
            self._stats["error_code"], self._stats["warn_code"] = int(ew[0]), int(ew[1])
        return int(ew[0])

    def _poll(self) -> bool:
        """Read pose and joints into the cache; ``False`` if a reply was unusable."""
        if not self._api.connected:
            raise _LinkLost("SDK reports not connected")
        code, pos = self._call("get_position", is_radian=True)
        jcode, joints = self._call("get_servo_angle", is_radian=True)
        try:
            if code != 0 or jcode != 0:
                raise ValueError(f"codes {code}, {jcode}")
            pose = pose_from_sdk(pos)
            q = np.asarray(joints, dtype=float)[:6]
            if q.shape != (6,) or not np.all(np.isfinite(q)):
                raise ValueError("joint angles")
        except (ValueError, TypeError, IndexError) as e:
            with self._cv:
                self._stats["poll_errors"] += 1
                age = time.monotonic() - self._poll_t
                if self._poll_t and age > STALE_POSE_S and self._fault is None:
                    # Moving on a pose this old would blind the safety pipeline (workspace, joints).
                    why = f"get_position code {code}" if code != 0 else f"unusable reply: {e}"
                    self._latch(f"xArm pose not updated for {age:.1f} s ({why})")
                    self._zero_req = True
            return False
        q.setflags(write=False)
        with self._cv:
            self._pose, self._joints, self._poll_t = pose, q, time.monotonic()
        return True

    def _connect(self) -> None:
        """Connect (raises ``_LinkLost``), then check firmware and latch any controller error."""
        with self._cv:
            self._stats["connect_attempts"] += 1
        try:
            if not self._api.connected:
                self._api.connect()
        except Exception as e:
            raise _LinkLost(f"connect: {type(e).__name__}: {e}") from e
        if not self._api.connected:
            raise _LinkLost("connect: still not connected")
        with self._cv:
            self._connected = True
        err = self._controller_error()
        firmware = self._firmware_problem()
        with self._cv:
            if err:
                self._latch(error_text(err))
            elif firmware:
                self._latch(firmware)

    def _firmware_problem(self) -> str | None:
        version, problem = firmware_of(self._api)
        with self._cv:
            self._stats["firmware"] = version
        return problem

    def _enable(self, recovering: bool) -> str | None:
        """The enabling sequence (recovery first clears the error), with the controller's limits set or
        verified before motion is enabled; the reason it failed or ``None``."""
        what = "recovery" if recovering else "setup"
        steps: list[tuple[str, tuple]] = [("clean_error", ())] if recovering else []
        steps += [("clean_warn", ())]
        for name, args in steps:
            code = self._call(name, *args)
            if code != 0:
                return f"xArm {what} failed: {name}{args!r} returned code {code}"
        failure = self._check_controller_limits()
        if failure is not None:
            return failure
        for name, args in (("motion_enable", (True,)), ("set_mode", (MODE_CARTESIAN_VELOCITY,)), ("set_state", (0,))):
            code = self._call(name, *args)
            if code != 0:
                return f"xArm {what} failed: {name}{args!r} returned code {code}"
        err = self._controller_error()
        if err:
            return f"{error_text(err)} (still present after {what})"
        firmware = self._firmware_problem()
        if firmware:
            return firmware
        code, state = self._call("get_state")
        if code != 0 or state not in READY_STATES:
            return f"xArm {what} failed: not ready after set_state(0) (state {state}, code {code})"
        self._setup_gripper()
        return None

    def _check_controller_limits(self) -> str | None:
        """Set (``arm.xarm.controller_limits = "set"``) the controller's limits, read them back and
        compare with config; the fault text naming each disagreement, or ``None``. ``status()`` shows
        every setting with its value on the controller and the expected one."""
        want = self.controller_limits
        failed = apply_limits(self._call, want) if self._xc.controller_limits == "set" else []
        actual = read_limits(self._call, self._property)
        mismatches = compare(want, actual)
        bad = {m.name for m in mismatches}
        with self._cv:
            self._stats["controller_limits"] = {
                name: {"controller": actual[name], "expected": expected, "ok": name not in bad}
                for name, expected in want.items()
            }
        if not failed and not mismatches:
            return None
        return "xArm controller limits: " + "; ".join(failed + [str(m) for m in mismatches])

    def _property(self, name: str) -> Any:
        """An SDK property (the report thread's copy: no call to the controller); ``None`` if unreadable."""
        try:
            return getattr(self._api, name)
        except Exception:  # noqa: BLE001 - a property the SDK version lacks, or its report not yet in
            return None

    def _setup_gripper(self) -> None:
        """Location mode, enable, speed. A missing or faulty gripper is reported, not an arm fault."""
        for name, arg in (("set_gripper_mode", 0), ("set_gripper_enable", True),
                          ("set_gripper_speed", self._xc.gripper_speed)):
            code = self._call(name, arg)
            with self._cv:
                self._stats["gripper_code"] = code
            if code != 0:
                with self._cv:
                    self._stats["note"] = f"gripper: {name}({arg!r}) returned code {code}"
                return

    def _recover(self) -> None:
        with self._cv:
            if self._fault is None:
                return
            if not self._connected:
                self._stats["note"] = "resume ignored: not connected"
                return
            seq = self._fault_seq
            self._stats["recovering"] = True
        try:
            failure = self._enable(recovering=True)
        finally:
            with self._cv:
                self._stats["recovering"] = False
        with self._cv:
            if failure is not None:
                self._latch(failure)
            elif self._fault_seq == seq:  # no new fault arrived meanwhile
                self._fault = None
                self._twist = None
                self._stats["note"] = "recovered"

    def _lose_link(self, reason: str) -> None:
        log.warning("xArm link lost: %s", reason)
        with self._cv:
            self._connected = False
            self._latch(DISCONNECTED)
            self._stats["disconnect_reason"] = reason
        self._disconnect_quietly()

    def _disconnect_quietly(self) -> None:
        """``disconnect()`` on a link that may already be gone: a failure there changes nothing."""
        try:
            self._api.disconnect()
        except Exception as e:  # noqa: BLE001 - the SDK raises socket errors of any type
            log.debug("xArm disconnect: %s", e)

    def _reconnect(self) -> bool:
        """Reconnect with exponential backoff; ``False`` if closing. Stays faulted until a resume."""
        delay = self._xc.reconnect_min_s
        while True:
            with self._cv:
                deadline = time.monotonic() + delay
                while not self._closing and (left := deadline - time.monotonic()) > 0:
                    self._cv.wait(left)
                if self._closing:
                    return False
                # Requests made while the link was down are void.
                self._twist, self._gripper_req, self._zero_req, self._link_lost_req = None, None, False, None
                if self._reset_req:
                    self._reset_req = False
                    self._stats["note"] = "resume ignored: not connected"
            try:
                self._connect()
                with self._cv:
                    if self._fault == DISCONNECTED:
                        self._fault = RECONNECTED
                if not self._poll():
                    raise _LinkLost("no pose after reconnecting")
            except _LinkLost as e:
                with self._cv:
                    self._connected = False
                    self._stats["disconnect_reason"] = str(e)
                self._disconnect_quietly()
                delay = min(2.0 * delay, self._xc.reconnect_max_s)
                continue
            with self._cv:
                self._stats["reconnects"] += 1
            return True

    def _shutdown(self) -> None:
        """Thread exit: leave a zero command and disconnect."""
        with self._cv:
            connected = self._connected
        if connected:
            try:
                self._send([0.0] * 6, None)
            except _LinkLost:
                pass
        self._disconnect_quietly()
        with self._cv:
            self._connected = False
            self._closing = True
            if self._fault is None:
                self._fault = CLOSED
