"""The watch model's tree at one snapshot as plain data: what another planner needs to plan the same model.

:meth:`~.watch.WatchSearch.tree` searches a snapshot exhaustively and writes down every number its root
decision rests on; a planner that knows nothing of rollouts or trackers (``bench/peer.py``, pomdp_py's
POUCT) then plans the same problem, and :func:`exact_values` solves it by plain recursion, the reference
the tests hold the search to. With ``G`` goals, ``A`` commits (``moves``) and ``Q`` questions:

* the state is the goal ``g`` the user wants, drawn from ``b`` (``G,``), and the answers so far; a node with
  ``d`` answers has ``s = n - d n_q`` rollout steps left;
* a commit ``a`` ends the episode with the return ``value[g, a, s]`` (the motion over the ``s`` steps left,
  the charge for the last pose included);
* a question ``q`` returns ``question_cost[g]`` (the paper's ``-5`` plus the arm standing still for
  ``n_q`` steps), then the person answers yes with ``L_yes[q, g]``; it may be asked only where ``open``
  lists it for the node (``planner.question_gate``, the depth limits); with ``s = n_q`` nothing can be done
  after the answer and the question ends the episode with ``last_question[g]``;
* a watch of motion ``w`` (root only) ends the episode with ``watches[w][g]``: the watched steps' return
  plus what the tracker's pick after the predicted input earns for ``g`` (``docs/model.md``, "No pomdp_py
  peer" has why it is a terminal payoff and not a belief update). A goal outside the watch's branches is
  paid the watch's value itself, so that ``b . watches[w]`` is that value (``planner.watch_branches``).

A motion's value is the better of its commit and its watch (:func:`~.watch.plan_watch`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..geometry import FloatArray
from ..model.actions import Action

NodeKey = tuple[int, frozenset[int], frozenset[int]]
"""A node of the question tree: (rollout steps left, questions asked, questions answered yes)."""


@dataclass(frozen=True, eq=False)
class WatchTree:
    """One snapshot's watch-model problem (module doc). Arrays are read-only; returns are undiscounted."""

    moves: tuple[Action, ...]
    questions: tuple[Action, ...]
    b: FloatArray
    value: FloatArray
    """``(G, A, n + 1)``: ``value[g, a, s]``, a commit's return with ``s`` steps left."""
    question_cost: FloatArray
    last_question: FloatArray
    L_yes: FloatArray
    n: int
    n_q: int
    open: dict[NodeKey, frozenset[int]]
    """The questions each node may ask (a node not listed: none)."""
    watches: dict[int, FloatArray]
    """Per watched motion (its index in ``moves``): the payoff of watching it, ``(G,)``."""

    @staticmethod
    def key(steps: int, answers: frozenset[tuple[int, bool]]) -> NodeKey:
        """The key of the node reached by ``answers`` (``(question, yes)`` pairs) with ``steps`` left."""
        return steps, frozenset(q for q, _ in answers), frozenset(q for q, yes in answers if yes)

    def steps_left(self, answers: frozenset[tuple[int, bool]]) -> int:
        """Rollout steps left after ``answers``."""
        return self.n - len(answers) * self.n_q

    def open_questions(self, answers: frozenset[tuple[int, bool]]) -> frozenset[int]:
        """The questions the node reached by ``answers`` may ask."""
        return self.open.get(self.key(self.steps_left(answers), answers), frozenset())


def exact_values(tree: WatchTree) -> dict[Action, float]:
    """Every root action's value by plain recursion over ``tree`` (Bayes over the answers, the best action
    at every node): the reference :meth:`~.watch.WatchSearch` is tested against. A motion's value is the
    better of its commit and its watch, as the planner reports it."""

    def node(belief: list[float], answers: frozenset[tuple[int, bool]]) -> tuple[float, list[float]]:
        """(value, value vector over goals) of the best action at a node with ``belief`` (unnormalised)."""
        s = tree.steps_left(answers)
        total = sum(belief)
        best, best_vec = -math.inf, [0.0] * len(belief)
        for a in range(len(tree.moves)):
            vec = [float(tree.value[g, a, s]) for g in range(len(belief))]
            v = sum(p * x for p, x in zip(belief, vec, strict=True)) / total
            if v > best:
                best, best_vec = v, vec
        for q in sorted(tree.open_questions(answers)):
            vec = question(belief, answers, q)
            v = sum(p * x for p, x in zip(belief, vec, strict=True)) / total
            if v > best:
                best, best_vec = v, vec
        return best, best_vec

    def question(belief: list[float], answers: frozenset[tuple[int, bool]], q: int) -> list[float]:
        """Question ``q``'s value vector over goals at a node."""
        if tree.steps_left(answers) == tree.n_q:
            return [float(x) for x in tree.last_question]
        like = [float(x) for x in tree.L_yes[q]]
        vec = [float(x) for x in tree.question_cost]
        for yes in (True, False):
            p_ans = like if yes else [1.0 - x for x in like]
            child = [p * x for p, x in zip(belief, p_ans, strict=True)]
            if sum(child) <= 0.0:
                continue
            _, child_vec = node(child, answers | {(q, yes)})
            vec = [v + pa * c for v, pa, c in zip(vec, p_ans, child_vec, strict=True)]
        return vec

    b = [float(x) for x in tree.b]
    out: dict[Action, float] = {}
    for a, action in enumerate(tree.moves):
        out[action] = sum(p * float(tree.value[g, a, tree.n]) for g, p in enumerate(b))
    for q in sorted(tree.open_questions(frozenset())):
        out[tree.questions[q]] = sum(p * x for p, x in zip(b, question(b, frozenset(), q), strict=True))
    for w, vec in tree.watches.items():
        out[tree.moves[w]] = max(out[tree.moves[w]], sum(p * float(x) for p, x in zip(b, vec, strict=True)))
    return out
