"""A stand-in for the xArm SDK's ``xarm.wrapper.XArmAPI`` that enforces its documented rules.

Used by the tests and by a daemon configured with ``[arm.xarm] sdk = "fake"``. It is not a physics model:
it is a strict model of the *protocol*, so that a driver calling the SDK in the wrong order, with the
wrong units or without checking return codes fails here as it would on the arm.

Each rule and where it comes from (``shared/reference/xarm6.md`` = R, the SDK's own docstrings and
API-code list = S):

1. Construction ``FakeXArmAPI(port, is_radian=False, do_not_open=False)`` connects unless
   ``do_not_open`` (S: ``XArmAPI.__init__``); ``connect()`` raises when the controller cannot be reached
   (S: the SDK raises ``Exception('connect socket failed')``); ``connect()`` on a connected object does
   nothing.
2. Return codes (R; S "API code"): ``-1`` not connected, ``1`` uncleared controller error, ``2`` warning,
   ``3`` reply timeout, ``9`` not ready to move. Setter calls return a code, getters ``(code, value)``.
   As in the SDK, only *motion* commands report 1 and 9: for other calls the SDK maps them to 0, so
   ``set_mode``/``set_state``/``motion_enable`` "succeed" while an error is present but change nothing.
3. Cartesian velocity control (R): ``motion_enable(True)``, ``set_mode(5)``, ``set_state(0)``. Every
   ``set_mode`` and every ``motion_enable`` leaves the arm not ready (state 4) until the next
   ``set_state(0)``, and ``set_state(0)`` has no effect while motion is disabled or an error is present;
   ``vc_set_cartesian_velocity`` then returns 9.
4. Units (R; S ``vc_set_cartesian_velocity``): ``speeds = [x, y, z (mm/s), rx, ry, rz]`` with the angular
   part an axis-angle rate vector in deg/s, or rad/s when ``is_radian`` (default: the constructor's
   ``is_radian``); base frame unless ``is_tool_coord``. ``get_position`` returns
   ``(code, [x, y, z (mm), roll, pitch, yaw])`` and ``get_servo_angle`` ``(code, [7 angles])``, angles in
   degrees unless ``is_radian``; roll-pitch-yaw is extrinsic x-y-z (``R = Rz(yaw) Ry(pitch) Rx(roll)``).
5. ``duration > 0`` (R, firmware >= 1.8.0): the speed is zeroed that many seconds after the command;
   ``duration <= 0`` holds the speed until the next command. A fake built with ``firmware < (1, 8, 0)``
   ignores ``duration`` (the SDK does not send it to such firmware).
6. The commanded velocity is integrated on the fake's own clock (``clock``, default
   ``time.monotonic``): the pose moves in real time, exactly (piecewise-constant twist on SE(3)).
7. Controller errors (R): ``inject_error(code)`` puts the arm in mode 0 / state 4 with motion disabled,
   zeroes the speed and fires the error/warn callback with ``{'error_code': .., 'warn_code': ..}`` (S
   payload). Motion commands return 1 until ``clean_error()``; then 9 until ``motion_enable(True)``,
   ``set_mode(5)``, ``set_state(0)`` (R recovery order; S ``clean_error`` docstring).
   ``inject_warn(code)`` sets a warning (cleared by ``clean_warn``) that does not stop motion (S maps 2
   to success for motion commands).
8. Connection (R): ``drop_connection()`` closes the link: every call returns -1 and the connect callback
   fires with ``{'connected': False, 'reported': False}`` (S payload); ``connect()`` raises until
   ``restore_connection()``. The controller keeps executing the last command until its ``duration``
   runs out, which is why the duration matters.
9. Reply timeout (R: the SDK blocks up to 2 s): ``hang(seconds)`` makes every call issued in the next
   ``seconds`` block until that moment and return 3 (or ``(3, None)``) without any effect.
10. Gripper (R): ``set_gripper_mode(0)`` (location mode, the only mode documented),
    ``set_gripper_enable(True)``, ``set_gripper_speed`` (r/min), ``set_gripper_position(pos)`` with
    ``0 <= pos <= 850`` (0 closed, 850 open). Stricter than the SDK: a position outside 0..850, a speed
    outside 1..5000 or a mode other than 0 returns 12 (the SDK's "parameter error"), a position on a
    gripper that is not enabled returns 103 ("end effector not enabled") and a gripper with an injected
    error (``inject_gripper_error``) returns 102 until ``clean_gripper_error()``.

11. Controller limits (S ``doc/api/xarm_api.md``; the table in ``arm/xarm_limits.py``):
    ``set_reduced_mode``, ``set_reduced_max_tcp_speed`` (mm/s, stored as float32),
    ``set_reduced_tcp_boundary([x_max, x_min, y_max, y_min, z_max, z_min])`` (mm; truncated to int, a pair
    given min first is swapped, as the SDK does), ``set_fence_mode`` (returns ``[code]``, a list, as the
    SDK's does; ``set_fense_mode`` is its old name), ``set_collision_sensitivity(0..5)`` (the SDK asserts
    the range; it ends with ``set_state(0)``), ``set_self_collision_detection``; read back with
    ``get_reduced_mode``, ``get_reduced_states`` (7 elements: on, boundary, TCP speed, joint speed, 14
    joint ranges, fence on, rebound on) and the properties ``collision_sensitivity`` and
    ``self_collision_params``. The SDK says a new speed or boundary takes effect when reduced mode is
    switched on again: the fake enforces the values in force at the last ``set_reduced_mode(True)``.
    Enforcement (the docs say the arm stops with C35 when the TCP crosses the boundary; they do not say
    whether a velocity above the reduced TCP speed is capped or stopped, so the fake takes the stricter
    reading): with the fence on, the TCP reaching the boundary stops the arm there with error 35; in
    reduced mode, a velocity command whose linear speed exceeds the reduced TCP speed stops the arm with
    error 24 and returns 1. Both fire the error callback like :meth:`inject_error`.

Deliberately stricter than the real controller: a velocity command outside mode 5 returns 9 (the SDK only
logs a warning and the controller ignores it), non-finite or malformed speeds return 12, and a boundary
value outside int16 returns 12. Not modelled: joint motion (``get_servo_angle`` returns the fixed start
angles), joint speed limits, the report socket's other callbacks.

Every call is logged (:attr:`calls`, :meth:`wait_for_calls`) for assertions on order and timing.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..geometry import FloatArray, integrate_pose, quat_to_matrix, rpy_to_quat

NOT_CONNECTED = -1
HAS_ERROR = 1
HAS_WARN = 2
REPLY_TIMEOUT = 3
NOT_READY = 9
PARAM_ERROR = 12
END_EFFECTOR_HAS_FAULT = 102
END_EFFECTOR_NOT_ENABLED = 103
#: Speeds travel as 32-bit floats (S): a command this close above the reduced TCP speed is at it (mm/s).
SPEED_RESOLUTION_MM_S = 1e-3
#: Controller errors the fake raises by itself (rule 11).
SPEED_LIMIT_ERROR = 24
BOUNDARY_ERROR = 35

#: What a controller nobody has configured reports (rule 11): reduced mode and the fence off, a wide
#: boundary, sensitivity at the factory default 3, self-collision detection off.
FACTORY_LIMITS = {
    "reduced_mode": False,
    "tcp_speed_mm_s": 250.0,
    "boundary_mm": (1000, -1000, 1000, -1000, 1000, -1000),
    "fence": False,
    "collision_sensitivity": 3,
    "self_collision": False,
}

GRIPPER_CLOSED = 0
GRIPPER_OPEN = 850

#: Controller states reported by ``get_state`` (S): 1 moving, 2 ready and idle, 3 paused, 4 stopped.
STATE_MOVING, STATE_READY, STATE_PAUSED, STATE_STOPPED = 1, 2, 3, 4

#: Default start: the joint angles (rad, 7 values as the SDK reports them for a 6-axis arm) and, to
#: 0.1 mm, their TCP pose by the forward kinematics of ``xarm6.xml`` (gripper pointing down, Jacobian
#: condition number about 10, far from singular), so a daemon's safety stages see a consistent start.
DEFAULT_START_JOINTS_RAD = (0.0, -0.5, -1.0, 0.0, 1.5, 0.0, 0.0)
DEFAULT_START_MM_RAD = (333.7, 0.0, 326.4, math.pi, 0.0, 0.0)

Callback = Callable[[dict], None]

#: The ``XArmAPI`` methods the fake implements, with the SDK's parameter names and defaults.
SDK_METHODS = (
    "connect", "disconnect", "motion_enable", "set_mode", "set_state", "get_state", "clean_error", "clean_warn",
    "get_err_warn_code", "vc_set_cartesian_velocity", "get_position", "get_servo_angle", "set_gripper_mode",
    "set_gripper_enable", "set_gripper_speed", "set_gripper_position", "get_gripper_position",
    "get_gripper_err_code", "clean_gripper_error", "register_connect_changed_callback",
    "register_error_warn_changed_callback", "release_connect_changed_callback",
    "release_error_warn_changed_callback", "set_reduced_mode", "set_reduced_max_tcp_speed",
    "set_reduced_tcp_boundary", "set_fence_mode", "set_collision_sensitivity",
    "set_self_collision_detection", "get_reduced_mode", "get_reduced_states",
)


@dataclass(frozen=True)
class Call:
    """One logged SDK call: when (fake clock, s), which method, its arguments and what it returned."""

    t: float
    name: str
    args: tuple
    kwargs: dict = field(default_factory=dict)
    result: Any = None


def matrix_to_rpy(m: FloatArray) -> tuple[float, float, float]:
    """Extrinsic x-y-z roll, pitch, yaw (rad) of a rotation matrix, the inverse of ``rpy_to_quat``."""
    sp = -float(m[2, 0])
    if abs(sp) < 1.0 - 1e-9:
        return (
            math.atan2(float(m[2, 1]), float(m[2, 2])),
            math.asin(sp),
            math.atan2(float(m[1, 0]), float(m[0, 0])),
        )
    # Gimbal lock: only roll - yaw (or roll + yaw) is defined; put it all in yaw.
    pitch = math.copysign(math.pi / 2, sp)
    return 0.0, pitch, math.atan2(-float(m[0, 1]), float(m[1, 1]))


def _locked(attr: str) -> property:
    """A read-only property returning ``self.<attr>`` under the fake's lock (the SDK's state is read
    from its report thread; so is the fake's)."""

    def get(self: Any) -> Any:
        with self._lock:
            return getattr(self, attr)

    return property(get)


