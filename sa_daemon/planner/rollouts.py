"""Rollouts of the watch model: every (user goal, motion action) pair integrated from a set of start poses.

A rollout is one start ``c``, one goal ``g`` the user heads to and one motion action ``a`` (move-to-goal,
HO, no-assist). At every step of ``dt`` seconds the user's twist is the one predicted for a user
heading to ``g`` (:func:`~..model.twists.user_linear` / ``user_angular``: current mode, smoothed speed), the robot's
twist is ``a``'s velocity generator, and the pose moves by their blend (the user's twist alone for
no-assist). HO is weighted by *its* belief: the start's, then after every step the tracker's update with
that step's predicted input (``planner.ho_belief = "tracked"``, as the daemon's HO follows the belief
while the user drives), or the start's all along (``"fixed"``). Recorded per rollout and step ``s``:

* ``value[c, g, a, s]``: the return of section III-E's reward over the first ``s`` steps, undiscounted,
  for goal ``g``: per paper step (``reward.step_s``) the distance reward ``R_d`` to ``g``'s ``k_c`` at
  the pose reached, plus ``-5`` where the robot's twist opposes the user's; ``+100`` once, when the
  pose reaches ``k_c``, after which the rollout earns nothing more (the goal is terminal); plus, for a
  rollout that has not arrived, what its last pose is worth after the horizon (the task goes on from
  where it ends): ``planner.terminal = "fixed"`` (default), ``R_d`` there for ``planner.terminal_s``;
  ``"approach"``, the return of finishing the approach at the assisted speed (``alpha`` x the move
  generator's top speed + ``1 - alpha`` x the user's, in each part), goal bonus included
  (:func:`~..model.reward.approach_return`);
* ``stay[c, g]``: the same return for one rollout step of standing still at start ``c`` (a question);
* the pose and the return (without the terminal charge: the task goes on from there) after
  ``watch_steps`` steps, and ``loglik[c, g, a, :]``, the MaxEnt IOC log-likelihood the
  belief tracker adds over those steps (``-(Q_g' - V_g')`` per input sample, ``runtime.belief_hz``
  samples a second).

Committing to ``a`` for ``s`` steps from start ``c`` under belief ``b`` is worth
``sum_g b(g) value[c, g, a, s]``.

**Two forms.** This module integrates the batch with numpy passes over whole arrays: the readable
reference. :mod:`.kernel` computes the same rollouts compiled (numba), one fused loop per rollout,
split over ``planner.threads`` threads, 2-3x faster; :class:`Rollouts` uses it wherever it implements
the configuration (:func:`.kernel.supported`: the default HO generator and step cost), and the tests
hold the two equal on random problems. Without watched steps the watch arrays and ``loglik`` are empty.

**Separation.** Every velocity generator's linear part depends on the position alone and its angular
part on the orientation alone, and the user drives one of the two. So in translation mode the
orientation of a rollout does not depend on ``g`` and is integrated once per ``(c, a)``; in rotation
mode the position is. The quaternion work, the expensive part, is then ``G`` times smaller in
translation mode. Tracked HO depends on ``g`` through its belief in the part the user does not drive
too: that part of HO's pose alone is kept per goal, apart from the arrays of the other actions. The
approach corridor (``move.approach_standoff_m > 0``, :func:`~..model.twists.approach_points`) breaks the
separation: the linear part then depends on the orientation too, so in rotation mode positions become
per goal as well (numpy broadcasts them so; the kernel integrates such a move's position per goal).
"""

from __future__ import annotations

import numpy as np

from ..config import Config
from ..geometry import FloatArray, norms, quat_angle, turn
from ..model.actions import Action, ActionKind, Mode
from ..model.huber import marginal_nll_driven, pregrasp_points, q_minus_v_driven
from ..model.reward import approach_return, distance_reward, opposes
from ..model.twists import (
    approach_points,
    assisted_speeds,
    ho_angular,
    ho_linear,
    move_angular,
    move_linear,
    user_angular,
    user_linear,
)
from . import kernel
from .split import Pending, threads


