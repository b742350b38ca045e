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

import math
import time
from dataclasses import dataclass

import numpy as np

from ..geometry import FloatArray
from .actions import Action, ActionKind
from .methods import method_spec
from .model import SharedAutonomyModel
from .problem import Problem
from .snapshot import PlanResult, Snapshot


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
    ub: float


class _Search:
    def __init__(self, prob: Problem, deadline: float, node_budget: int | None) -> None:
        self.p = prob
        self.deadline = deadline
        self.node_budget = node_budget
        self.nodes = 0
        self.n_q = len(prob.questions)
        self.max_depth = min(self.n_q, prob.cfg.planner.max_questions)
        self.m_memo: dict[tuple[int, int], tuple[float, Action]] = {}
        self.v_memo: dict[tuple[int, int, int], tuple[float, Action]] = {}
        self.depth_cut = False

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

    def can_ask(self, asked: int, depth: int) -> bool:
        return depth > 0 and asked != (1 << self.n_q) - 1

    def expand(self, b: FloatArray, asked: int, yes: int, depth: int) -> list[_Child]:
        p, g = self.p, self.p.gamma
        qs = [q for q in range(self.n_q) if not asked >> q & 1]
        L = p.L_yes[qs]
        p_yes = L @ b
        b_yes = L * b / p_yes[:, None]
        b_no = (1.0 - L) * b / (1.0 - p_yes)[:, None]
        keys, beliefs = [], []
        for j, q in enumerate(qs):
            keys += [(asked | 1 << q, yes | 1 << q), (asked | 1 << q, yes)]
            beliefs += [b_yes[j], b_no[j]]
        mv = self.move_values(keys, beliefs)
        u_yes, u_no = b_yes @ p.U, b_no @ p.U
        deeper = depth - 1 > 0 and len(qs) > 1
        out = []
        for j, q in enumerate(qs):
            (my, ay), (mn, an) = mv[2 * j], mv[2 * j + 1]
            if deeper:
                uy = min(u_yes[j], max(my, p.q_reward + g * u_yes[j]))
                un = min(u_no[j], max(mn, p.q_reward + g * u_no[j]))
            else:
                uy, un = my, mn
            lb = p.q_reward + g * (p_yes[j] * my + (1 - p_yes[j]) * mn)
            ub = p.q_reward + g * (p_yes[j] * uy + (1 - p_yes[j]) * un)
            out.append(_Child(q, float(p_yes[j]), b_yes[j], b_no[j], my, mn, ay, an, lb, ub))
        out.sort(key=lambda c: -c.lb)
        return out

    def value(
        self, b: FloatArray, asked: int, yes: int, depth: int, m: float, m_act: Action, root: dict | None = None
    ) -> tuple[float, Action]:
        """Exact value of the depth-limited problem at the belief reached by answers ``(asked, yes)``."""
        key = (asked, yes, depth)
        if key in self.v_memo:
            return self.v_memo[key]
        self._check()
        p = self.p
        best, act = m, m_act
        if asked != (1 << self.n_q) - 1 and p.q_reward + p.gamma * float(b @ p.U) > m:
            if depth == 0:
                self.depth_cut = True
            else:
                for c in self.expand(b, asked, yes, depth):
                    if c.ub <= best:
                        continue
                    bit = 1 << c.q
                    vy, _ = self.value(c.b_yes, asked | bit, yes | bit, depth - 1, c.m_yes, c.a_yes)
                    vn, _ = self.value(c.b_no, asked | bit, yes, depth - 1, c.m_no, c.a_no)
                    v = p.q_reward + p.gamma * (c.p_yes * vy + (1.0 - c.p_yes) * vn)
                    if root is not None:
                        root[c.q] = (v, c.ub)
                    if v > best:
                        best, act = v, p.questions[c.q]
        self.v_memo[key] = (best, act)
        return best, act


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
        deadline = t0 + snap.budget_s if snap.budget_s is not None else math.inf
        prob = Problem(self.model, snap)
        s = _Search(prob, deadline, snap.node_budget)
        b0 = prob.b0
        ((m0, a0),) = s.move_values([(0, 0)], [b0])
        best_v, best_a, depth_done, complete = m0, a0, 0, False
        ub = max(m0, prob.q_reward + prob.gamma * float(b0 @ prob.U)) if s.n_q else m0
        root_values: dict[str, float] = {}
        try:
            for depth in range(0, s.max_depth + 1):
                s.depth_cut = False
                root: dict[int, tuple[float, float]] = {}
                try:
                    v, a = s.value(b0, 0, 0, depth, m0, a0, root)
                finally:
                    for q, (qv, _) in root.items():
                        if qv > best_v:
                            best_v, best_a = qv, prob.questions[q]
                        root_values[prob.questions[q].label] = qv
                best_v, best_a, depth_done = v, a, depth
                if not s.depth_cut or depth == s.max_depth:
                    complete = True
                    ub = v
                    break
        except _Stop:
            pass
        root_values.setdefault(a0.label, m0)
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

