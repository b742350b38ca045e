"""What the controller hands out: the adopted plan, the pending question, one control period's output.

Plain frozen values, so the daemon's view and the evaluation can hold them without touching the
controller (``control/controller.py``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..model.actions import NO_ASSIST, Action
from ..model.model import Command
from ..world.goalset import GoalSet
from .safety import SafetyResult

ZERO6 = np.zeros(6)


class NoQuestion(ValueError):
    """An answer arrived while no question is pending."""


@dataclass(frozen=True)
class Plan:
    """An adopted action, the goal set its ``goal`` index refers to, and when it expires (s): a late
    planner leaves the arm on no-assist instead of an old move."""

    action: Action
    goals: GoalSet
    until: float


@dataclass(frozen=True)
class Question:
    """The pending question about ``target``, asked at ``asked_at`` (s); ``qid`` numbers the questions so
    that a late answer to one cannot answer the next."""

    target: str
    asked_at: float
    qid: int


def answer_word(answer: bool | str) -> str:
    """An answer as events and records spell it: ``"yes"`` (``True`` or ``"yes"``), ``"other"`` (that
    object, another grasp), else ``"no"`` (what :meth:`~.controller.Controller.on_answer` reads it as)."""
    return answer if answer == "other" else ("yes" if answer in (True, "yes") else "no")


@dataclass(frozen=True)
class Tick:
    """One control period's output: the model's blended command, what the safety pipeline made of it
    (``safety.twist`` is what the arm gets), whether the user's input was fresh, and the error text when
    the command could not be computed (the arm then gets the user's twist alone, filtered)."""

    command: Command
    safety: SafetyResult
    fresh: bool
    error: str | None = None

    @property
    def refused(self) -> bool:
        """The pipeline halted a command that asked for motion (what a UI shows as 'blocked')."""
        return self.safety.refuses(self.command.total_twist)


IDLE_TICK = Tick(Command(NO_ASSIST, ZERO6.copy(), ZERO6.copy(), False), SafetyResult(ZERO6.copy(), ()), False)
