"""Anytime exact solver for the shared-autonomy POMDP.

The value of a belief is ``max(best move now, best question followed by the value of each answer's
belief)`` (see :mod:`.problem`). The solver searches the tree of answer sequences:

* **iterative deepening** on the number of questions, so a good answer exists at any deadline;
* **branch and bound**: a question is skipped when its upper bound cannot beat the best action found at
  the node. The bound of a belief is the linear full-information value ``U(b) = b . U_g`` (a proven
  upper bound, :meth:`Problem._upper_bounds`), refined one level: ``V(b_z) <= min(U(b_z),
  max(m(b_z), r_q + gamma U(b_z)))``;
* **memoisation** of beliefs reached by the same set of answers (the belief after answers does not
  depend on their order);
* **numpy batches**: all children of a node are evaluated in one call.

The search stops at the deadline (``budget_s``), after ``node_budget`` belief evaluations (deterministic,
for evaluation), or when the optimum is proven: an iteration in which no node wanted a deeper question.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass

import numpy as np

from ..geometry import FloatArray
from ..model.actions import Action
from ..model.methods import method_spec
from ..model.model import SharedAutonomyModel
from .problem import Problem
from .snapshot import PlanResult, Snapshot
from .watch import plan_watch


class _Stop(Exception):
    """Deadline or node budget reached."""


@dataclass
class _Child:
    q: int
    p_yes: float
    b_yes: FloatArray
    b_no: FloatArray
    m_yes: float
    m_no: float
    a_yes: Action
    a_no: Action
    lb: float
    ub: float  # bound within the current depth limit
    ub_free: float  # bound if deeper questions were allowed
    u_no: float  # bound on the value after "no" used by ``ub``


class _Search:
    def __init__(self, prob: Problem, deadline: float, node_budget: int | None, bound_levels: int = 3) -> None:
        self.p = prob
        self.deadline = deadline
        self.node_budget = node_budget
        self.levels = bound_levels
        self.nodes = 0
        self.n_q = len(prob.questions)
        self.all_asked = (1 << self.n_q) - 1
        self.max_depth = min(self.n_q, prob.cfg.planner.max_questions,
                             prob.snap.questions_left if prob.snap.questions_left is not None else self.n_q)
        self.m_memo: dict[tuple[int, int], tuple[float, Action]] = {}
        self.v_memo: dict[tuple[int, int, int], tuple[float, Action, bool]] = {}
        self.free_memo: dict[tuple[int, int], tuple[float, Action]] = {}  # values no depth limit touched
        self.cuts = 0  # nodes where the depth limit stopped a question that might have paid

    def _check(self) -> None:
        if time.perf_counter() > self.deadline:
            raise _Stop
        if self.node_budget is not None and self.nodes >= self.node_budget:
            raise _Stop

    def move_values(self, keys: list[tuple[int, int]], beliefs: list[FloatArray]) -> list[tuple[float, Action]]:
        """Best move of each belief, memoised by answer set; new ones evaluated in one batch."""
        todo = [i for i, k in enumerate(keys) if k not in self.m_memo]
        if todo:
            vals, acts = self.p.best_moves(np.array([beliefs[i] for i in todo]))
            for j, i in enumerate(todo):
                self.m_memo[keys[i]] = (float(vals[j]), acts[j])
            self.nodes += len(todo)
        return [self.m_memo[k] for k in keys]

    def _avail(self, asked: int) -> np.ndarray:
        """``(1, Q)`` mask of the questions not yet asked."""
        return np.array([[not asked >> q & 1 for q in range(self.n_q)]])

    def _children(self, B: FloatArray, avail: np.ndarray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """``P(yes)`` ``(n, Q)`` and the beliefs after yes and no ``(n, Q, G)`` for beliefs ``(n, G)``."""
        L = self.p.L_yes
        py = B @ L.T
        by = B[:, None, :] * L[None] / np.where(avail, py, 1.0)[..., None]
        bn = B[:, None, :] * (1.0 - L)[None] / np.where(avail, 1.0 - py, 1.0)[..., None]
        return py, by, bn

    def _leaf_bound(self, kids: FloatArray, can_ask: np.ndarray) -> tuple[FloatArray, FloatArray]:
        """Cheap bound on ``V`` of beliefs ``(n, G)``: ``m`` if no question is left, else
        ``min(U, max(m, r_q + gamma U))`` (a question's children are bounded by the linear ``U``).
        Returns ``(bound, m)`` with ``m`` the best move value."""
        p = self.p
        u = kids @ p.U
        m = p.move_values(kids)
        return np.where(can_ask, np.minimum(u, np.maximum(m, p.q_reward + p.gamma * u)), m), m

    def question_bounds(self, B: FloatArray, avail: np.ndarray, level: int) -> FloatArray:
        """Upper bound ``(n, Q)`` on each question's value (then optimal play) at beliefs ``(n, G)``.

        A "yes" child is bounded by :meth:`_leaf_bound` (it concentrates the belief, so that bound is
        tight). A "no" child is refined ``level`` more times - ``min(U, max(m, best question bound))`` -
        where the loose linear bound hurts: a spread belief losing one target at a time.
        Unavailable questions get ``-inf``.
        """
        p = self.p
        n, nq = avail.shape
        py, by, bn = self._children(B, avail)
        kid_avail = (avail[:, None, :] & ~np.eye(nq, dtype=bool)[None]).reshape(n * nq, nq)
        can_ask = kid_avail.any(axis=1)
        uy, _ = self._leaf_bound(by.reshape(n * nq, -1), can_ask)
        bn = bn.reshape(n * nq, -1)
        un, m = self._leaf_bound(bn, can_ask)
        if level > 0 and can_ask.any():
            deeper = self.question_bounds(bn[can_ask], kid_avail[can_ask], level - 1).max(axis=1)
            un[can_ask] = np.minimum(un[can_ask], np.maximum(m[can_ask], deeper))
        qb = p.q_reward + p.gamma * (py * uy.reshape(n, nq) + (1.0 - py) * un.reshape(n, nq))
        return np.where(avail, qb, -np.inf)

    def questions_can_pay(self, b: FloatArray, avail: np.ndarray, m: float, levels: int) -> bool:
        """False if no question can beat ``m`` at any depth (bounds deepened until proven or spent)."""
        for level in range(levels + 1):
            if self.question_bounds(b[None], avail, level).max() <= m:
                return False
        return True

    def expand(self, b: FloatArray, asked: int, yes: int, depth: int) -> list[_Child]:
        """Children of a node, each question with exact one-step and bounded full values, best first."""
        p, g = self.p, self.p.gamma
        avail = self._avail(asked)
        qs = np.flatnonzero(avail[0])
        py, by, bn = self._children(b[None], avail)
        keys, beliefs = [], []
        for q in qs:
            keys += [(asked | 1 << q, yes | 1 << q), (asked | 1 << q, yes)]
            beliefs += [by[0, q], bn[0, q]]
        mv = self.move_values(keys, beliefs)
        can_ask = np.full(2 * len(qs), len(qs) > 1)
        leaf, _ = self._leaf_bound(np.concatenate((by[0, qs], bn[0, qs])), can_ask)
        out = []
        for j, q in enumerate(qs):
            (my, ay), (mn, an) = mv[2 * j], mv[2 * j + 1]
            pq = float(py[0, q])
            lb = p.q_reward + g * (pq * my + (1 - pq) * mn)
            uy, un = max(my, float(leaf[j])), max(mn, float(leaf[len(qs) + j]))
            free = p.q_reward + g * (pq * uy + (1 - pq) * un)
            # At the depth limit the children are leaves: the one-step value is exact.
            ub, u_no = (free, un) if depth > 1 else (lb, mn)
            out.append(_Child(int(q), pq, by[0, q], bn[0, q], my, mn, ay, an, lb, ub, free, u_no))
        out.sort(key=lambda c: -c.lb)
        return out

    def value(
        self,
        b: FloatArray,
        asked: int,
        yes: int,
        depth: int,
        m: float,
        m_act: Action,
        alpha: float = -math.inf,
        root: dict | None = None,
    ) -> tuple[float, Action, bool]:
        """Value of the depth-limited problem at the belief reached by answers ``(asked, yes)``.

        Returns ``(v, action, exact)``. With a threshold ``alpha`` the search may stop once it proves
        ``V <= alpha`` (fail-low): then ``exact`` is False and ``v`` is an upper bound ``<= alpha``.
        """
        free = self.free_memo.get((asked, yes))
        if free is not None:
            return free[0], free[1], True
        key = (asked, yes, depth)
        hit = self.v_memo.get(key)
        if hit is not None and (hit[2] or hit[0] <= alpha):
            return hit
        self._check()
        p = self.p
        best, act = m, m_act
        bound = -math.inf  # upper bound of the questions not valued exactly
        cuts = self.cuts
        if asked != self.all_asked and p.q_reward + p.gamma * float(b @ p.U) > max(m, alpha):
            avail = self._avail(asked)
            # Deep bounds pay at the root; inner nodes are many and their deep bounds rarely prune.
            levels = self.levels if asked == 0 else min(1, self.levels)
            if not self.questions_can_pay(b, avail, max(m, alpha), levels):
                pass  # no question can beat the threshold, at any depth
            elif depth == 0:
                self.cuts += 1
                bound = math.inf
            else:
                for c in self.expand(b, asked, yes, depth):
                    thr = max(alpha, best)
                    if c.ub <= thr:
                        if c.ub_free > thr:
                            self.cuts += 1  # only the depth limit pruned it
                        bound = max(bound, c.ub)
                        continue
                    bit = 1 << c.q
                    py, pn = c.p_yes, 1.0 - c.p_yes
                    a_y = (thr - p.q_reward - p.gamma * pn * c.u_no) / (p.gamma * py)
                    vy, _, ey = self.value(c.b_yes, asked | bit, yes | bit, depth - 1, c.m_yes, c.a_yes, a_y)
                    a_n = (thr - p.q_reward - p.gamma * py * vy) / (p.gamma * pn)
                    vn, _, en = self.value(c.b_no, asked | bit, yes, depth - 1, c.m_no, c.a_no, a_n)
                    v = p.q_reward + p.gamma * (py * vy + pn * vn)
                    if ey and en:
                        if root is not None:
                            root[c.q] = v
                        if v > best:
                            best, act = v, p.questions[c.q]
                    else:
                        bound = max(bound, v)  # an upper bound <= thr
        exact = best > alpha or bound <= best
        result = (best, act, True) if exact else (max(best, bound), act, False)
        if exact and self.cuts == cuts:
            self.free_memo[(asked, yes)] = (best, act)
        self.v_memo[key] = result
        return result


class Solver:
    """Plans one snapshot: rule-based methods answer at once, planned methods search (module doc)."""

    def __init__(self, model: SharedAutonomyModel | None = None) -> None:
        self.model = model or SharedAutonomyModel()

    def plan(self, snap: Snapshot) -> PlanResult:
        t0 = time.perf_counter()
        spec = method_spec(snap.method)
        if not spec.planned:
            act = self.model.fixed_action(snap.method, snap.goals, snap.probs)
            return PlanResult(act, math.nan, math.nan, 0, 0, (time.perf_counter() - t0) * 1e3, True)
        if self.model.cfg.planner.model == "watch":
            return plan_watch(self.model, snap)
        deadline = t0 + snap.budget_s if snap.budget_s is not None else math.inf
        prob = Problem(self.model, snap)
        s = _Search(prob, deadline, snap.node_budget, self.model.cfg.planner.bound_levels)
        b0 = prob.b0
        ((m0, a0),) = s.move_values([(0, 0)], [b0])
        best_v, best_a, depth_done, complete = m0, a0, 0, False
        ub = max(m0, prob.q_reward + prob.gamma * float(b0 @ prob.U)) if s.n_q else m0
        root_values: dict[Action, float] = {}
        try:
            for depth in range(s.max_depth + 1):
                cuts = s.cuts
                root: dict[int, float] = {}
                try:
                    v, a, _ = s.value(b0, 0, 0, depth, m0, a0, root=root)
                finally:
                    for q, qv in root.items():
                        if qv > best_v:
                            best_v, best_a = qv, prob.questions[q]
                        root_values[prob.questions[q]] = qv
                best_v, best_a, depth_done = v, a, depth
                if s.cuts == cuts or depth == s.max_depth:
                    complete = True
                    ub = v
                    break
        except _Stop:
            pass
        root_values.setdefault(a0, m0)
        return PlanResult(
            action=best_a,
            value=float(best_v),
            upper_bound=float(max(ub, best_v)),
            depth=depth_done,
            nodes=s.nodes,
            time_ms=(time.perf_counter() - t0) * 1e3,
            complete=complete,
            root_values=root_values,
        )

    def action_values(self, snap: Snapshot) -> dict[Action, float]:
        """Exact value of every root action (then optimal play).

        For benchmarks and tests: a planner's choice is optimal iff its value equals the maximum. The watch
        model's search is exhaustive: its values are those of an unbudgeted plan.
        """
        if self.model.cfg.planner.model == "watch":
            return plan_watch(self.model, dataclasses.replace(snap, budget_s=None, node_budget=None)).root_values
        prob = Problem(self.model, snap)
        s = _Search(prob, math.inf, None, self.model.cfg.planner.bound_levels)
        b0 = prob.b0
        out: dict[Action, float] = {}
        for j, a in enumerate(prob.moves):
            out[a] = float(b0 @ prob.M[:, j])
        depth = s.max_depth - 1
        if depth >= 0:
            for c in s.expand(b0, 0, 0, s.max_depth):
                bit = 1 << c.q
                vy, _, _ = s.value(c.b_yes, bit, bit, depth, c.m_yes, c.a_yes)
                vn, _, _ = s.value(c.b_no, bit, 0, depth, c.m_no, c.a_no)
                out[prob.questions[c.q]] = prob.q_reward + prob.gamma * (c.p_yes * vy + (1 - c.p_yes) * vn)
        return out
