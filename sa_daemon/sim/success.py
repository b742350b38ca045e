"""Success as the paper counts it (section VI): the intended grasp type, closed at a pose from which the
object is held, within the time limit.

On an arm with physics (``lift_test``, the MuJoCo arm) the gripper must then lift the task's object; on
the kinematic arm the geometric rule of :mod:`~..world.holding` stands in for the lift. Either way the
closed pose must be of the task's grasp type. A user who closes too early (``hasty``) fails here, even
though it closed where it meant to.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..arm.base import Arm
from ..geometry import Pose
from ..world.holding import HOLD_FAILURES, WRONG_TYPE, holds
from ..world.scene import Scene, SceneObject


@dataclass(frozen=True)
class Outcome:
    """``success`` and, for a failure, why: ``kind`` (one of :data:`FAILURES`, for counting) and ``reason``
    (with its numbers, for reading: ``the TCP is 0.012 m outside the object``). ``rule_held``: where a
    lift decided, whether the geometric rule (the kinematic arm's stand-in for the lift) holds the same
    close, so every physics run measures the rule; ``None`` where the rule itself decided or nothing
    closed."""

    success: bool
    reason: str = ""
    kind: str = ""
    rule_held: bool | None = None


TIMEOUT = "timeout"
NOT_LIFTED = "not lifted"
FAILURES = (TIMEOUT, *HOLD_FAILURES, NOT_LIFTED)
"""Every ``Outcome.kind`` of a failed trial."""


def scene_object(scene: Scene, name: str) -> SceneObject:
    for o in scene.objects:
        if o.name == name:
            return o
    raise KeyError(f"scene {scene.name!r} has no object {name!r}")


def grasp_outcome(scene: Scene, task: str, closed_at: Pose | None, arm: Arm | None = None) -> Outcome:
    """The outcome of a trial of ``task`` whose gripper closed at ``closed_at`` (``None``: it never closed,
    the time ran out). ``arm``: lifted with its ``lift_test`` if it has one (call it when the trial is over:
    it moves the arm)."""
    if closed_at is None:
        return Outcome(False, "timeout", TIMEOUT)
    goal = scene.goal(task)
    verdict = holds(scene_object(scene, goal.object), closed_at, goal.grasp_type)
    lift_test = getattr(arm, "lift_test", None)
    if not callable(lift_test):
        return Outcome(verdict.held, verdict.reason, verdict.kind)
    if verdict.kind == WRONG_TYPE:  # physics cannot tell a side grasp from a top grasp
        return Outcome(False, verdict.reason, verdict.kind)
    lifted = lift_test()
    if lifted != goal.object:
        return Outcome(False, f"the lift test raised {lifted or 'nothing'}, not the {goal.object}", NOT_LIFTED,
                       rule_held=verdict.held)
    return Outcome(True, rule_held=verdict.held)
