"""Build an arm by its backend name (``backends.py`` is the registry)."""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

from .backends import backend

if TYPE_CHECKING:
    from ..config import Config
    from ..world.scene import Scene
    from .base import Arm


def make_arm(name: str, scene: Scene, cfg: Config) -> Arm:
    """A fresh arm of backend ``name`` holding the TCP at ``scene.start`` (simulated arms); raises
    ``ValueError`` for an unknown backend."""
    module, _, cls = backend(name).arm_class.partition(":")
    return getattr(importlib.import_module(module), cls).from_config(scene, cfg)