class FakeXArmAPI:
    """A strict in-process xArm controller behind the ``XArmAPI`` method names (rules: module docstring).

    Thread-safe: the driver's I/O thread calls it while a test injects faults from another thread.
    Callbacks run in the thread that caused them, outside the fake's lock (as the SDK runs them in its
    report thread).
    """

    def __init__(
        self,
        port: str | None = None,
        is_radian: bool = False,
        do_not_open: bool = False,
        *,
        clock: Callable[[], float] = time.monotonic,
        firmware: tuple[int, int, int] = (2, 4, 0),
        start_mm_rad: Sequence[float] = DEFAULT_START_MM_RAD,
        start_joints_rad: Sequence[float] = DEFAULT_START_JOINTS_RAD,
        limits: dict[str, Any] | None = None,
        **kwargs: Any,
    ) -> None:
        self._lock = threading.RLock()
        self._log_cv = threading.Condition(self._lock)
        self._clock = clock
        self._port = port
        self._is_radian = bool(is_radian)
        self.version_number: tuple[int, int, int] = tuple(firmware)  # type: ignore[assignment]
        self._calls: list[Call] = []
        self._connect_cbs: list[Callback] = []
        self._error_cbs: list[Callback] = []
        # link and controller
        self._link_up = True
        self._connected = False
        self._hang_until = 0.0  # time.monotonic() (real time: a hang blocks real threads)
        self._hang_release = threading.Event()
        self._blocked = 0  # calls blocked in a hang right now
        self._error = 0
        self._warn = 0
        self._enabled = False
        self._mode = 0
        self._ready = False
        self._paused = False
        # motion (mm, rad, mm/s, rad/s, base frame)
        start = np.asarray(start_mm_rad, dtype=float)
        self._pos_mm = start[:3].copy()
        self._quat = rpy_to_quat(start[3:6])
        self._joints = [float(a) for a in start_joints_rad]
        self._speed = np.zeros(6)
        self._expiry = math.inf
        self._stopped_since: float | None = self._clock()
        self._t = clock()
        # gripper
        self._gripper_mode = 0
        self._gripper_enabled = False
        self._gripper_speed = 0.0
        self._gripper_pos = float(GRIPPER_OPEN)
        self._gripper_error = 0
        # controller limits (rule 11): as set, and as in force since the last set_reduced_mode(True)
        lim = {**FACTORY_LIMITS, **(limits or {})}
        self._reduced = bool(lim["reduced_mode"])
        self._tcp_speed = float(np.float32(lim["tcp_speed_mm_s"]))
        self._boundary = tuple(int(v) for v in lim["boundary_mm"])
        self._fence = bool(lim["fence"])
        self._sensitivity = int(lim["collision_sensitivity"])
        self._self_collision = bool(lim["self_collision"])
        self._active_speed, self._active_boundary = self._tcp_speed, self._boundary
        self._pending: list[dict] = []  # error callbacks raised under the lock, fired after it
        if not do_not_open:
            if not port:
                raise ValueError("port (controller address) is required unless do_not_open=True")
            self.connect()

    # -- fault injection (test API) -------------------------------------------------------------------

    def inject_error(self, code: int) -> None:
        """A controller error ``code``: mode 0 / state 4, motion disabled, speed zero, callback fired."""
        if code <= 0:
            raise ValueError("controller error codes are positive")
        with self._lock:
            self._advance()
            self._raise(int(code))
        self._flush()

    def inject_warn(self, code: int) -> None:
        """A controller warning ``code`` (motion continues); fires the error/warn callback."""
        with self._lock:
            self._warn = int(code)
            payload, connected = self._err_payload(), self._connected
        if connected:
            self._fire(self._error_cbs, payload)

    def place(self, position_mm: Sequence[float], rpy_rad: Sequence[float]) -> None:
        """Put the TCP at a pose (mm, extrinsic roll-pitch-yaw in rad) at rest, as if moved there by hand."""
        with self._lock:
            self._advance()
            self._stop()
            self._pos_mm = np.asarray(position_mm, dtype=float).copy()
            self._quat = rpy_to_quat(rpy_rad)

    def inject_gripper_error(self, code: int) -> None:
        """A gripper error: position commands return 102 until ``clean_gripper_error()``."""
        with self._lock:
            self._gripper_error = int(code)

    def drop_connection(self) -> None:
        """The network link goes down: calls return -1, ``connect()`` raises, the connect callback fires."""
        with self._lock:
            self._link_up = False
            was = self._connected
            self._connected = False
        if was:
            self._fire(self._connect_cbs, {"connected": False, "reported": False})

    def restore_connection(self) -> None:
        """The link is back; the client must ``connect()`` again (a dropped socket stays closed)."""
        with self._lock:
            self._link_up = True

    def hang(self, seconds: float) -> None:
        """The controller stops replying for ``seconds``: calls issued meanwhile block until then and
        return 3 (reply timeout)."""
        with self._lock:
            self._hang_release.clear()
            self._hang_until = time.monotonic() + float(seconds)

    def unhang(self) -> None:
        """End a :meth:`hang` early (blocked calls return 3 at once)."""
        with self._lock:
            self._hang_until = 0.0
            self._hang_release.set()

    # -- inspection (test API) ------------------------------------------------------------------------

    @property
    def calls(self) -> list[Call]:
        """A copy of the call log, oldest first."""
        with self._lock:
            return list(self._calls)

    def calls_named(self, name: str) -> list[Call]:
        """The logged calls of one method."""
        with self._lock:
            return [c for c in self._calls if c.name == name]

    def clear_calls(self) -> None:
        with self._lock:
            self._calls.clear()

    def wait_for_calls(self, name: str, count: int, timeout: float) -> bool:
        """Block until ``count`` calls of ``name`` are logged (``True``) or ``timeout`` s pass (``False``)."""
        deadline = time.monotonic() + timeout
        with self._log_cv:
            while sum(1 for c in self._calls if c.name == name) < count:
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self._log_cv.wait(left)
            return True

    def wait_for_blocked(self, timeout: float) -> bool:
        """Block until some call is blocked in a :meth:`hang` (``True``) or ``timeout`` s pass."""
        deadline = time.monotonic() + timeout
        with self._log_cv:
            while self._blocked == 0:
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self._log_cv.wait(left)
            return True

    @property
    def stopped_since(self) -> float | None:
        """Clock time (s) since which the velocity in force has been zero: when the last moving command's
        ``duration`` ran out (the model's instant, not when anyone looked), when a zero command landed,
        or when the arm stopped itself; ``None`` while it moves."""
        return self._now(lambda: self._stopped_since)

    @property
    def speed(self) -> FloatArray:
        """The velocity in force now: ``[mm/s x3, rad/s x3]``, base frame (zero once expired)."""
        return self._now(lambda: self._speed.copy())

    @property
    def position_mm(self) -> FloatArray:
        """The TCP position now (mm, base frame)."""
        return self._now(lambda: self._pos_mm.copy())

    gripper_position = _locked("_gripper_pos")  # mm
    gripper_enabled = _locked("_gripper_enabled")
    enabled = _locked("_enabled")

    # -- SDK properties -------------------------------------------------------------------------------

    connected = _locked("_connected")

    @property
    def default_is_radian(self) -> bool:
        return self._is_radian

    mode = _locked("_mode")

    @property
    def state(self) -> int:
        return self._now(self._state_code)

    collision_sensitivity = _locked("_sensitivity")

    @property
    def self_collision_params(self) -> list:
        """``[is_collision_detection, tool_type, tool_params]`` (S; the fake has no tool model)."""
        with self._lock:
            return [int(self._self_collision), 0, []]

    @property
    def error_code(self) -> int:
        """The controller's error now (the motion is advanced first: reaching the fence raises 35)."""
        return self._now(lambda: self._error)

    warn_code = _locked("_warn")

    @property
    def has_error(self) -> bool:
        return self.error_code != 0

    @property
    def has_warn(self) -> bool:
        return self.warn_code != 0

    @property
    def has_err_warn(self) -> bool:
        return self.has_error or self.has_warn

    # -- connection -----------------------------------------------------------------------------------

    def connect(self, port: str | None = None, baudrate: Any = None, timeout: Any = None, axis: Any = None,
                **kwargs: Any) -> None:
        """Open the connection (not subject to :meth:`hang`); raises when the link is down."""
        with self._lock:
            self._port = port or self._port
            if self._connected:
                self._log("connect", (), {}, None)
                return
            if not self._link_up or not self._port:
                self._log("connect", (), {}, "failed")
                raise ConnectionError(f"connect socket failed ({self._port})")
            self._connected = True
            self._log("connect", (), {}, None)
            error = self._err_payload() if self._error or self._warn else None
        self._fire(self._connect_cbs, {"connected": True, "reported": True})
        if error is not None:
            self._fire(self._error_cbs, error)

    def disconnect(self) -> None:
        """Close the connection (no reply is awaited, so not subject to :meth:`hang`)."""
        with self._lock:
            was = self._connected
            self._connected = False
            self._log("disconnect", (), {}, None)
        if was:
            self._fire(self._connect_cbs, {"connected": False, "reported": False})

    def register_connect_changed_callback(self, callback: Callback | None = None) -> bool:
        """``callback({'connected': bool, 'reported': bool})`` on every connection change."""
        return self._register(self._connect_cbs, callback)

    def register_error_warn_changed_callback(self, callback: Callback | None = None) -> bool:
        """``callback({'error_code': int, 'warn_code': int})`` on every error or warning change."""
        return self._register(self._error_cbs, callback)

    def release_connect_changed_callback(self, callback: Callback | None = None) -> bool:
        return self._release(self._connect_cbs, callback)

    def release_error_warn_changed_callback(self, callback: Callback | None = None) -> bool:
        return self._release(self._error_cbs, callback)

    # -- controller state -----------------------------------------------------------------------------

    def motion_enable(self, enable: bool = True, servo_id: int | None = None) -> int:
        def op() -> int:
            if self._error:
                return 0  # the controller refuses; the SDK maps the reply to 0
            self._enabled = bool(enable)
            self._ready = False
            self._stop()
            return 0

        return self._set("motion_enable", (enable,), {"servo_id": servo_id}, op)

    def set_mode(self, mode: int = 0, detection_param: int = 0) -> int:
        def op() -> int:
            if not 0 <= int(mode) <= 7:
                return PARAM_ERROR
            if self._error:
                return 0
            self._mode = int(mode)
            self._ready = False
            self._stop()
            return 0

        return self._set("set_mode", (mode,), {}, op)

    def set_state(self, state: int = 0) -> int:
        def op() -> int:
            if state == 0:
                if not self._error and self._enabled:
                    self._ready, self._paused = True, False
            elif state == 3:
                self._paused = True
                self._stop()
            elif state in (4, 6):
                self._ready = False
                self._stop()
            else:
                return PARAM_ERROR
            return 0

        return self._set("set_state", (state,), {}, op)

    def get_state(self) -> tuple[int, int | None]:
        return self._get("get_state", (), {}, lambda: self._state_code())

    def clean_error(self) -> int:
        payload: list[dict] = []

        def op() -> int:
            if self._error:
                self._error = 0
                payload.append(self._err_payload())
            return 0

        code = self._set("clean_error", (), {}, op)
        if payload:
            self._fire(self._error_cbs, payload[0])
        return code

    def clean_warn(self) -> int:
        payload: list[dict] = []

        def op() -> int:
            if self._warn:
                self._warn = 0
                payload.append(self._err_payload())
            return 0

        code = self._set("clean_warn", (), {}, op)
        if payload:
            self._fire(self._error_cbs, payload[0])
        return code

    def get_err_warn_code(self, show: bool = False, lang: str = "en") -> tuple[int, list[int] | None]:
        return self._get("get_err_warn_code", (), {}, lambda: [self._error, self._warn])

    # -- motion ---------------------------------------------------------------------------------------

    def vc_set_cartesian_velocity(self, speeds: Sequence[float], is_radian: bool | None = None,
                                  is_tool_coord: bool = False, duration: float = -1, **kwargs: Any) -> int:
        def op() -> int:
            try:
                s = np.asarray(speeds, dtype=float).reshape(-1)
                d = float(duration)
            except (TypeError, ValueError):
                return PARAM_ERROR
            if s.shape != (6,) or not np.all(np.isfinite(s)) or not math.isfinite(d):
                return PARAM_ERROR
            if self._error:
                return HAS_ERROR
            if not (self._ready and self._enabled and not self._paused and self._mode == 5):
                return NOT_READY
            if self._reduced and float(np.linalg.norm(s[:3])) > self._active_speed + SPEED_RESOLUTION_MM_S:
                self._raise(SPEED_LIMIT_ERROR)  # rule 11: the stricter reading
                return HAS_ERROR
            radian = self._is_radian if is_radian is None else bool(is_radian)
            if not radian:
                s[3:] = np.radians(s[3:])
            if is_tool_coord:
                r = quat_to_matrix(self._quat)
                s[:3], s[3:] = r @ s[:3], r @ s[3:]
            moving, was_moving = bool(np.any(s)), bool(np.any(self._speed))
            self._speed = s
            honour = d > 0 and self.version_number >= (1, 8, 0)
            self._expiry = self._clock() + d if honour else math.inf
            if moving:
                self._stopped_since = None
            elif was_moving or self._stopped_since is None:
                self._stopped_since = self._clock()
            return 0

        return self._set(
            "vc_set_cartesian_velocity",
            (list(speeds) if isinstance(speeds, (list, tuple, np.ndarray)) else speeds,),
            {"is_radian": is_radian, "is_tool_coord": is_tool_coord, "duration": duration},
            op,
        )

    def get_position(self, is_radian: bool | None = None) -> tuple[int, list[float] | None]:
        def op() -> list[float]:
            rpy = matrix_to_rpy(quat_to_matrix(self._quat))
            radian = self._is_radian if is_radian is None else bool(is_radian)
            ang = list(rpy) if radian else [math.degrees(a) for a in rpy]
            return [float(v) for v in self._pos_mm] + ang

        return self._get("get_position", (), {"is_radian": is_radian}, op)

    def get_servo_angle(self, servo_id: int | None = None, is_radian: bool | None = None,
                        is_real: bool = False) -> tuple[int, Any]:
        def op() -> Any:
            radian = self._is_radian if is_radian is None else bool(is_radian)
            angles = [a if radian else math.degrees(a) for a in self._joints]
            if servo_id is None or servo_id == 8:
                return angles
            return angles[int(servo_id) - 1]

        return self._get("get_servo_angle", (), {"servo_id": servo_id, "is_radian": is_radian}, op)

    # -- gripper --------------------------------------------------------------------------------------

    def set_gripper_mode(self, mode: int, **kwargs: Any) -> int:
        def op() -> int:
            if mode != 0:
                return PARAM_ERROR
            self._gripper_mode = 0
            return 0

        return self._set("set_gripper_mode", (mode,), {}, op)

    def set_gripper_enable(self, enable: bool, **kwargs: Any) -> int:
        def op() -> int:
            self._gripper_enabled = bool(enable)
            return 0

        return self._set("set_gripper_enable", (enable,), {}, op)

    def set_gripper_speed(self, speed: float, **kwargs: Any) -> int:
        def op() -> int:
            if not (isinstance(speed, (int, float)) and 1 <= speed <= 5000):
                return PARAM_ERROR
            self._gripper_speed = float(speed)
            return 0

        return self._set("set_gripper_speed", (speed,), {}, op)

    def set_gripper_position(self, pos: float, wait: bool = False, speed: float | None = None,
                             auto_enable: bool = False, timeout: float | None = None, **kwargs: Any) -> int:
        def op() -> int:
            if not (isinstance(pos, (int, float)) and math.isfinite(pos) and GRIPPER_CLOSED <= pos <= GRIPPER_OPEN):
                return PARAM_ERROR
            if self._gripper_mode != 0:
                return PARAM_ERROR
            if auto_enable:
                self._gripper_enabled = True
            if not self._gripper_enabled:
                return END_EFFECTOR_NOT_ENABLED
            if self._gripper_error:
                return END_EFFECTOR_HAS_FAULT
            self._gripper_pos = float(pos)
            return 0

        return self._set("set_gripper_position", (pos,), {"wait": wait, "auto_enable": auto_enable}, op)

    def get_gripper_position(self, **kwargs: Any) -> tuple[int, float | None]:
        return self._get("get_gripper_position", (), {}, lambda: self._gripper_pos)

    def get_gripper_err_code(self, **kwargs: Any) -> tuple[int, int | None]:
        return self._get("get_gripper_err_code", (), {}, lambda: self._gripper_error)

    def clean_gripper_error(self, **kwargs: Any) -> int:
        def op() -> int:
            self._gripper_error = 0
            return 0

        return self._set("clean_gripper_error", (), {}, op)

    # -- controller limits (rule 11) ------------------------------------------------------------------

    def set_reduced_mode(self, on: bool) -> int:
        def op() -> int:
            self._reduced = bool(on)
            if self._reduced:  # the speed and boundary set since take effect now
                self._active_speed, self._active_boundary = self._tcp_speed, self._boundary
            return 0

        return self._set("set_reduced_mode", (on,), {}, op)

    def set_reduced_max_tcp_speed(self, speed: float) -> int:
        def op() -> int:
            if not (isinstance(speed, (int, float)) and math.isfinite(speed) and speed > 0):
                return PARAM_ERROR
            self._tcp_speed = float(np.float32(speed))
            return 0

        return self._set("set_reduced_max_tcp_speed", (speed,), {}, op)

    def set_reduced_tcp_boundary(self, boundary: Sequence[float]) -> int:
        if len(boundary) < 6:
            raise AssertionError("boundary needs 6 values")  # the SDK asserts len >= 6

        def op() -> int:
            try:
                b = [int(v) for v in boundary[:6]]
            except (TypeError, ValueError, OverflowError):
                return PARAM_ERROR
            if any(not -32768 <= v <= 32767 for v in b):
                return PARAM_ERROR
            for i in (0, 2, 4):  # max first, as the SDK reorders
                if b[i] < b[i + 1]:
                    b[i], b[i + 1] = b[i + 1], b[i]
            self._boundary = tuple(b)
            return 0

        return self._set("set_reduced_tcp_boundary", (list(boundary),), {}, op)

    def set_fence_mode(self, on: bool) -> list[int] | int:
        """``[0]`` on success (the SDK returns the reply list); a failure's code as an int."""

        def op() -> list[int]:
            self._fence = bool(on)
            return [0]

        return self._set("set_fence_mode", (on,), {}, op)

    set_fense_mode = set_fence_mode  # the SDK's old spelling

    def set_collision_sensitivity(self, value: int, wait: bool = True) -> int:
        assert isinstance(value, int) and 0 <= value <= 5  # as the SDK checks

        def op() -> int:
            self._sensitivity = value
            if not self._error and self._enabled:  # the SDK ends with set_state(0)
                self._ready, self._paused = True, False
            return 0

        return self._set("set_collision_sensitivity", (value,), {}, op)

    def set_self_collision_detection(self, on_off: bool) -> int:
        def op() -> int:
            self._self_collision = bool(on_off)
            return 0

        return self._set("set_self_collision_detection", (on_off,), {}, op)

    def get_reduced_mode(self) -> tuple[int, int | None]:
        return self._get("get_reduced_mode", (), {}, lambda: int(self._reduced))

    def get_reduced_states(self, is_radian: bool | None = None) -> tuple[int, list | None]:
        def op() -> list:
            joint_speed = math.pi if (self._is_radian if is_radian is None else is_radian) else 180.0
            return [int(self._reduced), list(self._boundary), self._tcp_speed, joint_speed, [0.0] * 14,
                    int(self._fence), 0]

        return self._get("get_reduced_states", (), {"is_radian": is_radian}, op)

    # -- internals ------------------------------------------------------------------------------------

    def _set(self, name: str, args: tuple, kwargs: dict, op: Callable[[], Any]) -> Any:
        """Run a setter: hang and connection rules first, then ``op`` under the lock; log the result."""
        return self._run(name, args, kwargs, op, getter=False)

    def _get(self, name: str, args: tuple, kwargs: dict, op: Callable[[], Any]) -> tuple[int, Any]:
        return self._run(name, args, kwargs, op, getter=True)

    def _run(self, name: str, args: tuple, kwargs: dict, op: Callable[[], Any], getter: bool) -> Any:
        with self._lock:
            hang_left = self._hang_until - time.monotonic()
        if hang_left > 0:
            with self._lock:
                self._blocked += 1
                self._log_cv.notify_all()
            try:
                self._hang_release.wait(hang_left)
            finally:
                with self._lock:
                    self._blocked -= 1
                    result: Any = (REPLY_TIMEOUT, None) if getter else REPLY_TIMEOUT
                    self._log(name, args, kwargs, result)
            return result
        with self._lock:
            if not self._connected:
                result = (NOT_CONNECTED, None) if getter else NOT_CONNECTED
            else:
                self._advance()
                value = op()
                result = (0, value) if getter else value
            self._log(name, args, kwargs, result)
        self._flush()
        return result

    def _log(self, name: str, args: tuple, kwargs: dict, result: Any) -> None:
        self._calls.append(Call(self._clock(), name, args, dict(kwargs), result))
        self._log_cv.notify_all()

    def _advance(self) -> None:
        """Integrate the commanded twist from the last update to now, stopping at its expiry, or where the
        TCP reaches the boundary with the fence on (error 35, rule 11)."""
        now = self._clock()
        end = min(now, self._expiry)
        dt = end - self._t
        if dt > 0 and np.any(self._speed):
            hit = self._boundary_time(dt) if self._fence else math.inf
            self._pos_mm, self._quat = integrate_pose(self._pos_mm, self._quat, self._speed, min(dt, hit))
            if hit <= dt:
                self._t = now
                self._raise(BOUNDARY_ERROR, at=self._t - dt + hit)
                return
        self._t = now
        if now >= self._expiry:
            self._stop(at=self._expiry)
        if self._fence and not self._error and self._outside():
            self._raise(BOUNDARY_ERROR)

    def _box(self) -> tuple[FloatArray, FloatArray]:
        b = self._active_boundary
        return np.array([b[1], b[3], b[5]], dtype=float), np.array([b[0], b[2], b[4]], dtype=float)

    def _outside(self) -> bool:
        lo, hi = self._box()
        return bool(np.any(self._pos_mm < lo) or np.any(self._pos_mm > hi))

    def _boundary_time(self, dt: float) -> float:
        """When (s from the last update) the TCP, moving at the linear speed in force, reaches the boundary
        (``inf``: not within ``dt``). The position moves linearly in the base frame."""
        lo, hi = self._box()
        v, p = self._speed[:3], self._pos_mm
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(v > 0, (hi - p) / v, np.where(v < 0, (lo - p) / v, np.inf))
        first = float(np.min(np.maximum(t, 0.0)))
        return first if first <= dt else math.inf

    def _raise(self, code: int, at: float | None = None) -> None:
        """A controller error (caller holds the lock): mode 0 / state 4, motion disabled, speed zero; its
        callback is queued for :meth:`_flush`."""
        self._error = int(code)
        self._mode, self._ready, self._enabled = 0, False, False
        self._stop(at=at)
        if self._connected:
            self._pending.append(self._err_payload())

    def _now(self, read: Callable[[], Any]) -> Any:
        """``read()`` of the controller as it is now: the motion advanced to the clock first (which may
        raise an error whose callback then fires, outside the lock)."""
        with self._lock:
            self._advance()
            value = read()
        self._flush()
        return value

    def _flush(self) -> None:
        """Fire the error callbacks queued under the lock, outside it."""
        with self._lock:
            pending, self._pending = self._pending, []
        for payload in pending:
            self._fire(self._error_cbs, payload)

    def _stop(self, at: float | None = None) -> None:
        if np.any(self._speed) or self._stopped_since is None:
            self._stopped_since = self._clock() if at is None else at
        self._speed = np.zeros(6)
        self._expiry = math.inf

    def _state_code(self) -> int:
        if self._ready and self._enabled and not self._error:
            if self._paused:
                return STATE_PAUSED
            return STATE_MOVING if np.any(self._speed) else STATE_READY
        return STATE_STOPPED

    def _err_payload(self) -> dict:
        return {"error_code": self._error, "warn_code": self._warn}

    def _register(self, cbs: list[Callback], callback: Callback | None) -> bool:
        if callback is None:
            return False
        with self._lock:
            if callback not in cbs:
                cbs.append(callback)
        return True

    def _release(self, cbs: list[Callback], callback: Callback | None) -> bool:
        with self._lock:
            if callback is None:
                cbs.clear()
            elif callback in cbs:
                cbs.remove(callback)
        return True

    def _fire(self, cbs: list[Callback], payload: dict) -> None:
        with self._lock:
            targets = list(cbs)
        for cb in targets:
            cb(dict(payload))
