"""The xArm Python SDK's vocabulary, the one place the driver (``xarm_arm.py``) and the bring-up check
(``xarm_check.py``) take it from: return codes, controller error texts, gripper positions and modes,
the unit conversion at the SDK boundary (mm, mm/s and the SDK's angle flags here only; SI everywhere
else) and the factory of the SDK object (the real ``XArmAPI`` or the documented fake).

Every value is from the SDK's documentation (``shared/reference/xarm6.md``; docs/xarm.md).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from ..config import ConfigError
from ..extras import MissingExtra, require
from ..geometry import FloatArray, Pose

#: SDK return codes (shared/reference/xarm6.md).
CODE_NOT_CONNECTED = -1
CODE_HAS_ERROR = 1
CODE_REPLY_TIMEOUT = 3
CODE_NOT_READY = 9
#: Codes that mean the link is gone (or as good as gone): reconnect.
LINK_CODES = (CODE_NOT_CONNECTED, CODE_REPLY_TIMEOUT)

#: Velocity commands are accepted up to 250 Hz (reference); faster control loops are coalesced.
MAX_COMMAND_HZ = 250.0
#: ``duration`` of velocity commands needs controller firmware 1.8.0 (reference).
MIN_FIRMWARE = (1, 8, 0)
#: xArm gripper positions (reference): 0 closed, 850 fully open.
GRIPPER_CLOSED_POS = 0
GRIPPER_OPEN_POS = 850
#: Mode 5 = Cartesian velocity control; state 0 = "motion" (reference).
MODE_CARTESIAN_VELOCITY = 5
READY_STATES = (1, 2)  # get_state: 1 moving, 2 ready and idle; 3 paused, 4 stopped are not ready

#: Meanings of controller error codes (reference; wording of the SDK's controller error list).
CONTROLLER_ERRORS: dict[int, str] = {
    1: "emergency stop button on the control box pressed",
    2: "emergency stop input of the control box triggered",
    3: "emergency stop button of the three-state switch pressed",
    10: "servo motor error",
    **{10 + j: f"servo motor {j} error" for j in range(1, 7)},
    19: "end effector communication error",
    21: "kinematic error",
    22: "self collision",
    23: "joint limit",
    24: "speed limit",
    25: "planning error",
    28: "end module communication error",
    30: "feedback speed limit",
    31: "collision current",
    35: "safety boundary",
    38: "abnormal joint angle",
}

def error_text(code: int) -> str:
    """Fault text of a controller error, e.g. ``"xArm error 22: self collision"``."""
    return f"xArm error {code}: {CONTROLLER_ERRORS.get(code, 'controller error (see the SDK error list)')}"


def firmware_of(api: Any) -> tuple[str | None, str | None]:
    """``(version, problem)`` of the controller's firmware (``version_number``): the version as text
    (``None``: unreadable) and why it cannot be used (``None``: it can, or the version is unknown)."""
    try:
        v = tuple(int(x) for x in api.version_number)[:3]
    except (AttributeError, TypeError, ValueError):
        return None, None
    version = ".".join(str(x) for x in v)
    if not any(v) or v >= MIN_FIRMWARE:
        return version, None  # (0, 0, 0): unknown
    return version, f"xArm firmware {version} < 1.8.0: velocity commands would not time out"


def twist_to_speeds(twist: FloatArray) -> list[float]:
    """SDK ``speeds`` of a base-frame twist: ``[mm/s x3, rad/s x3]`` (m/s -> mm/s; rad/s kept)."""
    t = np.asarray(twist, dtype=float)
    return [float(v) for v in t[:3] * 1000.0] + [float(v) for v in t[3:]]


def pose_from_sdk(position: list[float]) -> Pose:
    """SI pose of ``get_position(is_radian=True)``: ``[x, y, z (mm), roll, pitch, yaw (rad)]``."""
    p = np.asarray(position, dtype=float)
    return Pose.from_rpy(p[:3] / 1000.0, p[3:6])


def sdk_factory(ip: str, sdk: str = "real") -> Callable[[], Any]:
    """``XArmAPI(ip, is_radian=True, do_not_open=True)``, imported lazily; with ``sdk = "fake"`` (config
    ``arm.xarm.sdk``) the documented fake, ``sa_daemon/testing/fake_xarm.py``."""
    if sdk == "fake":
        from ..testing.fake_xarm import FakeXArmAPI

        return lambda: FakeXArmAPI(ip, is_radian=True, do_not_open=True)
    try:
        sdk = require("xarm.wrapper", "xarm")
    except MissingExtra as e:  # a ConfigError: the message starts with the key, arm.backend
        raise ConfigError(str(e)) from e
    return lambda: sdk.XArmAPI(ip, is_radian=True, do_not_open=True)
