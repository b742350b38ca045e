"""Belief over goals: MaxEnt IOC joystick updates, answers to questions, resampling (sections III-D, F, G).

A :class:`Belief` is immutable: every update returns a new one, so the daemon can hand the current
belief to the planner worker while the control loop keeps updating its own.

Resampling (``docs/model.md`` explains the choice): when ``N_eff = 1 / sum p^2 < |G| / 2`` each high-level
target ``T`` is given ``n_T = clip(round(p_T * N_targets), 1, K_T)`` goals, its grasp poses sorted by
distance to the gripper and redistributed so that copy ``i < n_T - 1`` owns the ``i``-th closest pose and
the last copy owns the rest (paper Fig. 2), each copy carrying ``p_T / n_T``. Unlike a plain particle
resampler, every target keeps at least one goal and its probability, so evidence is never thrown away
and a wrong belief can still be corrected. Resampling only happens when the allocation would change.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ..config import IntentConfig
from ..geometry import FloatArray, Pose
from ..world.goals import Goal, target_object
from ..world.goalset import GoalSet
from .huber import (
    marginal_nll,
    mixture_nll,
    point_listing_log_w,
    pose_log_weights,
    pose_nll,
    q_minus_v,
    switched_pose_log_w,
)


def _check_finite(name: str, value: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    arr = np.asarray(value, dtype=float)
    if arr.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains NaN or inf: refused")
    return arr


def log_sum_exp(x: FloatArray) -> float:
    """``log(sum(exp(x)))`` by max shift (``scipy.special.logsumexp`` gives the same, at ~10x the call
    overhead on 20-element arrays; the belief updates at 40 Hz)."""
    top = float(np.max(x))
    return top + float(np.log(np.sum(np.exp(x - top))))


def cap_probabilities(p: FloatArray, cap: float, among: np.ndarray | None = None) -> FloatArray:
    """Clamp any probability above ``cap`` to ``cap`` and spread the excess equally over the others
    (over the others in the boolean mask ``among`` if given: goals of answered targets take none)."""
    p = np.array(p, dtype=float)
    i = int(np.argmax(p))
    others = np.arange(len(p)) != i
    if among is not None:
        others &= among
    if p[i] > cap and others.any():
        excess = p[i] - cap
        p[i] = cap
        p[others] += excess / int(others.sum())
    return p


INPUT_COPY_WEIGHTS = ("input", "tracked")
"""The ``intent.copy_weights`` that read the input's posterior over the grasp poses: the belief keeps that
posterior (:attr:`Belief.pose_log_w`) and carries it through a resampling."""

POSTERIOR_POSES = ("tracked", "switching", "points")
"""The ``intent.poses`` whose likelihood weighs a goal's poses by its posterior over them."""

JOINT_COPY_REACHES = ("pooled", "ranked")
"""The ``intent.copy_reach`` that read each target's posterior over all its poses across its copies: the
belief keeps it (:attr:`Belief.pose_joint_log_w`)."""


