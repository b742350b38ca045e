"""The watch model's search: ask now, assist and watch, or commit, compared over one horizon.

Every plan is judged at the same time ``T = planner.horizon_s`` from now, undiscounted: the value of a
plan is the expected distance reward of section III-E at ``T`` (to each goal's ``k_c``, with the +100
bonus), plus the opposition penalties charged on the way, plus ``-5`` per question. Time is priced by
the horizon itself: a question stands the arm still for ``reward.question_time_s`` that a move would
have used. With ``n`` steps of ``dt = planner.rollout_step_s`` left, at belief ``b`` and pose ``x``:

    commit(a)  = sum_g b(g) value_x[g, a, n]                                 (:mod:`.rollouts`)
    ask(q)     = r_q + sum_z P(z | b, q) D(b_z, x, n - n_q)                   (arm still for n_q steps)
    watch(w)   = sum_g b~(g) (P_x[g, w] + D(b'_gw, x'_gw, n - n_w))           (root only, watch_levels = 1)
    D(b, x, n) = max( max_a commit(a),  max_q ask(q) )

``watch`` runs the motion ``w`` for ``n_w`` steps (``planner.watch_s``) while the user heads to ``g``:
the arm reaches ``x'_gw``, penalties ``P_x[g, w]`` are charged, and the belief becomes ``b'_gw``, ``b``
updated with the MaxEnt IOC likelihood of the joystick input predicted for that user - the tracker's
own update. ``b~`` is ``b`` over the top ``G_m`` goals (the ones actions exist for), renormalised: the
observation branches. Watched motions are HO, no-assist, and moves to the ``planner.watch_moves`` most
likely goals. Answers update the belief by Bayes with ``answer_p_correct``.

The search is exhaustive over this finite tree (so exact), batched with numpy: all question children
of a level in one call, all branches of one watched motion in one rollout batch. It is anytime in two
stages: commits and questions at the root first, then every watched motion in one batch, which is
skipped if the deadline or ``node_budget`` (evaluated beliefs; deterministic, for evaluation) is reached.
"""

from __future__ import annotations

import math
import time

import numpy as np

from ..geometry import FloatArray
from ..model.actions import Action, ActionKind
from ..model.model import SharedAutonomyModel
from .rollouts import Rollouts
from .snapshot import PlanResult, Snapshot

MAX_BATCH = 200_000
"""Beliefs one question level may hold; a deeper level than this is not searched (a depth limit)."""


class _Stop(Exception):
    pass


