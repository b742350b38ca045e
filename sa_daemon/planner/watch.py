"""The watch model's search: ask now, assist and watch, or commit, compared on equal terms.

Every plan is judged by the return of section III-E's reward over the same horizon ``T =
planner.horizon_s`` from now, undiscounted (``n`` steps of ``dt = planner.rollout_step_s``; the
reward per paper step ``reward.step_s``: the distance reward ``R_d`` to the goal's ``k_c``, ``-5`` for
opposing the user, ``+100`` once at the goal, which is terminal; :mod:`.rollouts`). A question costs the
paper's ``-5`` plus ``R_d`` at the pose where the arm stands still for ``reward.question_time_s`` (the
person's where the snapshot has it, ``Snapshot.question_time_s``): dear far from the goals, cheap near
them, and no discount artefact. Values are vectors over the goal ``g`` the user really wants; with ``s``
steps left at belief ``b`` and pose ``x``:

    commit_a[g]  = M_x[g, a, s]                                               (:mod:`.rollouts`)
    ask_q[g]     = -5 + n_q stay_x[g] + P(yes | g) D(b_yes, x, s - n_q)[g] + P(no | g) D(b_no, x, s - n_q)[g]
    watch_w[g]   = W_x[g, w] + D(b'_gw, x'_gw, s - n_w)[g]                    (at the root)
    D(b, x, s)   = the vector of the action in {commit_a, ask_q} with the largest b . vector
                   (and, with planner.watch_levels = 2, at a child of the root's watch of w: that watch
                   continued, :mod:`.continued_watch`)

where ``W_x[g, w]`` is the return of the watched steps alone (the terminal charge belongs to the end of the
horizon only). At every node the *tracker* picks the action that is best by *its* belief, as the daemon will, and the
pick is credited with what it earns for ``g``; the root's value of an action is ``b . vector``. For
commits and questions this is the usual expected value (answers are Bayes-consistent). For a watch it
is not: ``watch`` runs the motion ``w`` for ``n_w`` steps (``planner.watch_s``) while the user heads to
``g``; the arm reaches ``x'_gw`` and the belief becomes ``b'_gw``: the root belief updated with the
MaxEnt IOC likelihood of the joystick input predicted for that user, against each goal's ``k_c``
(``planner.watch_likelihood = "kc"``) or, as the tracker reads it, each goal's poses summed with weights
``exp(-V)`` (``"marginal"``, :func:`~..model.huber.marginal_nll_driven`), taking ``planner.watch_evidence``
(in rotation mode ``planner.watch_evidence_rotation`` where set) of that evidence and
``planner.watch_copy_evidence`` of it between copies of one target (:func:`~.watched_beliefs.watched_beliefs`;
by default half the evidence, and its split between copies as the rest: the input people give carries less
than a user heading exactly to the goal, session 31). If the
tracker would read a user heading to ``g`` as heading elsewhere, the watch is worth what the misled pick
earns for ``g``. Branches are the top ``G_m`` goals (the ones actions exist for), one child each; by
``planner.watch_branches`` a watch's value is averaged over them with ``b`` renormalised (``"top"``), or
over every goal ``h`` ``b`` holds, as commits and questions are, a goal outside the branches read through
the child of the branch its predicted input is likeliest for (``"mapped"``: ``W_x[h, w] +
D(b'_gw, x'_gw, s - n_w)[h]`` with ``g = argmax loglik[h, w, .]`` over the branches), or with every such
goal a branch of its own (``"all"``, exact, more children); ``planner.root_goals = "top"`` averages the
root's commits and questions over the branches instead. Watched motions are HO, no-assist, and moves to
the ``planner.watch_moves`` most likely goals. Answers update the belief by Bayes with
``answer_p_correct``; with ``planner.question_gate = "information"`` a node may ask only where the answers
are worth more than the question's cost over standing still as long and deciding without them,
``b . (P(yes | g) D(b_yes) + P(no | g) D(b_no) - D(b))`` at ``s - n_q`` steps above ``-r_q``, so that a
question is never chosen for the standing still alone (all three switches session 34; the gate the
default since session 35, the other two off: the default compares watches on other goals than commits
and questions, ``docs/model.md``). Question chains go as
deep as the horizon allows (``planner.max_questions`` at most, and less where a level would hold more
than ``MAX_BATCH`` beliefs); beliefs reached by the same answers in another order are decided once, and
so are the children of branches that reach the same pose with the same belief (turning, goals that share
an orientation: the predicted turn and the tracker's reading of it depend on the orientation alone).

The search is exhaustive over this finite tree (so exact), batched with numpy: all question children
of a level in one call, all branches of every watched motion in one rollout batch. It is anytime in two
stages: commits and questions at the root first, then every watched motion in one batch, which is
skipped if the deadline or ``node_budget`` (evaluated beliefs; deterministic, for evaluation) is reached.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from ..geometry import FloatArray
from ..model.actions import Action, ActionKind, Mode
from ..model.huber import pregrasp_points
from ..model.model import SharedAutonomyModel
from .answers import ThirdAnswer, yes_likelihood
from .continued_watch import continued_vectors, grandchildren
from .node_keys import answer_keys, distinct_rows
from .rollouts import Rollouts
from .snapshot import PlanResult, Snapshot
from .watch_tree import NodeKey, WatchTree, node_key
from .watched_beliefs import watched_beliefs

MAX_BATCH = 20_000
"""Beliefs one question level may hold; a deeper level than this is not searched (a depth limit)."""
GATHER_RATIO, MAX_GATHER = 4, 4_000_000
"""``decide`` values a batch by one ``(n, G, A)`` gather where it has more than one start pose per
``GATHER_RATIO`` nodes and the gather holds at most ``MAX_GATHER`` numbers, else by one matrix product
per start pose."""


def _frozen(x: FloatArray) -> FloatArray:
    """A read-only copy of ``x``."""
    out = np.array(x)
    out.setflags(write=False)
    return out


class _Late(Exception):
    """The deadline passed before the continued watch's stage (:meth:`WatchSearch._continued`)."""


