"""What a person answers to a question, as arrays over (question ``q``, goal ``g``): section III-C's
observation model for the searches (the commit model's :mod:`.problem`, the watch model's :mod:`.watch`).

A question names a high-level target (object, grasp type); goal ``g`` is in it or not. With ``p =
intent.answer_p_correct`` (the paper's 0.999):

    L_yes[q, g] = P(yes | g) = p if g is in q's target, else 1 - p

With ``asking.third_answer`` a person may also answer "that object, another grasp" (:class:`ThirdAnswer`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..geometry import FloatArray
from ..model.actions import Action
from ..world.goals import target_object
from ..world.goalset import GoalSet


def in_target(questions: Sequence[Action], goals: GoalSet) -> np.ndarray:
    """``(Q, G)``: goal ``g`` is in the target question ``q`` names (:meth:`GoalSet.target_mask`)."""
    return np.array([goals.target_mask(q.target) for q in questions], dtype=bool).reshape(len(questions), len(goals))


def yes_likelihood(questions: Sequence[Action], goals: GoalSet, p: float) -> FloatArray:
    """``L_yes`` ``(Q, G)`` of the module doc."""
    return np.where(in_target(questions, goals), p, 1.0 - p)


@dataclass(frozen=True)
class ThirdAnswer:
    """The answers yes, no and "that object, another grasp" (``asking.third_answer``; ``docs/model.md``):
    a person whose goal is on the asked object but of another grasp type answers "other" with ``p``; a
    wrong answer is one of the other two, equally. Arrays are ``(Q, G)``."""

    asked: np.ndarray
    """Goal ``g`` is in the asked target."""
    siblings: np.ndarray
    """Goal ``g`` is on the asked object, of another grasp type."""
    P_yes: FloatArray
    P_no: FloatArray
    P_other: FloatArray
    equal_share: FloatArray
    """Where the object's other targets hold no probability: each sibling goal's share of the asked
    target's (equal per target, then per goal of it)."""

    @classmethod
    def of(cls, questions: Sequence[Action], goals: GoalSet, p: float) -> ThirdAnswer:
        asked = in_target(questions, goals)
        qobj = np.array([target_object(q.target) for q in questions])
        gobj = np.array([g.object for g in goals.goals])
        sib = (qobj[:, None] == gobj[None, :]) & ~asked
        has_sib = sib.any(axis=1)[:, None]
        wrong = np.where(has_sib, (1.0 - p) / 2.0, 1.0 - p)  # a wrong answer, one of the others
        P_yes = np.where(asked, p, wrong)
        P_other = np.where(has_sib, np.where(sib, p, wrong), 0.0)
        counts = np.bincount(goals.target_index, minlength=len(goals.targets))[goals.target_index]
        n_sib = np.array([len(set(goals.target_index[row])) for row in sib])
        share = np.where(sib, 1.0 / np.maximum(n_sib[:, None] * counts[None, :], 1), 0.0)
        return cls(asked, sib, P_yes, 1.0 - P_yes - P_other, P_other, share)

    def other_grasp(self, B: FloatArray, q: np.ndarray) -> FloatArray:
        """The tracker's belief after "that object, another grasp" to question ``q[k]`` (per row ``k`` of
        ``B``): the asked target's probability goes to the object's other targets, in proportion to theirs
        (equally where they have none); other objects keep theirs (``Belief.after_other_grasp``)."""
        A, S = self.asked[q], self.siblings[q]
        m_asked = np.einsum("kg,kg->k", B, A)
        m_sib = np.einsum("kg,kg->k", B, S)
        with np.errstate(divide="ignore", invalid="ignore"):
            scaled = np.where(S, B * (1.0 + m_asked / m_sib)[:, None], B)
        equal = B + m_asked[:, None] * self.equal_share[q]
        return np.where(A, 0.0, np.where((m_sib > 0.0)[:, None], scaled, equal))