@dataclass(frozen=True, eq=False)
class Belief:
    """Goals and their normalised log-probabilities.

    Answers are final (``docs/model.md``). ``confirmed`` is the high-level target the user said "yes" to,
    if any: "once the user answers yes, the high-level target is known" (section III-B), so from then on
    joystick input only moves probability among that target's goals (its grasp-pose copies) and the
    target's total is kept. ``ruled_out`` holds the targets the user said "no" to: joystick input no
    longer moves their probability (the answer's ``1 - answer_p_correct`` share stays as it is), so a few
    seconds of ambiguous motion cannot bring back a target the user has denied.
    """

    goals: GoalSet
    log_p: FloatArray
    confirmed: str | None = None
    ruled_out: frozenset[str] = frozenset()
    pose_log_w: FloatArray | None = None
    """``intent.poses = "tracked"``, ``intent.reach_pose`` not ``"closest"`` or ``intent.copy_weights``
    ``"input"`` or ``"tracked"``: each goal's posterior over its own
    grasp poses from the input since the last resampling, ``(G, K)`` log-weights normalised per goal
    (``-inf`` on padding); ``None``: uniform over its poses."""
    anchor: FloatArray | None = None
    """Where the user last drove the gripper (m, base frame): its position at the last input sample that
    translated (``None``: no input yet). A turn's charge (``intent.turn_charge``) is measured from here, not
    from where the gripper is: assistance moves the gripper while the user turns (docs/model.md)."""
    pose_joint_log_w: FloatArray | None = None
    """``intent.copy_reach`` ``"pooled"`` or ``"ranked"`` (:data:`JOINT_COPY_REACHES`): each target's
    posterior over all its grasp poses from the input, whichever copy holds them, ``(G, K)``
    log-probabilities normalised per target
    (``-inf`` on padding): Bayes from uniform over the target's poses, never split by a resampling, which
    only deals the poses out to the copies; ``None``: not kept."""

    def __post_init__(self) -> None:
        lp = np.array(self.log_p, dtype=float)
        if lp.shape != (len(self.goals),):
            raise ValueError("log_p must have one entry per goal")
        lp.setflags(write=False)
        object.__setattr__(self, "log_p", lp)

    @classmethod
    def uniform(cls, goals: GoalSet | tuple[Goal, ...] | list[Goal]) -> Belief:
        """Uniform prior over ``goals``."""
        gs = goals if isinstance(goals, GoalSet) else GoalSet(tuple(goals))
        return cls(gs, np.full(len(gs), -np.log(len(gs))))

    @classmethod
    def from_probs(cls, goals: GoalSet, probs: FloatArray) -> Belief:
        """Belief with the given probabilities (normalised; zeros allowed)."""
        p = _check_finite("probs", probs, (len(goals),))
        if np.any(p < 0) or p.sum() <= 0:
            raise ValueError("probabilities must be non-negative with a positive sum")
        with np.errstate(divide="ignore"):
            return cls(goals, np.log(p / p.sum()))

    @cached_property
    def probs(self) -> FloatArray:
        """Probabilities of the goals, ``(G,)``, summing to 1."""
        p = np.exp(self.log_p)
        p.setflags(write=False)
        return p

    @property
    def n_eff(self) -> float:
        """Kish's effective sample size ``1 / sum p^2``."""
        return float(1.0 / np.sum(self.probs**2))

    def target_probabilities(self) -> dict[str, float]:
        """Probability of each high-level target: what users and metrics see."""
        return self.goals.target_probabilities(self.probs)

    def _with(self, log_p: FloatArray, confirmed: str | None = None, ruled_out: frozenset[str] = frozenset(),
              pose_log_w: FloatArray | None = None, anchor: FloatArray | None = None,
              pose_joint_log_w: FloatArray | None = None) -> Belief:
        """A belief over the same goals with ``log_p``, the answers so far plus the new ones, and the pose
        weights and anchor (``None``: the current ones)."""
        return Belief(self.goals, log_p, confirmed or self.confirmed, self.ruled_out | ruled_out,
                      self.pose_log_w if pose_log_w is None else pose_log_w,
                      self.anchor if anchor is None else anchor,
                      self.pose_joint_log_w if pose_joint_log_w is None else pose_joint_log_w)

    def pose_weights(self) -> FloatArray:
        """Each goal's log-weights over its grasp poses from the input so far, ``(G, K)`` (:attr:`pose_log_w`)."""
        if self.pose_log_w is not None:
            return self.pose_log_w
        mask = self.goals.pose_mask
        with np.errstate(divide="ignore"):
            return np.where(mask, -np.log(mask.sum(axis=1, keepdims=True)), -np.inf)

    def pose_joint_weights(self) -> FloatArray:
        """Each target's log posterior over all its grasp poses, laid out over its copies' poses ``(G, K)``
        (:attr:`pose_joint_log_w`; uniform over the target's poses when not kept)."""
        if self.pose_joint_log_w is not None:
            return self.pose_joint_log_w
        mask = self.goals.pose_mask
        per_target = np.bincount(self.goals.target_index, weights=mask.sum(axis=1))[self.goals.target_index]
        with np.errstate(divide="ignore"):
            return np.where(mask, -np.log(per_target)[:, None], -np.inf)

    def _per_target(self, log_w: FloatArray) -> FloatArray:
        """``(G, K)`` pose log-weights normalised over each target's poses across its copies, each held
        within :data:`LOG_FLOOR` of its target's largest (read-only)."""
        out = np.array(log_w, dtype=float)
        for t in range(len(self.goals.targets)):
            rows = self.goals.target_index == t
            block = out[rows]
            m = self.goals.pose_mask[rows]
            block[m] = _log_normalised(block[m])
            out[rows] = block
        out.setflags(write=False)
        return out

    def _normalised(self, log_p: FloatArray, cap: float, among: np.ndarray | None = None) -> FloatArray:
        log_p = log_p - log_sum_exp(log_p)
        p = np.exp(log_p)
        if p.max() > cap:
            with np.errstate(divide="ignore"):
                log_p = np.log(cap_probabilities(p, cap, among))
        return log_p

    def _competing(self) -> np.ndarray | None:
        """Goals whose probability joystick input may move (``None``: all of them)."""
        if self.confirmed is not None:
            return self.goals.target_mask(self.confirmed)
        if not self.ruled_out:
            return None
        free = ~np.any([self.goals.target_mask(t) for t in self.ruled_out], axis=0)
        return free if free.any() else None  # every target denied (a wrong answer): trust the joystick

    def after_input(self, pose: Pose, user_twist: FloatArray, cfg: IntentConfig) -> Belief:
        """MaxEnt IOC update from one joystick sample: ``log b(g) -= beta (Q_g(x, u) - V_g(x))``, ``beta`` the
        rationality of the part the input drives (``intent.rationality``, ``intent.rotation_rationality``);
        a goal's grasp poses summed with weights ``exp(-V)`` (:func:`~.huber.marginal_nll`), or with each
        goal's posterior over its poses from all the input so far (``tracked``, :attr:`pose_log_w`), or
        with that posterior the pose free to change before each sample (``switching``,
        :func:`~.huber.switched_pose_log_w`), or with each grasp point's ``exp(-V)`` weight shared among its
        listings by that posterior (``points``, :func:`~.huber.point_listing_log_w`), or its lowest-value one
        alone (``intent.poses``). The pose posterior is kept whenever ``poses`` is one of
        :data:`POSTERIOR_POSES`, ``reach_pose`` is not ``closest``, or ``copy_weights`` is ``input`` or
        ``tracked``.

        ``user_twist`` is the user's commanded twist (m/s, rad/s, base frame, current mode only). Called at
        every input sample, also when the input is zero. NaN/inf input raises ``ValueError``. A sample that
        translates moves :attr:`anchor` to ``pose``'s position; any other leaves it.
        """
        u = _check_finite("user_twist", user_twist, (6,))
        positions, quats = self.goals.positions, self.goals.quats_wxyz
        pose_log_w = joint = None
        anchor = pose.position if self.anchor is None or u[:3].any() else self.anchor
        if cfg.poses in POSTERIOR_POSES or cfg.reach_pose != "closest" or cfg.copy_weights in INPUT_COPY_WEIGHTS:
            # Bayes over each goal's poses, from uniform, along the whole input
            per = pose_nll(pose.position, pose.quat_wxyz, u, positions, quats, cfg, anchor=anchor)
            log_w = self.pose_weights()
            if cfg.poses == "switching":  # the pose may have changed since the last sample (a sticky chain)
                log_w = switched_pose_log_w(
                    log_w, pose_log_weights(pose.position, pose.quat_wxyz, positions, quats, cfg), cfg.pose_switch)
            tracked_nll = mixture_nll(log_w, per)
            pose_log_w = log_w - per + tracked_nll[:, None]  # normalised per goal: sum_k w_k e^-per_k = e^-nll
            pose_log_w.setflags(write=False)
            if cfg.copy_reach in JOINT_COPY_REACHES:  # the same Bayes over each target's poses, across its copies
                joint = self._per_target(self.pose_joint_weights() - per)
        if cfg.poses == "nearest":
            nll = cfg.rationality * q_minus_v(pose.position, pose.quat_wxyz, u, positions, quats, cfg,
                                              cfg.rotation_scale, anchor)
        elif cfg.poses == "marginal":
            nll = marginal_nll(pose.position, pose.quat_wxyz, u, positions, quats, cfg, anchor)
        elif cfg.poses == "points":
            nll = mixture_nll(point_listing_log_w(
                pose_log_weights(pose.position, pose.quat_wxyz, positions, quats, cfg), log_w, self.goals.same_point),
                per)
        else:
            nll = tracked_nll
        free = self._competing()
        if free is None:
            return self._with(self._normalised(self.log_p - nll, cfg.cap), pose_log_w=pose_log_w, anchor=anchor,
                              pose_joint_log_w=joint)
        # Only the free goals compete, within their joint probability; answered targets keep theirs.
        lp = np.array(self.log_p)
        inner = lp[free] - nll[free]
        lp[free] = log_sum_exp(lp[free]) + inner - log_sum_exp(inner)
        if self.confirmed is None:
            lp = self._normalised(lp, cfg.cap, free)
        return self._with(lp, pose_log_w=pose_log_w, anchor=anchor, pose_joint_log_w=joint)

    def answer_likelihood(self, target: str, yes: bool, p_correct: float) -> FloatArray:
        """``P(answer | g)`` for every goal when ``target`` was asked (section III-D)."""
        p_yes = np.where(self.goals.target_mask(target), p_correct, 1.0 - p_correct)
        return p_yes if yes else 1.0 - p_yes

    def after_answer(self, target: str, yes: bool, cfg: IntentConfig) -> Belief:
        """Bayes update from a yes/no answer to "is ``target`` your goal?"; a "no" with
        ``intent.reading_trust`` below 1 then doubts the input's reading (:meth:`_doubted`)."""
        if target not in self.goals.targets:
            raise ValueError(f"unknown target {target!r}")
        like = self.answer_likelihood(target, yes, cfg.answer_p_correct)
        log_p = self._normalised(self.log_p + np.log(like), cfg.cap)
        if yes:
            return self._with(log_p, target)
        if cfg.reading_trust < 1.0 and self.confirmed is None:
            log_p = self._doubted(log_p, target, cfg)
        return self._with(log_p, ruled_out=frozenset({target}))

    def _doubted(self, log_p: FloatArray, target: str, cfg: IntentConfig) -> FloatArray:
        """After a "no" to ``target``: the belief ``log_p`` over the targets still open mixed toward uniform.

        Two readings of the input so far: sound (prior ``lambda_0 = intent.reading_trust``), the belief as
        it is, under which the "no" had probability ``1 - b_t`` (``b_t`` the target's probability before the
        answer); or unsound, the input telling nothing, a uniform belief over the ``n`` targets open before
        the answer, under which it had ``1 - 1/n``. The posterior trust is
        ``lambda = lambda_0 (1 - b_t) / (lambda_0 (1 - b_t) + (1 - lambda_0)(1 - 1/n))`` and each open
        target's share of the open mass becomes ``lambda p + (1 - lambda) / (n - 1)``, a target's share dealt
        to its copies as they hold it (equally where they hold nothing). Denied targets keep theirs."""
        gs = self.goals
        rest = np.array([t not in self.ruled_out and t != target for t in gs.targets])  # open after the answer
        n = int(rest.sum()) + 1  # open before it
        if n <= 2:
            return log_p  # nothing left to spread over
        b_t = float(gs.target_sums(self.probs)[gs.targets.index(target)])
        trust = cfg.reading_trust * (1.0 - b_t)
        trust = trust / (trust + (1.0 - cfg.reading_trust) * (1.0 - 1.0 / n))
        p = np.exp(log_p)
        held = gs.target_sums(p)
        mixed = trust * held + (1.0 - trust) * held[rest].sum() / (n - 1)
        of = gs.target_index
        copies = np.bincount(of, minlength=len(gs.targets))
        within = np.where(held[of] > 0.0, p / np.where(held[of] > 0.0, held[of], 1.0), 1.0 / copies[of])
        out = np.where(rest[of], mixed[of] * within, p)
        with np.errstate(divide="ignore"):
            return self._normalised(np.log(out), cfg.cap)

    def without_confirmation(self) -> Belief:
        """This belief with its "yes" withdrawn (``asking.withdraw_yes_s``): the same probabilities, the
        "no" answers kept, and joystick input free again to move the confirmed target's total."""
        return Belief(self.goals, self.log_p, None, self.ruled_out, self.pose_log_w, self.anchor,
                      self.pose_joint_log_w)

    def without_denials(self) -> Belief:
        """This belief with its "no" answers withdrawn (``asking.withdraw_no_s``): the same probabilities
        (a denied target keeps the small share its answer left it) and joystick input free again to move
        every target; a "yes" is kept."""
        return Belief(self.goals, self.log_p, self.confirmed, frozenset(), self.pose_log_w, self.anchor,
                      self.pose_joint_log_w)

    def siblings(self, target: str) -> list[str]:
        """The other targets (grasp types) of ``target``'s object."""
        obj = target_object(target)
        return [t for t in self.goals.targets if t != target and target_object(t) == obj]

    def after_other_grasp(self, target: str, cfg: IntentConfig) -> Belief:
        """The third answer to "is ``target`` your goal?": "yes, that object, but another grasp" (section
        VII; ``asking.third_answer``). ``target`` is ruled out and its probability goes to its object's
        other targets, in proportion to theirs (equally where they have none); every other object keeps
        its probability. ``ValueError`` if the object has no other target."""
        sibs = self.siblings(target)
        if target not in self.goals.targets or not sibs:
            raise ValueError(f"{target!r}: its object has no other grasp type to prefer")
        p = np.exp(self.log_p - log_sum_exp(self.log_p))
        tp = self.goals.target_probabilities(p)
        asked = self.goals.target_mask(target)
        total = sum(tp[s] for s in sibs)
        for s in sibs:
            m = self.goals.target_mask(s)
            if total > 0.0:
                p[m] *= 1.0 + tp[target] / total
            else:
                p[m] += tp[target] / len(sibs) / m.sum()
        p[asked] = 0.0
        log_p = self._normalised(np.log(np.maximum(p, 1e-300)), cfg.cap)
        return self._with(log_p, ruled_out=frozenset({target}))

    # -- resampling and redistribution (section III-G) -------------------------------------------------

    def copy_allocation(self) -> dict[str, int]:
        """Number of goals each target would get if resampled now."""
        tp = self.target_probabilities()
        pool = self._pose_pools()
        n = len(tp)
        return {t: int(np.clip(np.floor(p * n + 0.5), 1, len(pool[t]))) for t, p in tp.items()}

    def current_allocation(self) -> dict[str, int]:
        """Number of goals each target has now."""
        counts = np.bincount(self.goals.target_index, minlength=len(self.goals.targets))
        return {t: int(c) for t, c in zip(self.goals.targets, counts)}

    def _pose_pools(self) -> dict[str, list[Pose]]:
        pools: dict[str, list[Pose]] = {t: [] for t in self.goals.targets}
        for g in self.goals.goals:
            pools[g.target].extend(g.poses)
        return pools

    def needs_resampling(self) -> bool:
        """``N_eff < |G| / 2`` and resampling would change the allocation of goals to targets."""
        return self.n_eff < len(self.goals) / 2 and self.copy_allocation() != self.current_allocation()

    def resampled(self, pose: Pose, cfg: IntentConfig) -> Belief:
        """Resample and redistribute grasp poses if :meth:`needs_resampling`, else return ``self``."""
        if not cfg.resample or not self.needs_resampling():
            return self
        tp = self.target_probabilities()
        alloc = self.copy_allocation()
        pools = self._pose_pools()
        keep = cfg.copy_weights in INPUT_COPY_WEIGHTS or cfg.keep_pose_posterior
        log_post = self._pose_pool_log_posteriors() if keep else None
        joint_pool = self._pose_pool_joint() if self.pose_joint_log_w is not None else None
        first = {}
        for g in self.goals.goals:
            first.setdefault(g.target, g)
        goals: list[Goal] = []
        probs: list[float] = []
        inner: list[FloatArray] = []  # when kept: each new copy's log posterior over its own poses
        joint: list[FloatArray] = []  # when kept: the target's posterior over its poses, dealt out to its copies
        for t in self.goals.targets:
            template, n = first[t], alloc[t]
            poses = pools[t]
            pooled = template.with_poses(tuple(poses))
            idx = np.argsort(pooled.pose_distances(pose, cfg.rotation_weight_m_per_rad), kind="stable")
            # equal shares (None); "poses": the marginal tracker's weights exp(-V) of the target's poses,
            # here; "input": the target's posterior over its poses from the input; "tracked": their product,
            # the score the tracked reach picks a pose by (huber.tracked_goal_poses)
            share = None
            if cfg.copy_weights in ("poses", "tracked"):
                lw = pose_log_weights(pose.position, pose.quat_wxyz, pooled.positions[None],
                                      pooled.quats_wxyz[None], cfg)[0]
                if cfg.copy_weights == "tracked":
                    lw = lw + log_post[t]
                    lw = lw - log_sum_exp(lw)
                share = np.exp(lw)
            elif cfg.copy_weights == "input":
                share = np.exp(log_post[t])
            for i in range(n):
                own = idx[i:] if i == n - 1 else idx[i:i + 1]
                goals.append(template.with_poses(tuple(poses[k] for k in own)))
                probs.append(tp[t] / n if share is None else tp[t] * share[own].sum())
                if log_post is not None:
                    inner.append(_log_normalised(log_post[t][own]))
                if joint_pool is not None:
                    joint.append(joint_pool[t][own])
        out = Belief.from_probs(GoalSet(tuple(goals)), np.array(probs))
        # each copy's weights over its own poses start uniform (when kept: INPUT_COPY_WEIGHTS or
        # keep_pose_posterior, their posterior)
        return Belief(out.goals, out.log_p, self.confirmed, self.ruled_out,
                      pose_log_w=None if log_post is None else _padded(inner, out.goals.pose_mask),
                      anchor=self.anchor,
                      pose_joint_log_w=None if joint_pool is None else _padded(joint, out.goals.pose_mask))

    def _pose_pool_joint(self) -> dict[str, FloatArray]:
        """Each target's :attr:`pose_joint_log_w` in :meth:`_pose_pools`' order."""
        return self._by_target(self.pose_joint_log_w)

    def _by_target(self, log_w: FloatArray) -> dict[str, FloatArray]:
        """``(G, K)`` per-pose rows concatenated per target, in :meth:`_pose_pools`' order (padding dropped)."""
        pools: dict[str, list[FloatArray]] = {t: [] for t in self.goals.targets}
        for i, g in enumerate(self.goals.goals):
            pools[g.target].append(log_w[i, :len(g.poses)])
        return {t: np.concatenate(parts) for t, parts in pools.items()}

    def _pose_pool_log_posteriors(self) -> dict[str, FloatArray]:
        """Each target's log posterior over its grasp poses, in :meth:`_pose_pools`' order: a copy's
        probability times its posterior over its own poses (:attr:`pose_log_w`), normalised per target."""
        pooled = self._by_target(self.pose_weights() + self.log_p[:, None])
        return {t: _log_normalised(lw) for t, lw in pooled.items()}


LOG_FLOOR = 745.0
"""A kept pose log-weight is held within this of its row's largest (``exp(-745)`` is float64's smallest
positive): below it a weight would be exactly zero, a pose the belief can no longer hold."""


def _log_normalised(log_w: FloatArray) -> FloatArray:
    """``log_w`` shifted to sum to one in probability, every entry finite: one the input has all but ruled
    out is held at :data:`LOG_FLOOR` below the largest (where it is ``exp(-745)`` or less, so no sum sees it);
    with no finite entry at all (a copy of no mass) the row starts afresh, uniform."""
    if not np.isfinite(log_w).any():
        return np.full(len(log_w), -np.log(len(log_w)))
    log_w = np.maximum(log_w, np.max(log_w) - LOG_FLOOR)
    return log_w - log_sum_exp(log_w)


def _padded(rows: list[FloatArray], mask: np.ndarray) -> FloatArray:
    """Per-goal pose log-weights ``rows`` laid out as ``mask`` ``(G, K)`` (``-inf`` on padding)."""
    out = np.full(mask.shape, -np.inf)
    for i, r in enumerate(rows):
        out[i, :len(r)] = r
    out.setflags(write=False)
    return out