class WatchSearch:
    """One snapshot's watch-model problem and its search (module doc)."""

    def __init__(self, model: SharedAutonomyModel, snap: Snapshot, deadline: float = math.inf,
                 node_budget: int | None = None) -> None:
        cfg = self.cfg = model.cfg
        self.snap, self.deadline, self.node_budget = snap, deadline, node_budget
        goals = snap.goals
        self.b0 = snap.probs
        self.kp, self.kq = goals.desired_poses(snap.pose, cfg.intent.rotation_weight_m_per_rad)
        self.moves, self.questions = model.action_set(snap.method, goals, self.b0, snap.pose, snap.asked)
        pc = cfg.planner
        self.dt = pc.rollout_step_s
        self.n = max(1, round(pc.horizon_s / self.dt))
        self.n_w = min(self.n - 1, max(1, round(pc.watch_s / self.dt)))
        self.n_q = max(1, math.ceil(cfg.reward.question_time_s / self.dt - 1e-9))
        self.max_q = pc.max_questions
        p = cfg.intent.answer_p_correct
        qi = np.array([goals.targets.index(q.target) for q in self.questions], dtype=int)
        self.L_yes = np.where(qi[:, None] == goals.target_index[None, :], p, 1.0 - p).reshape(len(qi), len(goals))
        cands = model.candidate_goals(goals, self.b0, snap.pose)
        self.branches = np.array([g for g in cands if self.b0[g] > 0], dtype=int)
        move_ix = [i for i, a in enumerate(self.moves) if a.kind is ActionKind.MOVE][: pc.watch_moves]
        other_ix = [i for i, a in enumerate(self.moves) if a.kind is not ActionKind.MOVE]
        self.watched = (other_ix + move_ix) if pc.watch_levels > 0 and self.n > self.n_w else []
        self.nodes = 0

    # -- pieces ------------------------------------------------------------------------------------------

    def _rollouts(self, positions: FloatArray, quats: FloatArray, weights: FloatArray, steps: int,
                  watch_steps: int = 0) -> Rollouts:
        s = self.snap
        return Rollouts(self.cfg, positions, quats, weights, self.kp, self.kq, self.moves, s.mode, s.user_speed,
                        steps, self.dt, watch_steps)

    def _check(self) -> None:
        if time.perf_counter() > self.deadline:
            raise _Stop
        if self.node_budget is not None and self.nodes >= self.node_budget:
            raise _Stop

    def decide(self, R: Rollouts, c: np.ndarray, B: FloatArray, steps: int, asked: np.ndarray,
               depth: int = 0) -> tuple[FloatArray, np.ndarray]:
        """``D`` for a batch: beliefs ``B`` ``(n, G)`` at start poses ``c`` ``(n,)`` of ``R`` with ``steps``
        left and the questions ``asked`` ``(n, Q)`` already asked. Returns the values ``(n,)`` and each
        best action's index: ``0..A-1`` a commit (``self.moves``), ``A + q`` question ``q``."""
        self.nodes += len(B)
        M = R.value[c, :, :, steps]  # (n, G, A)
        commit = np.einsum("ng,nga->na", B, M) if self.moves else np.full((len(B), 1), -np.inf)
        best = commit.max(axis=1)
        act = commit.argmax(axis=1)
        nq = len(self.questions)
        avail = ~asked
        if nq == 0 or steps < self.n_q or depth >= self.max_q or not avail.any():
            return best, act
        n = len(B)
        kids = 2 * n * nq
        if kids > MAX_BATCH:
            return best, act
        L = self.L_yes  # (Q, G)
        py = B @ L.T  # (n, Q)
        by = B[:, None, :] * L[None] / np.where(avail, py, 1.0)[..., None]
        bn = B[:, None, :] * (1.0 - L)[None] / np.where(avail, 1.0 - py, 1.0)[..., None]
        kid_asked = asked[:, None, :] | np.eye(nq, dtype=bool)[None]  # (n, Q, Q)
        kid_B = np.concatenate((by, bn), axis=1).reshape(kids, -1)
        kid_c = np.repeat(c, 2 * nq)
        kid_a = np.concatenate((kid_asked, kid_asked), axis=1).reshape(kids, nq)
        ok = np.concatenate((avail, avail), axis=1).reshape(kids)
        v = np.full(kids, -np.inf)
        v[ok], _ = self.decide(R, kid_c[ok], kid_B[ok], steps - self.n_q, kid_a[ok], depth + 1)
        v = v.reshape(n, 2, nq)
        qv = self.cfg.reward.question + py * v[:, 0] + (1.0 - py) * v[:, 1]
        qv = np.where(avail, qv, -np.inf)
        better = qv.max(axis=1) > best
        best = np.where(better, qv.max(axis=1), best)
        act = np.where(better, len(self.moves) + qv.argmax(axis=1), act)
        return best, act

    def _root_questions(self, R: Rollouts, asked: np.ndarray) -> dict[int, float]:
        """Value of every question at the root (then optimal play)."""
        out: dict[int, float] = {}
        if self.n < self.n_q or self.max_q < 1:
            return out
        b = self.b0
        for q in np.flatnonzero(~asked[0]):
            L = self.L_yes[q]
            py = float(b @ L)
            kids = np.stack((b * L / py, b * (1.0 - L) / (1.0 - py)))
            kid_asked = np.repeat(asked, 2, axis=0)
            kid_asked[:, q] = True
            v, _ = self.decide(R, np.zeros(2, dtype=int), kids, self.n - self.n_q, kid_asked, 1)
            out[int(q)] = self.cfg.reward.question + py * v[0] + (1.0 - py) * v[1]
        return out

    def child_beliefs(self, R: Rollouts, w: int) -> FloatArray:
        """``b'_gw`` for every branch ``g`` of watched motion ``w``: ``(branches, G)``."""
        log_b = np.log(np.maximum(self.b0, 1e-300))[None] + R.loglik[0, self.branches, w, :]
        log_b -= log_b.max(axis=1, keepdims=True)
        b = np.exp(log_b) * (self.b0 > 0)[None]
        return b / b.sum(axis=1, keepdims=True)

    def watch_values(self, R: Rollouts, asked: np.ndarray) -> dict[Action, float]:
        """``watch(w)`` of the module doc for every watched motion, all branches in one rollout batch."""
        g, ws = self.branches, self.watched
        B = np.concatenate([self.child_beliefs(R, w) for w in ws])
        pos = np.concatenate([R.watch_positions[0, g, w] for w in ws])
        quat = np.concatenate([R.watch_quats[0, g, w] for w in ws])
        left = self.n - self.n_w
        kids = self._rollouts(pos, quat, B, left)
        v, _ = self.decide(kids, np.arange(len(B)), B, left, np.repeat(asked, len(B), axis=0))
        v = v.reshape(len(ws), len(g))
        p = self.b0[g] / self.b0[g].sum()
        return {self.moves[w]: float(p @ (R.watch_penalty[0, g, w] + v[i])) for i, w in enumerate(ws)}

    # -- search ------------------------------------------------------------------------------------------

    def run(self) -> tuple[dict[Action, float], dict[Action, float], bool]:
        """Values of the root's commits and questions, and of its watched motions, searched before the
        deadline or budget; ``True`` if every watched motion was."""
        pose = self.snap.pose
        R = self._rollouts(pose.position[None], pose.quat_wxyz[None], self.b0[None], self.n,
                           self.n_w if self.watched else 0)
        values = {a: float(v) for a, v in zip(self.moves, self.b0 @ R.value[0, :, :, self.n], strict=True)}
        self.nodes += 1
        asked = np.zeros((1, len(self.questions)), dtype=bool)
        for q, v in self._root_questions(R, asked).items():
            values[self.questions[q]] = float(v)
        if not self.watched:
            return values, {}, True
        try:
            self._check()
        except _Stop:
            return values, {}, False
        return values, self.watch_values(R, asked), True


def plan_watch(model: SharedAutonomyModel, snap: Snapshot) -> PlanResult:
    """Plan one snapshot with the watch model. A watched motion is carried out like the same motion
    committed to (the next plan decides again), so a motion's root value is the better of the two."""
    t0 = time.perf_counter()
    deadline = t0 + snap.budget_s if snap.budget_s is not None else math.inf
    search = WatchSearch(model, snap, deadline, snap.node_budget)
    values, watched, complete = search.run()
    for a, v in watched.items():
        values[a] = max(values[a], v)
    best = max(values, key=values.__getitem__)
    upper = values[best] if complete else max(values[best], model.cfg.reward.goal)
    return PlanResult(best, values[best], upper, 1 if complete else 0, search.nodes,
                      (time.perf_counter() - t0) * 1e3, complete, values)
