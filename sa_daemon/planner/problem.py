"""One planning problem: the parts of the POMDP that do not depend on the belief, precomputed.

The structure the solver exploits (section III-B): the goal is static, a question leaves the state
unchanged, a move ends the episode. So, for a fixed snapshot, the reward of a move-to-goal or no-assist
action is a fixed vector over goals, ``M[:, a]``, and the value of a belief ``b`` reachable by answers is

    V(b) = max( max_a b . M[:, a],  b . R_HO(b),  max_q  r_q + gamma * sum_z P(z | b, q) V(b_z) ).

Only the HO action depends on the belief (its twist is belief-weighted), so its reward is rolled out per
belief, in batches.

Lookahead (``reward.lookahead_steps = H``): a move is judged at the pose it reaches after ``H`` steps of
``reward.step_s``, the robot twist recomputed from the pose at every step and the user's twist held at its
last value (the paper's ``a_{h,t} ~ a_{h,t-1}``); ``H = 1`` is the literal one-step reading. Opposition is
judged on the first step, where the user's twist is known. Each goal is represented by its ``k_c``.
"""

from __future__ import annotations

import numpy as np

from ..geometry import FloatArray, integrate_pose, quat_angle, rotvec_to_quat, quat_mul
from .actions import HO_ACTION, Action, ActionKind, blend, ho_twist, move_twist
from .huber import goal_gradients, max_gradient_speeds
from .model import SharedAutonomyModel
from .reward import distance_reward, distance_reward_upper_bound, opposes, opposition_reward
from .snapshot import Snapshot