class Rollouts:
    """The batch of the module doc; construction does all the work.

    ``positions`` ``(C, 3)`` and ``quats`` ``(C, 4)`` are the start poses, ``weights`` ``(C, G)`` the
    belief HO uses at each, ``kp``/``kq`` the goals' ``k_c`` (``(G, 3)``, ``(G, 4)``), ``actions`` the
    motion actions (moves index ``kp``), ``speed`` the user's (m/s, rad/s), ``steps`` the number of
    ``dt`` steps (s). ``compiled``: force the compiled (``True``) or the numpy form (``False``); ``None``
    (default) takes the compiled one where :func:`.kernel.supported`. ``pregrasp``: the goals' pre-grasp
    points ``(G, 3)`` (m) if the caller has them (``pregrasp_points``; computed here otherwise).
    ``anchor``: where the user last translated (m, :attr:`~..model.belief.Belief.anchor`), from which the
    tracker measures a turn's charge (``intent.turn_charge``); the predicted user of a rollout drives the
    mode's part alone, so turning it never moves (``None``: the first start's position).
    ``poses``: every goal's grasp poses ``((G, K, 3), (G, K, 4))`` (padded, ``GoalSet``): ``loglik`` is then
    the tracker's marginal over them (:func:`~..model.huber.marginal_nll_driven`, ``planner.watch_likelihood
    = "marginal"``) instead of MaxEnt IOC against ``kp``/``kq``; the compiled form takes it for a watch of
    one step (the default ``watch_s = rollout_step_s``: the input read at the start pose,
    :meth:`_start_marginal`), the numpy form for any.
    ``background``: the compiled form is only started on the rollout threads, and the caller runs other
    Python meanwhile; the arrays are ready after :meth:`join` (or not to be read after :meth:`cancel`).
    """

    _pending: Pending | None = None

    def __init__(self, cfg: Config, positions: FloatArray, quats: FloatArray, weights: FloatArray,
                 kp: FloatArray, kq: FloatArray, actions: list[Action], mode: Mode, speed: tuple[float, float],
                 steps: int, dt: float, watch_steps: int = 0, compiled: bool | None = None,
                 pregrasp: FloatArray | None = None, background: bool = False,
                 anchor: FloatArray | None = None, poses: tuple[FloatArray, FloatArray] | None = None) -> None:
        if compiled is None:  # the kernel reads the input against k_c; a one-step watch's marginal is cheap here
            compiled = kernel.supported(cfg) and (poses is None or watch_steps <= 1)
        if pregrasp is None:
            pregrasp = pregrasp_points(kp, kq, cfg.intent.user_standoff_m)
        anchor = np.array(positions[0] if anchor is None else anchor, dtype=float)
        if compiled:
            self._compiled(cfg, positions, quats, weights, kp, kq, pregrasp, anchor, actions, mode, speed, steps,
                           dt, watch_steps, background)
            if poses is not None and watch_steps:
                self.loglik = self._start_marginal(cfg, positions, quats, kp, kq, pregrasp, anchor, poses, mode,
                                                   speed, dt, len(actions))
            return
        C, G, A = len(positions), len(kp), len(actions)
        translating = Mode(mode) is Mode.TRANSLATION
        kind = [a.kind for a in actions]
        is_move = np.array([k is ActionKind.MOVE for k in kind])
        is_none = np.array([k is ActionKind.NONE for k in kind])
        ho = [i for i, k in enumerate(kind) if k is ActionKind.HO]
        mp = kp[[a.goal if a.kind is ActionKind.MOVE else 0 for a in actions]]  # (A, 3) move targets
        mq = kq[[a.goal if a.kind is ActionKind.MOVE else 0 for a in actions]]
        # Positions vary with the user's goal in translation mode, orientations in rotation mode. HO
        # following the tracked belief depends on g in the other part too: that part of HO's pose is kept
        # apart (``free``, (C, G, 3|4)), so the other actions keep a single copy of it.
        tracked = bool(ho) and cfg.planner.ho_belief == "tracked"
        P = np.broadcast_to(positions[:, None, None, :], (C, G if translating else 1, A, 3)).copy()
        Q = np.broadcast_to(quats[:, None, None, :], (C, 1 if translating else G, A, 4)).copy()
        h = ho[0] if ho else -1
        if tracked:
            free = np.broadcast_to((quats if translating else positions)[:, None, :],
                                   (C, G, 4 if translating else 3)).copy()
        gp, gq = kp[None, :, None, :], kq[None, :, None, :]  # the user's goals, (1, G, 1, .)
        standoff = cfg.intent.user_standoff_m
        pre = pregrasp[None, :, None, :]
        move_m = is_move[None, None, :, None]
        none_m = is_none[None, None, :, None]
        alpha = cfg.blend.alpha
        # HO's belief, as logs: the start's, then (tracked) per rollout the tracker's update with the
        # predicted input, (C, 1, G) or (C, G, G)
        log_w = np.log(np.maximum(weights, 1e-300))[:, None, :]
        t_apply = cfg.intent.action_apply_time_s
        per_step = cfg.reward.opposition_penalty * dt / cfg.reward.step_s
        th = cfg.reward.opposition_threshold
        rate = cfg.runtime.belief_hz * dt  # input samples the tracker reads per rollout step
        samples = rate * cfg.intent.rationality
        rot_scale = cfg.intent.rotation_scale  # the tracker's weight of the rotation part
        k = dt / cfg.reward.step_s  # paper steps per rollout step
        self.value = np.empty((C, G, A, steps + 1))
        self._no_watch(C, G, A)
        loglik = np.zeros((C, G, A, G if watch_steps else 0))

        tail = cfg.planner.terminal_s / cfg.reward.step_s  # the state at the horizon lasts this many paper steps
        v_t, v_r = assisted_speeds(cfg, speed)  # the approach after the horizon (m/s, rad/s)
        approach = cfg.planner.terminal == "approach"

        def reward_at() -> tuple[FloatArray, FloatArray, FloatArray]:
            """(R_d without the bonus, reached, the terminal value) of every rollout's own goal at its pose,
            ``(C, G, A)``; the terminal value is what the pose is worth after the horizon if not arrived."""
            d_t = norms(P - gp)
            d_r = quat_angle(Q, gq)
            if tracked and translating:
                d_r[:, :, h] = quat_angle(free, kq)
            elif tracked:
                d_t[:, :, h] = norms(free - kp)
            reached = (d_t <= cfg.reward.goal_translation_m) & (d_r <= cfg.reward.goal_rotation_rad)
            r = distance_reward(d_t, d_r, cfg.reward) - np.where(reached, cfg.reward.goal, 0.0)
            return r, reached, approach_return(d_t, d_r, v_t, v_r, cfg.reward) if approach else r * tail

        def watched(array: FloatArray, free_part: bool) -> FloatArray:
            """``array`` as ``(C, G, A, .)``, HO's column from ``free`` where that part is kept apart."""
            out = np.broadcast_to(array, (C, G, A, array.shape[-1])).copy()
            if tracked and free_part:
                out[:, :, h] = free
            return out

        r0, arrived, end = reward_at()
        self.value[..., 0] = np.where(arrived, 0.0, end)
        self.stay = np.where(arrived, 0.0, r0 * k)[:, :, 0]  # one rollout step standing still, (C, G)
        total = np.zeros((C, G, A))
        zero = np.zeros(1)
        for s in range(steps):
            u_lin = user_linear(P, gp, pre, speed[0], standoff) if translating else zero
            u_ang = zero if translating else user_angular(Q, gq, speed[1])
            r_lin = np.where(move_m, move_linear(P, approach_points(P, Q, mp, mq, cfg.move), cfg.move), 0.0)
            r_ang = np.where(move_m, move_angular(Q, mq, cfg.move), 0.0)
            if ho:  # HO under its belief, after the user's twist
                w = np.exp(log_w - log_w.max(axis=-1, keepdims=True))
                if translating:
                    p1 = P[:, :, h] + u_lin[:, :, h] * t_apply
                    q1 = free if tracked else Q[:, :, h]
                else:
                    p1 = free if tracked else P[:, :, h]
                    q1 = turn(Q[:, :, h], u_ang[:, :, h], t_apply)
                aim = approach_points(p1[..., None, :], q1[..., None, :], kp, kq, cfg.move)
                ho_lin, ho_ang = ho_linear(p1, aim, w, cfg), ho_angular(q1, kq, w, cfg)
                if not (tracked and not translating):
                    r_lin[:, :, h] = ho_lin
                if not (tracked and translating):
                    r_ang[:, :, h] = ho_ang
                if tracked and s + 1 < steps:
                    log_w = log_w - samples * q_minus_v_driven(
                        P[:, :, h] if translating else free, Q[:, :, h], u_lin[:, :, h] if translating else None,
                        None if translating else u_ang[:, :, h], kp, kq, cfg.intent, rot_scale, anchor)
            t_lin = np.where(none_m, u_lin, (1.0 - alpha) * u_lin + alpha * r_lin)
            t_ang = np.where(none_m, u_ang, (1.0 - alpha) * u_ang + alpha * r_ang)
            opposed = opposes(u_lin, r_lin, th) | opposes(u_ang, r_ang, th)  # (HO's free part: no input there)
            step_penalty = np.where(opposed & ~arrived, per_step, 0.0)
            if s < watch_steps:  # only the driven part enters the likelihood: HO's is in P or Q
                driven = (np.broadcast_to(P, (C, G, A, 3)) if translating else watched(P, free_part=True),
                          np.broadcast_to(Q, (C, G, A, 4)),
                          np.broadcast_to(u_lin, (C, G, A, 3)) if translating else None,
                          None if translating else np.broadcast_to(u_ang, (C, G, A, 3)))
                if poses is None:
                    loglik -= samples * q_minus_v_driven(*driven, kp, kq, cfg.intent, rot_scale, anchor)
                else:
                    loglik -= rate * marginal_nll_driven(*driven, *poses, cfg.intent, anchor)
            P = P + t_lin * dt
            Q = turn(Q, t_ang, dt)
            if tracked:  # the user does not drive this part: HO's share of the blend alone
                free = turn(free, alpha * ho_ang, dt) if translating else free + alpha * ho_lin * dt
            r, reached, end = reward_at()
            total = total + np.where(arrived, 0.0, r * k + step_penalty + np.where(reached, cfg.reward.goal, 0.0))
            arrived = arrived | reached
            self.value[..., s + 1] = total + np.where(arrived, 0.0, end)
            if s + 1 == watch_steps:
                self.watch_positions = watched(P, free_part=not translating)
                self.watch_quats = watched(Q, free_part=translating)
                self.watch_return = total.copy()  # the return so far, without the terminal charge
        self.loglik = loglik

    def join(self) -> None:
        """Wait for rollouts started in the ``background``, this thread taking its share (no-op otherwise)."""
        if self._pending is not None:
            self._pending.join()
            self._pending = None

    def cancel(self) -> None:
        """Stop rollouts started in the ``background`` (the starts in progress finish); the arrays are
        incomplete and not to be read."""
        if self._pending is not None:
            self._pending.cancel()
            self._pending = None

    def _no_watch(self, C: int, G: int, A: int) -> None:
        """The watch arrays without watched steps: empty, ``(C, G, 0, ...)``."""
        self.watch_positions = np.empty((C, G, 0, 3))
        self.watch_quats = np.empty((C, G, 0, 4))
        self.watch_return = np.empty((C, G, 0))
        self.loglik = np.zeros((C, G, A, 0))

    @staticmethod
    def _start_marginal(cfg: Config, positions: FloatArray, quats: FloatArray, kp: FloatArray, kq: FloatArray,
                        pregrasp: FloatArray, anchor: FloatArray, poses: tuple[FloatArray, FloatArray], mode: Mode,
                        speed: tuple[float, float], dt: float, A: int) -> FloatArray:
        """``loglik`` ``(C, G, A, G)`` of a one-step watch under the tracker's marginal: at each start, the
        input predicted for a user heading to each goal, read for one rollout step (the same for every
        action: the arm has not moved yet)."""
        C, G = len(positions), len(kp)
        P = np.broadcast_to(positions[:, None, :], (C, G, 3))
        Q = np.broadcast_to(quats[:, None, :], (C, G, 4))
        if Mode(mode) is Mode.TRANSLATION:
            u = user_linear(P, kp[None], pregrasp[None], speed[0], cfg.intent.user_standoff_m)
            nll = marginal_nll_driven(P, Q, u, None, *poses, cfg.intent, anchor)
        else:
            nll = marginal_nll_driven(P, Q, None, user_angular(Q, kq[None], speed[1]), *poses, cfg.intent, anchor)
        rate = cfg.runtime.belief_hz * dt
        return np.broadcast_to((-rate * nll)[:, :, None, :], (C, G, A, G)).copy()

    def _compiled(self, cfg: Config, positions: FloatArray, quats: FloatArray, weights: FloatArray, kp: FloatArray,
                  kq: FloatArray, pregrasp: FloatArray, anchor: FloatArray, actions: list[Action], mode: Mode,
                  speed: tuple[float, float], steps: int, dt: float, watch_steps: int, background: bool) -> None:
        """The same rollouts by :func:`.kernel.roll` (one compiled loop per rollout)."""
        C, G, A = len(positions), len(kp), len(actions)
        kind = np.array([kernel.MOVE if a.kind is ActionKind.MOVE else kernel.HO if a.kind is ActionKind.HO
                         else kernel.NONE for a in actions], dtype=np.int64)
        targets = np.array([a.goal if a.kind is ActionKind.MOVE else 0 for a in actions], dtype=np.int64)
        fp, hp, rp = kernel.parameters(cfg, speed, dt)
        self.value = np.empty((C, G, A, steps + 1))
        self.stay = np.empty((C, G))
        if watch_steps:  # filled by the kernel
            self.watch_positions = np.empty((C, G, A, 3))
            self.watch_quats = np.empty((C, G, A, 4))
            self.watch_return = np.empty((C, G, A))
            self.loglik = np.zeros((C, G, A, G))
        else:
            self._no_watch(C, G, A)
        inputs = (np.ascontiguousarray(positions, dtype=float), np.ascontiguousarray(quats, dtype=float),
                  np.log(np.maximum(np.asarray(weights, dtype=float), 1e-300)),
                  np.ascontiguousarray(kp, dtype=float), np.ascontiguousarray(kq, dtype=float),
                  np.ascontiguousarray(pregrasp, dtype=float), anchor, kind, targets,
                  Mode(mode) is Mode.TRANSLATION, cfg.planner.ho_belief == "tracked",
                  cfg.planner.terminal == "approach", steps, watch_steps, dt, fp, hp, rp)
        self._pending = Pending(threads(cfg), inputs, (self.value, self.stay, self.watch_positions, self.watch_quats,
                                                       self.watch_return, self.loglik), background)
        if not background:
            self.join()
