"""What a daemon is asked to run: the plain options the composition root (``launch.py``) fills from the
command line and the configuration."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from ..world.scene import Scene


@dataclass
class RunOptions:
    """What ``sa-daemon run`` was asked to do (CLI flags over config)."""

    scene: Scene
    arm: str = "kinematic"
    input: str = "sim"
    tasks: list[str] = field(default_factory=list)
    method: str = "policy"
    pub: str = "tcp://127.0.0.1:5555"
    cmd: str = "tcp://127.0.0.1:5556"
    duration_s: float | None = None
    record: str | None = None
    seed: int = 0
    progress: bool = False
    #: With the simulated user and no duration: stop once every task has been done once.
    exit_when_done: bool = True
    #: The person's profile in force (name, file, the keys it set), or ``None``.
    profile: dict | None = None
    #: The configuration without a person's profile (what ``set_profile`` applies a profile over).
    base_config: Any = None