class Problem:
    """Precomputed search data for one :class:`Snapshot` (see module doc)."""

    def __init__(self, model: SharedAutonomyModel, snap: Snapshot) -> None:
        cfg = model.cfg
        self.cfg = cfg
        self.snap = snap
        goals = snap.goals
        self.b0 = snap.probs
        self.kp, self.kq = goals.desired_poses(snap.pose, cfg.intent.rotation_weight_m_per_rad)
        moves, self.questions = model.action_set(snap.method, goals, self.b0, snap.pose, snap.asked)
        self.moves = [a for a in moves if a.kind is not ActionKind.HO]
        self.has_ho = len(self.moves) < len(moves)
        self.u = snap.user_twist
        self.H = cfg.reward.lookahead_steps
        self.dt = cfg.reward.step_s
        self.gamma = cfg.reward.gamma
        self.q_reward = cfg.reward.question
        # M[g, a]: reward of static move a if the goal is g.
        self.M = self._static_rewards() if self.moves else np.zeros((len(goals), 0))
        # L_yes[q, g] = P(yes | g, question q).
        p = cfg.intent.answer_p_correct
        ti = goals.target_index
        qi = np.array([goals.targets.index(q.target) for q in self.questions], dtype=int)
        self.L_yes = np.where(qi[:, None] == ti[None, :], p, 1.0 - p)
        self.U = self._upper_bounds()

    # -- static moves ------------------------------------------------------------------------------------

    def _rewards_at(self, positions: FloatArray, quats: FloatArray) -> FloatArray:
        """Distance rewards ``(..., G)`` of final poses ``(..., 3/4)`` w.r.t. every goal's ``k_c``."""
        d_t = np.linalg.norm(positions[..., None, :] - self.kp, axis=-1)
        d_r = quat_angle(quats[..., None, :], self.kq)
        return distance_reward(d_t, d_r, self.cfg.reward)

    def _static_rewards(self) -> FloatArray:
        pose, u, cfg = self.snap.pose, self.u, self.cfg
        n = len(self.moves)
        pos = np.tile(pose.position, (n, 1))
        quat = np.tile(pose.quat_wxyz, (n, 1))
        goal_idx = np.array([a.goal if a.kind is ActionKind.MOVE else -1 for a in self.moves])
        is_move = goal_idx >= 0
        gp = self.kp[np.maximum(goal_idx, 0)]
        gq = self.kq[np.maximum(goal_idx, 0)]
        opposed = np.zeros(n, dtype=bool)
        for step in range(self.H):
            r = move_twist(pos, quat, gp, gq, cfg.move)
            r[~is_move] = 0.0
            total = np.where(is_move[:, None], blend(u, r, cfg.blend), u)
            if step == 0:
                opposed = opposes(u, r, cfg.reward.opposition_threshold)
            pos, quat = integrate_pose(pos, quat, total, self.dt)
        rewards = self._rewards_at(pos, quat) + opposition_reward(opposed, cfg.reward)[:, None]
        return rewards.T  # (G, A)

    # -- HO, per belief ----------------------------------------------------------------------------------

    def ho_rewards(self, beliefs: FloatArray) -> FloatArray:
        """Reward of the HO action for each goal under each belief: ``(n, G)`` for beliefs ``(n, G)``."""
        cfg, u = self.cfg, self.u
        beliefs = np.atleast_2d(beliefs)
        n = beliefs.shape[0]
        pos = np.tile(self.snap.pose.position, (n, 1))
        quat = np.tile(self.snap.pose.quat_wxyz, (n, 1))
        opposed = np.zeros(n, dtype=bool)
        for step in range(self.H):
            grads = goal_gradients(pos, quat, u, self.kp, self.kq, cfg.intent, cfg.ho)
            r = ho_twist(beliefs, grads)
            if step == 0:
                opposed = opposes(u, r, cfg.reward.opposition_threshold)
            pos, quat = integrate_pose(pos, quat, blend(u, r, cfg.blend), self.dt)
        return self._rewards_at(pos, quat) + opposition_reward(opposed, cfg.reward)[:, None]

    def best_moves(self, beliefs: FloatArray) -> tuple[FloatArray, list[Action]]:
        """Best move value and action for each belief ``(n, G)``: ``(n,)`` values and ``n`` actions."""
        beliefs = np.atleast_2d(beliefs)
        vals = beliefs @ self.M if self.moves else np.full((beliefs.shape[0], 0), -np.inf)
        if self.has_ho:
            ho = np.sum(beliefs * self.ho_rewards(beliefs), axis=-1)
            vals = np.concatenate((vals, ho[:, None]), axis=1)
        idx = np.argmax(vals, axis=1)
        acts = self.moves + ([HO_ACTION] if self.has_ho else [])
        return vals[np.arange(len(idx)), idx], [acts[i] for i in idx]

    # -- bounds ------------------------------------------------------------------------------------------

    def _upper_bounds(self) -> FloatArray:
        """Per-goal upper bound ``U_g`` on the value of any policy if the goal is ``g``.

        Any policy asks ``k >= 0`` questions then moves with reward ``R``; its discounted return
        ``r_q (1 - gamma^k) / (1 - gamma) + gamma^k R`` is at most ``max(R, r_q / (1 - gamma))``. ``R`` of a
        static move is known exactly; HO's depends on the belief, so it is bounded by the best reward of
        any pose its bounded-speed twist can reach (``docs/model.md``).
        """
        cfg = self.cfg
        floor = self.q_reward / (1.0 - self.gamma) if self.gamma < 1.0 else -np.inf
        best = np.full(len(self.kp), floor)
        if self.moves:
            best = np.maximum(best, self.M.max(axis=1))
        if self.has_ho:
            alpha, T = cfg.blend.alpha, self.H * self.dt
            v_max, w_max = max_gradient_speeds(cfg.intent, cfg.ho)
            pose = self.snap.pose
            p_user = pose.position + (1.0 - alpha) * self.u[:3] * T
            q_user = quat_mul(rotvec_to_quat((1.0 - alpha) * self.u[3:] * T), pose.quat_wxyz)
            d = np.linalg.norm(self.kp - p_user, axis=-1)
            slack_t, slack_r = alpha * v_max * T, alpha * w_max * T
            d_rot = quat_angle(self.kq, q_user)
            ub = distance_reward_upper_bound(
                np.maximum(0.0, d - slack_t - 1e-9), d + slack_t + 1e-9, np.maximum(0.0, d_rot - slack_r - 1e-9),
                cfg.reward,
            )
            best = np.maximum(best, ub)
        return best
