"""``sa-daemon run --arm xarm --check``: the installer's check of the real arm, without moving it.

Connects, reads the firmware and the controller's error, sets (``arm.xarm.controller_limits = "set"``) or
only reads (``"verify"``) the controller's own limits (``xarm_limits.py``) and compares them with config,
reads the TCP pose and checks it lies in the safety workspace, then disconnects. It never enables
motion: no ``motion_enable``, ``set_mode``, ``set_state`` or velocity command. Every step is one line
of a pass/fail list (:func:`run_check`); the command exits 0 only if all pass.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..config import Config
from .xarm_limits import apply_limits, compare, expected_limits, read_limits
from .xarm_sdk import error_text, firmware_of, pose_from_sdk, sdk_factory


@dataclass(frozen=True)
class CheckItem:
    """One line of the check: what was checked, whether it passed, and the values behind it."""

    name: str
    ok: bool
    detail: str

    def line(self) -> str:
        return f"{'PASS' if self.ok else 'FAIL'}  {self.name:<26} {self.detail}"


def run_check(cfg: Config, api_factory: Callable[[], Any] | None = None) -> list[CheckItem]:
    """Every check of the module doc, in order; stops after the connection if there is none."""
    xc = cfg.arm.xarm
    api = (api_factory or sdk_factory(xc.ip, xc.sdk))()
    items: list[CheckItem] = []
    try:
        api.connect()
    except Exception as e:  # noqa: BLE001 - the SDK raises socket errors of any type
        return [CheckItem("connection", False, f"{xc.ip}: {type(e).__name__}: {e}")]
    if not api.connected:
        return [CheckItem("connection", False, f"{xc.ip}: not connected")]
    try:
        items.append(CheckItem("connection", True, xc.ip))
        version, problem = firmware_of(api)
        items.append(CheckItem("firmware >= 1.8.0", problem is None and version is not None,
                               problem or (version or "unreadable")))
        code, ew = api.get_err_warn_code()
        err = int(ew[0]) if code == 0 and ew else None
        items.append(CheckItem("no controller error", err == 0,
                               "none" if err == 0 else (error_text(err) if err else f"unreadable (code {code})")))
        want = expected_limits(cfg)

        def call(name: str, *args: Any) -> Any:
            return getattr(api, name)(*args)

        if xc.controller_limits == "set":
            failed = apply_limits(call, want)
            items.append(CheckItem("controller limits set", not failed, "; ".join(failed) or "every setter returned 0"))
        actual = read_limits(call, lambda name: getattr(api, name, None))
        bad = {m.name: m for m in compare(want, actual)}
        for name, expected in want.items():
            items.append(CheckItem(name, name not in bad, f"controller {actual[name]!r}, expected {expected!r}"))
        items.append(_pose_item(api, cfg))
    finally:
        try:
            api.disconnect()
        except Exception:  # noqa: BLE001, S110 - the check's result stands either way
            pass
    return items


def _pose_item(api: Any, cfg: Config) -> CheckItem:
    code, pos = api.get_position(is_radian=True)
    if code != 0 or pos is None:
        return CheckItem("TCP in the workspace", False, f"get_position returned code {code}")
    p = pose_from_sdk(pos).position
    lo, hi = np.asarray(cfg.safety.workspace_min_m), np.asarray(cfg.safety.workspace_max_m)
    inside = bool(np.all(p >= lo) and np.all(p <= hi))
    def fmt(v: np.ndarray) -> str:
        return "(" + ", ".join(f"{x:.3f}" for x in v) + ")"

    return CheckItem("TCP in the workspace", inside, f"TCP at {fmt(p)} m; box {fmt(lo)} .. {fmt(hi)} m")


def format_check(items: list[CheckItem]) -> str:
    passed = sum(i.ok for i in items)
    verdict = "all checks passed" if passed == len(items) else f"{len(items) - passed} of {len(items)} checks FAILED"
    return "\n".join([*(i.line() for i in items), verdict])
