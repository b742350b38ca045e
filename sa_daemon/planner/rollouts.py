"""Rollouts of the watch model: every (user goal, motion action) pair integrated from a set of start poses.

A row of the batch is one start pose ``c``, one goal ``g`` the user heads to and one motion action ``a``
(move-to-goal, HO, no-assist). At every step of ``dt`` seconds the user's twist is the one predicted for a
user heading to ``g`` (:func:`~..model.twists.user_twist_toward`, current mode, smoothed speed), the
robot's twist is ``a``'s velocity generator at the row's pose (HO weighted by the start's belief), and
the pose moves by their blend (the user's alone for no-assist). Recorded per row and step ``s``:

* ``value[c, g, a, s]``: ``Phi_g(x_s) + P_s``, the distance reward of section III-E of goal ``g`` (to its
  ``k_c``, with the +100 bonus) at the pose after ``s`` steps, plus the opposition penalties charged so
  far (``-5`` per ``reward.step_s`` of predicted opposition, so a rate independent of ``dt``);
* the pose and the penalties after ``watch_steps`` steps, and ``loglik[c, g, a, :]``, the MaxEnt IOC
  log-likelihood the belief tracker would add over those steps (``-(Q_g' - V_g')`` per input sample,
  ``runtime.belief_hz`` samples a second).

Committing to ``a`` for ``s`` steps from start ``c`` under belief ``b`` is worth
``sum_g b(g) value[c, g, a, s]``.
"""

from __future__ import annotations

import numpy as np

from ..config import Config
from ..geometry import FloatArray, integrate_pose, quat_angle
from ..model.actions import Action, ActionKind, Mode
from ..model.huber import q_minus_v_at
from ..model.reward import distance_reward, opposes, opposition_reward
from ..model.twists import (
    blend,
    ho_goal_twists,
    ho_twist,
    move_twist,
    user_twist_toward,
)


class Rollouts:
    """The batch of the module doc. Arrays are read-only results; construction does all the work.

    ``positions`` ``(C, 3)`` and ``quats`` ``(C, 4)`` are the start poses, ``weights`` ``(C, G)`` the
    belief HO uses at each, ``kp``/``kq`` the goals' ``k_c`` (``(G, 3)``, ``(G, 4)``), ``actions`` the
    motion actions (moves index ``kp``), ``steps`` the number of ``dt`` steps.
    """

    def __init__(self, cfg: Config, positions: FloatArray, quats: FloatArray, weights: FloatArray,
                 kp: FloatArray, kq: FloatArray, actions: list[Action], mode: Mode, speed: tuple[float, float],
                 steps: int, dt: float, watch_steps: int = 0) -> None:
        C, G, A = len(positions), len(kp), len(actions)
        self.shape = (C, G, A)
        kinds = np.array([[a.kind is ActionKind.MOVE, a.kind is ActionKind.HO, a.kind is ActionKind.NONE]
                          for a in actions], dtype=bool).reshape(A, 3)
        target = np.array([a.goal if a.kind is ActionKind.MOVE else 0 for a in actions], dtype=int)
        # Flat rows in (c, g, a) order.
        c_idx, g_idx, a_idx = (ix.ravel() for ix in np.meshgrid(np.arange(C), np.arange(G), np.arange(A),
                                                                  indexing="ij"))
        is_move, is_ho, is_none = kinds[a_idx, 0], kinds[a_idx, 1], kinds[a_idx, 2]
        pos, quat = positions[c_idx].copy(), quats[c_idx].copy()
        ugp, ugq = kp[g_idx], kq[g_idx]  # where each row's user heads (and whose reward it earns)
        mgp, mgq = kp[target[a_idx]][is_move], kq[target[a_idx]][is_move]
        ho_w = weights[c_idx[is_ho]]
        per_step = opposition_reward(True, cfg.reward) * dt / cfg.reward.step_s
        samples = cfg.runtime.belief_hz * dt  # tracker updates per rollout step
        value = np.empty((len(c_idx), steps + 1))
        penalty = np.zeros(len(c_idx))
        loglik = np.zeros((len(c_idx), G))

        def phi(p: FloatArray, q: FloatArray) -> FloatArray:
            return distance_reward(np.linalg.norm(p - ugp, axis=-1), quat_angle(q, ugq), cfg.reward)

        value[:, 0] = phi(pos, quat)
        for s in range(steps):
            u = user_twist_toward(pos, quat, ugp, ugq, mode, speed)
            r = np.zeros_like(u)
            if is_move.any():
                r[is_move] = move_twist(pos[is_move], quat[is_move], mgp, mgq, cfg.move)
            if is_ho.any():
                grads = ho_goal_twists(pos[is_ho], quat[is_ho], u[is_ho], kp, kq, cfg)
                r[is_ho] = ho_twist(ho_w, grads)
            total = np.where(is_none[:, None], u, blend(u, r, cfg.blend))
            penalty += np.where(opposes(u, r, cfg.reward.opposition_threshold), per_step, 0.0)
            if s < watch_steps:
                loglik -= samples * q_minus_v_at(pos, quat, u, kp, kq, cfg.intent)
            pos, quat = integrate_pose(pos, quat, total, dt)
            value[:, s + 1] = phi(pos, quat) + penalty
            if s + 1 == watch_steps:
                self.watch_positions = pos.reshape(C, G, A, 3)
                self.watch_quats = quat.reshape(C, G, A, 4)
                self.watch_penalty = penalty.reshape(C, G, A).copy()
        self.value = value.reshape(C, G, A, steps + 1)
        self.loglik = loglik.reshape(C, G, A, G)

    def commit_matrix(self, c: int, s: int) -> FloatArray:
        """``M[g, a]``: the value of committing to action ``a`` for ``s`` steps from start ``c`` if the goal
        is ``g``."""
        return self.value[c, :, :, s]
