"""Optional extras (``pyproject.toml``): import what one brings, or say in one line which to install.

Every feature that lives in an extra imports it through :func:`require`, so a missing extra is one
clear error naming the extra and the pip command, never a ``ModuleNotFoundError`` traceback.
"""

from __future__ import annotations

import importlib
from types import ModuleType

#: extra -> (the pip distributions it brings, what needs it)
EXTRAS: dict[str, tuple[str, str]] = {
    "bench": ("pomdp-py", "the pomdp_py peer of `bench planner`"),
    "xarm": ("xarm-python-sdk", 'arm.backend "xarm" (--arm xarm)'),
    "voice": ("pocketsphinx", "answers by voice (`[voice]`, `hear`, `bench voice`)"),
    "ray": ("ray", "`eval --backend ray`"),
}


class MissingExtra(ImportError):
    """An optional extra is not installed; the message names it and the command that installs it."""


def require(module: str, extra: str) -> ModuleType:
    """``import module``, or :class:`MissingExtra` naming ``extra``."""
    try:
        return importlib.import_module(module)
    except ImportError as e:
        dists, what = EXTRAS[extra]
        raise MissingExtra(
            f"{what} needs the '{extra}' extra: pip install 'sa-daemon[{extra}]' (brings {dists}; "
            f"from a checkout: pip install -e '.[{extra}]'); import {module} failed: {e}"
        ) from e
