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
  plus what the tracker's picks after the predicted input (a continued watch among them, with
  ``planner.watch_levels = 2``) earn for ``g`` (``docs/model.md``, "A pomdp_py
  peer for it", has why it is a terminal payoff and not a belief update). ``b`` sums to 1 and
  ``b . watches[w]`` is the watch's value: with ``planner.watch_branches`` "top" or "all" a goal outside
  the watch's branches is paid that value itself; with "mapped" every goal ``b`` holds has its own return.

A motion's value is the better of its commit and its watch (:func:`~.watch.plan_watch`).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

from ..geometry import FloatArray
from ..model.actions import Action

NodeKey = tuple[int, frozenset[int], frozenset[int]]
"""A node of the question tree: (rollout steps left, questions asked, questions answered yes)."""
Answers = frozenset[tuple[int, bool]]
"""The answers a node was reached by: (question, yes) pairs."""


def node_key(steps: int, asked: Iterable[int], yes: Iterable[int]) -> NodeKey:
    """The key of the node with ``steps`` left after the questions ``asked``, ``yes`` those answered yes."""
    return steps, frozenset(asked), frozenset(yes)


@dataclass(frozen=True, eq=False)
class WatchTree:
    """One snapshot's watch-model problem (module doc); built by :meth:`~.watch.WatchSearch.tree`. Its arrays
    are read-only; returns are undiscounted."""

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
    askable: dict[NodeKey, frozenset[int]]
    """The questions each node of the question tree may ask (a node not listed: none)."""
    watches: dict[int, FloatArray]
    """Per watched motion (its index in ``moves``): the payoff of watching it, ``(G,)``."""

    def steps_left(self, answers: Answers) -> int:
        """Rollout steps left after ``answers``."""
        return self.n - len(answers) * self.n_q

    def open_questions(self, answers: Answers) -> frozenset[int]:
        """The questions the node reached by ``answers`` may ask."""
        key = node_key(self.steps_left(answers), (q for q, _ in answers), (q for q, yes in answers if yes))
        return self.askable.get(key, frozenset())


def exact_values(tree: WatchTree) -> dict[Action, float]:
    """Every root action's value by plain recursion over ``tree`` (Bayes over the answers, the best action
    at every node): the reference :class:`~.watch.WatchSearch` is tested against. A motion's value is the
    better of its commit and its watch, as the planner reports it."""
    goals = range(len(tree.b))

    def expected(belief: list[float], vec: list[float]) -> float:
        return sum(p * x for p, x in zip(belief, vec, strict=True)) / sum(belief)

    def commit(a: int, answers: Answers) -> list[float]:
        s = tree.steps_left(answers)
        return [float(tree.value[g, a, s]) for g in goals]

    def question(belief: list[float], answers: Answers, q: int) -> list[float]:
        """Question ``q``'s value vector over goals at a node (``belief`` unnormalised)."""
        if tree.steps_left(answers) == tree.n_q:
            return [float(x) for x in tree.last_question]
        vec = [float(x) for x in tree.question_cost]
        for yes in (True, False):
            like = [float(x) if yes else 1.0 - float(x) for x in tree.L_yes[q]]
            child = [p * x for p, x in zip(belief, like, strict=True)]
            after = best(child, answers | {(q, yes)})
            vec = [v + lk * c for v, lk, c in zip(vec, like, after, strict=True)]
        return vec

    def best(belief: list[float], answers: Answers) -> list[float]:
        """The value vector of the action best by ``belief`` at a node: the first commit of the largest
        value, a question only if strictly better (the search's tie-breaking)."""
        options = [commit(a, answers) for a in range(len(tree.moves))]
        options += [question(belief, answers, q) for q in sorted(tree.open_questions(answers))]
        return max(options, key=lambda vec: expected(belief, vec))

    b = [float(x) for x in tree.b]
    out: dict[Action, float] = {a: expected(b, commit(i, frozenset())) for i, a in enumerate(tree.moves)}
    for q in sorted(tree.open_questions(frozenset())):
        out[tree.questions[q]] = expected(b, question(b, frozenset(), q))
    for w, vec in tree.watches.items():
        out[tree.moves[w]] = max(out[tree.moves[w]], expected(b, [float(x) for x in vec]))
    return out
