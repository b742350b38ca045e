"""The xArm controller's own limits: what config asks of them, how they are set, read back and compared.

The controller's limits act even when the daemon misbehaves; the safety pipeline (``control/safety.py``)
is the stricter layer on top (``docs/safety.md``, "Layers of protection"). Settings, SDK calls and units
(xArm Python SDK, ``doc/api/xarm_api.md``; ``docs/xarm.md`` cites each fact):

=====================  =================================================  ==========================================
setting                set with                                           read back with
=====================  =================================================  ==========================================
reduced mode           ``set_reduced_mode(True)``                         ``get_reduced_states()[0]``
reduced TCP speed      ``set_reduced_max_tcp_speed(mm/s)``                ``get_reduced_states()[2]`` (mm/s)
TCP boundary           ``set_reduced_tcp_boundary([x+, x-, y+, y-, z+,    ``get_reduced_states()[1]`` (mm, int16)
                       z-])`` (mm, integers, base frame)
boundary switch        ``set_fence_mode(True)``                           ``get_reduced_states()[5]``
collision sensitivity  ``set_collision_sensitivity(1..5)``                property ``collision_sensitivity``
self-collision         ``set_self_collision_detection(True)``             property ``self_collision_params[0]``
=====================  =================================================  ==========================================

The SDK documents that a new reduced TCP speed or boundary "takes effect" when reduced mode is switched on
again, so ``set_reduced_mode(True)`` comes after them. ``set_fence_mode`` returns its reply as a list
(``[code]``) although documented as a code; :func:`code_of` accepts both. Settings made here are not saved
(``save_conf``): they are set again on every connect and recovery.

The boundary is the pipeline's workspace box (``safety.workspace_*_m``) grown by
``arm.xarm.fence_margin_m`` on every side and rounded outward to whole mm, so the pipeline, which never
lets the TCP leave its box, stops first; the reduced TCP speed is ``limits.tcp_mps``, the norm the
pipeline's speed stage enforces, so no command the pipeline passes exceeds it.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from ..config import Config

#: Tolerance of a read-back TCP speed (mm/s): the controller stores it as a 32-bit float.
SPEED_TOLERANCE_MM_S = 0.01

#: The settings by name, in the order they are reported.
SETTINGS = ("reduced_mode", "reduced_tcp_speed_mm_s", "tcp_boundary_mm", "fence_mode", "collision_sensitivity",
            "self_collision_detection")


@dataclass(frozen=True)
class ControllerLimits:
    """The controller settings config asks for (SDK units: mm, mm/s)."""

    reduced_mode: bool
    tcp_speed_mm_s: float
    boundary_mm: tuple[int, int, int, int, int, int]  # x_max, x_min, y_max, y_min, z_max, z_min
    fence: bool
    collision_sensitivity: int
    self_collision: bool

    def items(self) -> list[tuple[str, Any]]:
        """``(name, expected value)`` for every name of :data:`SETTINGS`."""
        values = (self.reduced_mode, self.tcp_speed_mm_s, list(self.boundary_mm), self.fence,
                  self.collision_sensitivity, self.self_collision)
        return list(zip(SETTINGS, values, strict=True))


@dataclass(frozen=True)
class Mismatch:
    """One controller setting that is not what config asks: its name, its value on the controller
    (``None``: unreadable) and the expected value."""

    name: str
    actual: Any
    expected: Any

    def __str__(self) -> str:
        return f"{self.name}: controller {self.actual!r}, expected {self.expected!r}"


def expected_limits(cfg: Config) -> ControllerLimits:
    """The settings of the module doc from ``[limits]``, ``[safety]`` and ``[arm.xarm]``."""
    m = cfg.arm.xarm.fence_margin_m
    # outward to whole mm (rounded to a nanometre first, so 0.82 m is 820 mm, not 821)
    lo = [math.floor(round((v - m) * 1000.0, 6)) for v in cfg.safety.workspace_min_m]
    hi = [math.ceil(round((v + m) * 1000.0, 6)) for v in cfg.safety.workspace_max_m]
    boundary = (hi[0], lo[0], hi[1], lo[1], hi[2], lo[2])
    return ControllerLimits(
        reduced_mode=True,
        tcp_speed_mm_s=round(cfg.limits.tcp_mps * 1000.0, 3),
        boundary_mm=boundary,  # type: ignore[arg-type]
        fence=True,
        collision_sensitivity=cfg.arm.xarm.collision_sensitivity,
        self_collision=True,
    )


def code_of(ret: Any) -> int:
    """The return code of an SDK setter: an int, or the first element of a reply list."""
    if isinstance(ret, (list, tuple)):
        return int(ret[0]) if ret else -1
    return int(ret)


Call = Callable[..., Any]
"""``call(name, *args)``: one SDK call by method name (the driver's ``_call``, or a plain getattr)."""


def apply_limits(call: Call, want: ControllerLimits) -> list[str]:
    """Set every controller limit; returns a text per setter that did not return 0 (empty: all did).
    Reduced mode is switched on last, after the values it takes effect with."""
    steps: list[tuple[str, tuple]] = [
        ("set_reduced_max_tcp_speed", (want.tcp_speed_mm_s,)),
        ("set_reduced_tcp_boundary", (list(want.boundary_mm),)),
        ("set_fence_mode", (want.fence,)),
        ("set_collision_sensitivity", (want.collision_sensitivity,)),
        ("set_self_collision_detection", (want.self_collision,)),
        ("set_reduced_mode", (want.reduced_mode,)),
    ]
    failed = []
    for name, args in steps:
        code = code_of(call(name, *args))
        if code != 0:
            failed.append(f"{name}{args!r} returned code {code}")
    return failed


def read_limits(call: Call, prop: Callable[[str], Any]) -> dict[str, Any]:
    """The controller's settings, by the names of :meth:`ControllerLimits.items` (``None``: unreadable).
    ``prop(name)`` reads an SDK property."""
    out: dict[str, Any] = dict.fromkeys(SETTINGS)
    code, states = call("get_reduced_states")
    if code == 0 and isinstance(states, (list, tuple)) and len(states) >= 6:
        out["reduced_mode"] = bool(states[0])
        out["tcp_boundary_mm"] = [int(v) for v in states[1]]
        out["reduced_tcp_speed_mm_s"] = float(states[2])
        out["fence_mode"] = bool(states[5])
    sensitivity = prop("collision_sensitivity")
    out["collision_sensitivity"] = int(sensitivity) if isinstance(sensitivity, int) else None
    params = prop("self_collision_params")
    out["self_collision_detection"] = bool(params[0]) if isinstance(params, (list, tuple)) and params else None
    return out


def compare(want: ControllerLimits, actual: dict[str, Any]) -> list[Mismatch]:
    """Each setting whose read-back value differs from config's (the speed within float32 rounding)."""
    out = []
    for name, expected in want.items():
        got = actual.get(name)
        if name == "reduced_tcp_speed_mm_s":
            same = got is not None and abs(got - expected) <= SPEED_TOLERANCE_MM_S
        else:
            same = got == expected
        if not same:
            out.append(Mismatch(name, got, expected))
    return out
