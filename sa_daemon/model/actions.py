"""The POMDP's high-level actions (section III-B): move toward a goal, HO assistance, no assistance, ask
about a target. Their velocity generators are in :mod:`.twists`; the joystick's two modes are here too."""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum


class ActionKind(str, Enum):
    MOVE = "move"
    HO = "ho"
    NONE = "none"
    QUESTION = "question"


class Mode(str, Enum):
    """Joystick mode: the 3 axes drive either translation or rotation."""

    TRANSLATION = "translation"
    ROTATION = "rotation"


@dataclass(frozen=True)
class Action:
    """A high-level action. ``goal`` indexes the goal set for moves; ``target`` names the high-level
    target of a move or a question."""

    kind: ActionKind
    goal: int | None = None
    target: str | None = None

    @property
    def label(self) -> str:
        """Short human form: ``move cup:top``, ``ho``, ``none``, ``ask cup:top``."""
        if self.kind is ActionKind.MOVE:
            return f"move {self.target}"
        if self.kind is ActionKind.QUESTION:
            return f"ask {self.target}"
        return self.kind.value

    def to_dict(self) -> dict:
        d: dict = {"kind": self.kind.value}
        if self.target is not None:
            d["goal"] = self.target
        if self.goal is not None:
            d["goal_index"] = self.goal
        return d


NO_ASSIST = Action(ActionKind.NONE)
HO_ACTION = Action(ActionKind.HO)