@dataclass(frozen=True)
class _Children:
    """The distinct children of the watched motions: their rollouts (maybe still running), beliefs
    ``(n, G)``, each one's motion (an index of ``moves``), and for every (motion, branch) in order the
    index of its child."""

    rollouts: Rollouts
    beliefs: FloatArray
    motions: np.ndarray
    of_branch: np.ndarray


class WatchSearch:
    """One snapshot's watch-model problem and its search (module doc)."""

    def __init__(self, model: SharedAutonomyModel, snap: Snapshot, deadline: float = math.inf,
                 node_budget: int | None = None) -> None:
        cfg = self.cfg = model.cfg
        self.snap, self.deadline, self.node_budget = snap, deadline, node_budget
        goals = snap.goals
        self.b0 = snap.probs
        self.kp, self.kq = (model.reach_poses(goals, snap.pose, snap.pose_log_w, snap.probs)
                            or model.desired_poses(goals, snap.pose, snap.probs))
        self.pregrasp = pregrasp_points(self.kp, self.kq, cfg.intent.user_standoff_m)
        self.poses = ((goals.positions, goals.quats_wxyz) if cfg.planner.watch_likelihood == "marginal" else None)
        cands = model.candidate_goals(goals, self.b0, snap.pose, (self.kp, self.kq))
        self.moves, self.questions = model.actions_for(snap.method, goals, cands, snap.asked)
        pc = cfg.planner
        self.dt = pc.rollout_step_s
        self.n = max(1, round(pc.horizon_s / self.dt))
        self.n_w = min(self.n - 1, max(1, round(pc.watch_s / self.dt)))
        self.n_q = max(1, round(snap.question_seconds(cfg.reward.question_time_s) / self.dt))
        self.max_q = pc.max_questions if snap.questions_left is None else min(pc.max_questions, snap.questions_left)
        p = cfg.intent.answer_p_correct
        self.L_yes = yes_likelihood(self.questions, goals, p)
        self.third = ThirdAnswer.of(self.questions, goals, p) if cfg.asking.third_answer else None
        """The answers "yes", "no" and "that object, another grasp" (``asking.third_answer``), or ``None``."""
        self.answers = 2 if self.third is None else 3
        """Children a question has: one per answer."""
        self.gated = pc.question_gate == "information"
        pool = np.arange(len(self.b0)) if pc.watch_branches == "all" else cands
        self.branches = np.array([g for g in pool if self.b0[g] > 0], dtype=int)
        self.branch_weights = self.b0[self.branches] / self.b0[self.branches].sum()
        """``b`` renormalised over the branches: a watch's average (``watch_branches`` "top", "all")."""
        self.b_root = self.b0
        """The belief the root's commits and questions are averaged by: ``b`` (``planner.root_goals =
        "all"``), or the branch weights (``"top"``), the watches' own average."""
        if pc.root_goals == "top":
            self.b_root = np.zeros_like(self.b0)
            self.b_root[self.branches] = self.branch_weights
        move_ix = [i for i, a in enumerate(self.moves) if a.kind is ActionKind.MOVE][: pc.watch_moves]
        other_ix = [i for i, a in enumerate(self.moves) if a.kind is not ActionKind.MOVE]
        self.watched = (other_ix + move_ix) if pc.watch_levels > 0 and self.n > 1 else []
        self.continues = pc.watch_levels > 1 and self.n > 2 * self.n_w
        """A child may keep its motion for another watch (:mod:`.continued_watch`)."""
        self.nodes = 0
        self.children = 0
        """Distinct children of the watched motions searched (branches turning alike are one child)."""
        self.grandchildren = 0
        """Distinct grandchildren searched where a child may continue its watch (:mod:`.continued_watch`)."""
        self._memo: dict[tuple[int, int], tuple[Rollouts, FloatArray]] = {}
        self._askable: tuple[Rollouts, dict[NodeKey, frozenset[int]]] | None = None
        """While :meth:`tree` searches: the root's rollouts and the questions each of their nodes may ask."""

    # -- pieces ------------------------------------------------------------------------------------------

    def rollouts(self, positions: FloatArray, quats: FloatArray, weights: FloatArray, steps: int,
                 watch_steps: int = 0, background: bool = False) -> Rollouts:
        """This snapshot's rollouts (its goals' ``k_c``, its motions, mode and speed) from start poses
        ``positions`` ``(C, 3)`` and ``quats`` ``(C, 4)`` under beliefs ``weights`` ``(C, G)``."""
        s = self.snap
        return Rollouts(self.cfg, positions, quats, weights, self.kp, self.kq, self.moves, s.mode, s.user_speed,
                        steps, self.dt, watch_steps, pregrasp=self.pregrasp, background=background,
                        anchor=s.anchor, poses=self.poses)

    def root_rollouts(self) -> Rollouts:
        """The rollouts from the snapshot's pose and belief over the whole horizon, with the watched steps if
        any motion is watched: the root's commit values, and the predicted input's ``loglik``."""
        pose = self.snap.pose
        return self.rollouts(pose.position[None], pose.quat_wxyz[None], self.b0[None], self.n,
                             self.n_w if self.watched else 0)

    def _out_of_budget(self) -> bool:
        """The deadline has passed or ``node_budget`` beliefs have been evaluated."""
        return time.perf_counter() > self.deadline or (self.node_budget is not None and self.nodes >= self.node_budget)

    def decide(self, R: Rollouts, c: np.ndarray, B: FloatArray, asked: np.ndarray, yes: np.ndarray, steps: int,
               depth: int = 0, watch: tuple[FloatArray, FloatArray] | None = None) -> FloatArray:
        """``D`` for a batch: the tracker at beliefs ``B`` ``(n, G)``, at start poses ``c`` ``(n,)`` of ``R``
        with ``steps`` left, after the answers ``yes`` ``(n, Q)`` to the questions ``asked`` ``(n, Q)``,
        picks the action best by its belief: a commit, a question, or where ``watch`` gives a node that
        option, the watch continued (its vectors ``(n, G)`` and the values the tracker weighs them by
        ``(n,)``, :meth:`_continued`). Returns what that choice is worth *if the goal is g*, ``(n, G)``."""
        self.nodes += len(B)
        n = len(B)
        rows = np.arange(n)
        M = self._commits(R, steps)  # (C, G, A)
        if self.moves:
            starts = np.flatnonzero(np.bincount(c))  # the start poses present (np.unique sorts: slower)
            if len(starts) == n:  # one node a start: the loop's products, batched (the same numbers)
                E = np.matmul(B[:, None, :], M[c])[:, 0]
            elif len(starts) * GATHER_RATIO > n or n * M.shape[1] * M.shape[2] > MAX_GATHER:
                E = np.empty((n, M.shape[2]))
                for cu in starts:  # one matrix product per start pose, not a (n, G, A) gather
                    at = c == cu
                    E[at] = B[at] @ M[cu]
            else:  # many start poses, few nodes each: one gather beats a Python loop over them
                E = np.einsum("ng,nga->na", B, M[c])
            act = E.argmax(axis=1)
            V, best = M[c, :, act], E[rows, act]
        else:
            V, best = np.full(B.shape, -np.inf), np.full(n, -np.inf)
        if watch is not None:
            keep = watch[1] > best
            V = np.where(keep[:, None], watch[0], V)
            best = np.where(keep, watch[1], best)
        avail = ~asked
        if (not self.questions or depth >= self.max_q or steps < self.n_q or not avail.any()
                or self.answers * int(avail.sum()) > MAX_BATCH):
            return V
        if steps == self.n_q:  # no time left after the answer: every question is worth the same (the first)
            if self.gated:  # no decision after the answer: no information worth anything
                return V
            w = self._ask_last(R, c)
            self._note_askable(R, steps, asked, yes, avail)
            eq = np.einsum("ng,ng->n", B, w)
            better = avail.any(axis=1) & (eq > best)
            return np.where(better[:, None], w, V)
        Vq = self.question_vectors(R, c, B, asked, yes, avail, steps, depth)
        if self.gated:  # a closed question is -inf throughout (0 x -inf would be nan in the product)
            avail = avail & np.isfinite(Vq[..., 0])
        self._note_askable(R, steps, asked, yes, avail)
        eq = np.where(avail, np.einsum("ng,nqg->nq", B, np.where(avail[..., None], Vq, 0.0)), -np.inf)
        q = eq.argmax(axis=1)
        better = eq[rows, q] > best
        return np.where(better[:, None], Vq[rows, q], V)

    def _note_askable(self, R: Rollouts, steps: int, asked: np.ndarray, yes: np.ndarray, avail: np.ndarray) -> None:
        """While :meth:`tree` searches: note the questions each node of the root's question tree may ask. The
        gate's "decide without asking" nodes (fewer steps left than their answers leave) are not nodes of
        the tree and are not noted."""
        if self._askable is None or self._askable[0] is not R:
            return
        for a, y, o in zip(asked, yes, avail, strict=True):
            if steps == self.n - int(a.sum()) * self.n_q:
                key = node_key(steps, np.flatnonzero(a).tolist(), np.flatnonzero(y).tolist())
                self._askable[1][key] = frozenset(np.flatnonzero(o).tolist())

    def _commits(self, R: Rollouts, steps: int) -> FloatArray:
        """``value[..., steps]`` of ``R`` as a contiguous ``(C, G, A)`` array, kept for reuse."""
        hit = self._memo.get((id(R), steps))
        if hit is None or hit[0] is not R:
            hit = self._memo[(id(R), steps)] = (R, np.ascontiguousarray(R.value[..., steps]))
        return hit[1]

    def question_vectors(self, R: Rollouts, c: np.ndarray, B: FloatArray, asked: np.ndarray, yes: np.ndarray,
                         avail: np.ndarray, steps: int, depth: int) -> FloatArray:
        """``ask_q`` of the module doc for every node and available question, ``(n, Q, G)`` (``-inf`` where
        not available). Each answer is a child: yes and no by the tracker's Bayes update, and with the third
        answer "other" by :meth:`.answers.ThirdAnswer.other_grasp`; each weighted for goal ``g`` by how
        likely a person with goal ``g`` gives it. The children are deduplicated: a belief depends on the set
        of answers, not their order, so each (start, asked, answers) is decided once."""
        n, nq = avail.shape
        L = self.L_yes  # (Q, G)
        node, q = np.nonzero(avail)
        Vq = np.full((n, nq, B.shape[1]), -np.inf)
        if steps == self.n_q:  # no decision after the answer: with the gate no question is worth its cost
            if not self.gated:
                Vq[node, q] = self._ask_last(R, c[node])
            return Vq
        total = self.cfg.reward.question + self.n_q * R.stay[c[node]]  # (k, G): asked, the arm stands still
        Bn, y, first_q = B[node], yes[node], np.eye(nq, dtype=bool)[q]
        py = np.einsum("kg,kg->k", Bn, L[q])
        yes_B, no_B = Bn * L[q] / py[:, None], Bn * (1.0 - L[q]) / (1.0 - py)[:, None]
        if self.third is not None:  # answers per question as 0 (none or no), 1 (yes), 2 (other)
            y = y.astype(np.int8)
            t = self.third
            outcomes = [(yes_B, np.where(first_q, 1, y).astype(np.int8), t.P_yes[q]), (no_B, y, t.P_no[q]),
                        (t.other_grasp(Bn, q), np.where(first_q, 2, y).astype(np.int8), t.P_other[q])]
        else:
            outcomes = [(yes_B, y | first_q, L[q]), (no_B, y, 1.0 - L[q])]
        m = len(outcomes)
        kid_B = np.concatenate([o[0] for o in outcomes])
        kid_c = np.tile(c[node], m)
        kid_a = np.tile(asked[node] | first_q, (m, 1))
        kid_y = np.concatenate([o[1] for o in outcomes])
        keys = answer_keys(kid_c, kid_a, kid_y)
        _, first, inverse = np.unique(keys, axis=0 if keys.ndim > 1 else None, return_index=True,
                                      return_inverse=True)  # (axis=0 on 1-D keys: the same, slower)
        v = self.decide(R, kid_c[first], kid_B[first], kid_a[first], kid_y[first], steps - self.n_q, depth + 1)
        v = v[inverse.ravel()]
        k = len(node)
        informed = np.zeros_like(total)
        for i, (_, _, like) in enumerate(outcomes):
            informed = informed + like * v[i * k:(i + 1) * k]
        Vq[node, q] = total + informed
        if self.gated:  # only a question whose answers are worth more than its cost (module doc)
            unasked = self.decide(R, c, B, asked, yes, steps - self.n_q, depth + 1)
            closed = np.einsum("kg,kg->k", Bn, informed - unasked[node]) <= -self.cfg.reward.question
            Vq[node[closed], q[closed]] = -np.inf
        return Vq

    def _ask_last(self, R: Rollouts, c: np.ndarray) -> FloatArray:
        """``ask_q`` with no time left after the answer, the same for every question: asked, the arm stands
        still, and whatever the answer, the pose's value at the horizon (no action moves in 0 steps: any
        column of ``value``). ``(n, G)`` for start poses ``c``."""
        return self.cfg.reward.question + self.n_q * R.stay[c] + R.value[c, :, 0, 0]

    def _root_questions(self, R: Rollouts, asked: np.ndarray) -> dict[int, float]:
        """Value of every question at the root (then the tracker's choices), by the root belief; a question
        the gate closes (``planner.question_gate``) is left out."""
        if self.max_q < 1 or not self.questions or self.n < self.n_q:
            return {}
        Vq = self.question_vectors(R, np.zeros(1, dtype=int), self.b0[None], asked, asked.copy(), ~asked, self.n, 0)
        return {int(q): float(self.b_root @ Vq[0, q]) for q in np.flatnonzero(~asked[0]) if np.isfinite(Vq[0, q]).all()}

    def child_beliefs(self, R: Rollouts, ws: list[int]) -> FloatArray:
        """``b'_gw`` for every watched motion ``w`` in ``ws`` and branch ``g``: ``(len(ws) * branches, G)``,
        motion by motion (:func:`watched_beliefs`)."""
        ll = R.loglik[0][self.branches][:, ws].transpose(1, 0, 2).reshape(-1, len(self.b0))
        share, copy = self.watch_share()
        return watched_beliefs(self.b0, ll, self.snap.goals.target_index, share, copy)

    def watch_share(self) -> tuple[float, float]:
        """The share of the predicted input's evidence a watched belief takes (``planner.watch_evidence``, in
        rotation mode ``watch_evidence_rotation`` where set) and its share between copies of one target
        (``planner.watch_copy_evidence``)."""
        pc = self.cfg.planner
        share = pc.watch_evidence
        if self.snap.mode is Mode.ROTATION and pc.watch_evidence_rotation is not None:
            share = pc.watch_evidence_rotation
        return share, pc.watch_copy_evidence

    def start_children(self, R: Rollouts) -> _Children:
        """The children of every watched motion, their rollouts started on the rollout threads (:meth:`run`
        asks the root's questions meanwhile; :meth:`watch_values` waits for them). Branch ``g`` of motion
        ``w`` starts at the pose ``w`` reaches while the user heads to ``g``, with the belief ``b'_gw``."""
        g, ws = self.branches, self.watched
        B = self.child_beliefs(R, ws)
        pos = np.concatenate([R.watch_positions[0, g, w] for w in ws])
        quat = np.concatenate([R.watch_quats[0, g, w] for w in ws])
        motions = np.repeat(ws, len(g))
        # Turning, branches whose goals share an orientation are the same child (the user turns by the
        # goal's orientation alone, and the tracker reads the turn by it): each distinct one is searched once
        # (one per motion where a child may continue its motion).
        rows = (pos, quat, B) + ((motions[:, None].astype(float),) if self.continues else ())
        first, kid = distinct_rows(np.concatenate(rows, axis=1))
        self.children = len(first)
        rollouts = self.rollouts(pos[first], quat[first], B[first], self.n - self.n_w,
                                 self.n_w if self.continues else 0, background=True)
        return _Children(rollouts, B[first], motions[first], kid)

    def watch_values(self, R: Rollouts, kids: _Children, asked: np.ndarray) -> dict[Action, float]:
        """``watch(w)`` of the module doc for every watched motion, all branches in one rollout batch
        (:meth:`start_children`). In branch ``g`` the tracker decides by its belief ``b'_gw`` and the
        outcome is counted for goal ``g``: a watch that would mislead the tracker is worth what the misled
        choice earns."""
        return {self.moves[w]: value for w, (_, _, value) in self._watch_returns(R, kids, asked).items()}

    def _watch_returns(self, R: Rollouts, kids: _Children,
                       asked: np.ndarray) -> dict[int, tuple[np.ndarray, FloatArray, float]]:
        """Per watched motion ``w``: the goals its value is averaged over, what it returns for each of them,
        and that average. ``watch_branches`` "top" and "all": the branches, each its own child, by the
        branch weights. "mapped": every goal ``h`` the root belief holds, as commits and questions are; a
        branch is its own child, any other goal is read through the child of the branch ``g`` its predicted
        input is likeliest for (``argmax_g loglik[h, w, g]``) and credited with what that child's choice
        earns for ``h``."""
        kids.rollouts.join()
        n = len(kids.beliefs)
        A = np.repeat(asked, n, axis=0)
        watch = self._continued(kids, A) if self.continues else None
        V = self.decide(kids.rollouts, np.arange(n), kids.beliefs, A, A.copy(), self.n - self.n_w, watch=watch)
        g, ws = self.branches, self.watched
        kid = kids.of_branch.reshape(len(ws), len(g))  # each (motion, branch)'s child, rows of V
        out = {}
        if self.cfg.planner.watch_branches == "mapped":
            h = np.flatnonzero(self.b0 > 0)
            slot = np.full(len(self.b0), -1)
            slot[g] = np.arange(len(g))
            for i, w in enumerate(ws):
                rep = np.where(slot[h] >= 0, slot[h], R.loglik[0][h, w][:, g].argmax(axis=1))
                ret = R.watch_return[0, h, w] + V[kid[i, rep], h]
                out[w] = (h, ret, float(self.b0[h] @ ret / self.b0[h].sum()))
            return out
        for i, w in enumerate(ws):
            ret = R.watch_return[0, g, w] + V[kid[i], g]  # each branch's own goal
            out[w] = (g, ret, float(self.branch_weights @ ret))
        return out

    def _continued(self, kids: _Children, asked: np.ndarray) -> tuple[FloatArray, FloatArray]:
        """Every child's watch continued (:mod:`.continued_watch`): its grandchildren, deduplicated like the
        children, rolled out over the ``n - 2 n_w`` steps left and decided (ask or commit), then what the
        continuation is worth, ``(vectors (n, G), values (n,))`` for :meth:`decide`'s ``watch``."""
        if time.perf_counter() > self.deadline:  # the grandchildren are the search's largest stage
            raise _Late
        share, copy = self.watch_share()
        pos, quat, B = grandchildren(kids.rollouts, kids.beliefs, kids.motions, self.branches,
                                     self.snap.goals.target_index, share, copy)
        first, kid = distinct_rows(np.concatenate((pos, quat, B), axis=1))
        self.grandchildren = m = len(first)
        steps = self.n - 2 * self.n_w
        B = B[first]
        G2 = self.rollouts(pos[first], quat[first], B, steps)
        A = np.repeat(asked[:1], m, axis=0)
        # decided in batches whose first question level fits MAX_BATCH, as one child's does: every grandchild
        # may ask (the limit cuts deeper levels only)
        size = max(1, MAX_BATCH // (self.answers * max(1, len(self.questions))))
        V = np.concatenate([self.decide(G2, np.arange(i, min(i + size, m)), B[i:i + size], A[i:i + size],
                                        A[i:i + size].copy(), steps) for i in range(0, m, size)])
        return continued_vectors(kids.rollouts, kids.beliefs, kids.motions, self.branches, V[kid])

    # -- search ------------------------------------------------------------------------------------------

    def run(self) -> tuple[dict[Action, float], dict[Action, float], bool]:
        """Values of the root's commits and questions, and of its watched motions, searched before the
        deadline or budget; ``True`` if every watched motion was."""
        R = self.root_rollouts()
        commit = self.b_root @ R.value[0, :, :, self.n]
        values = {a: float(v) for a, v in zip(self.moves, commit, strict=True)}
        self.nodes += 1
        asked = np.zeros((1, len(self.questions)), dtype=bool)
        # the children's rollouts run while this thread asks the root's questions (they need only R), and
        # are dropped if the questions use up the budget: the values are those of the two stages in turn
        kids = self.start_children(R) if self.watched else None
        for q, v in self._root_questions(R, asked).items():
            values[self.questions[q]] = float(v)
        if kids is None:
            return values, {}, True
        if self._out_of_budget():
            kids.rollouts.cancel()
            return values, {}, False
        try:
            return values, self.watch_values(R, kids, asked), True
        except _Late:  # the deadline passed before a continued watch (planner.watch_levels = 2)
            return values, {}, False

    def tree(self) -> WatchTree:
        """This snapshot's problem as plain data (:class:`~.watch_tree.WatchTree`), searched without a
        deadline: the commits' returns, the questions' costs and likelihoods, the questions every node of
        the root's question tree may ask, and each watched motion's payoff per goal. Not for the
        ``asking.third_answer`` model (its "other" answer is not a Bayes update) nor ``planner.root_goals =
        "top"`` (the root averages by another belief than its answers update)."""
        if self.third is not None:
            raise ValueError("asking.third_answer: the watch tree holds yes/no questions only")
        if self.cfg.planner.root_goals != "all":
            raise ValueError('planner.root_goals: the watch tree needs "all" (one belief for the root and its answers)')
        R = self.root_rollouts()
        asked = np.zeros((1, len(self.questions)), dtype=bool)
        kids = self.start_children(R) if self.watched else None
        self._askable = (R, {})
        try:
            root = frozenset(self._root_questions(R, asked))
        finally:
            _, askable = self._askable
            self._askable = None
        askable[node_key(self.n, (), ())] = root
        watches = self._watch_vectors(R, kids, asked) if kids is not None else {}
        return WatchTree(
            moves=tuple(self.moves), questions=tuple(self.questions), b=_frozen(self.b_root), value=_frozen(R.value[0]),
            question_cost=_frozen(self.cfg.reward.question + self.n_q * R.stay[0]),
            last_question=_frozen(self._ask_last(R, np.zeros(1, dtype=int))[0]), L_yes=_frozen(self.L_yes),
            n=self.n, n_q=self.n_q, askable=askable, watches={w: _frozen(v) for w, v in watches.items()},
        )

    def _watch_vectors(self, R: Rollouts, kids: _Children, asked: np.ndarray) -> dict[int, FloatArray]:
        """Each watched motion's payoff per goal, ``(G,)``, whose average by the root belief is its value:
        its return for the goals it is averaged over; for any other goal the value itself ("top", "all") or
        0 ("mapped": the belief holds none of them)."""
        out = {}
        for w, (h, ret, value) in self._watch_returns(R, kids, asked).items():
            vec = np.full(len(self.b0), value if self.cfg.planner.watch_branches != "mapped" else 0.0)
            vec[h] = ret
            out[w] = vec
        return out


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
