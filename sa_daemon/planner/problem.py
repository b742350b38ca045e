"""One planning problem: the POMDP of one snapshot, reduced to a reward matrix.

The structure the solver exploits (section III-B): the goal is static, a question leaves the state
unchanged, a move ends the episode. So, for a fixed snapshot, the reward of every move action is a fixed
vector over goals, ``M[:, a]``, and the value of a belief ``b`` reachable by answers is

    V(b) = max( max_a b . M[:, a],  max_q  r_q + gamma * sum_z P(z | b, q) V(b_z) ).

The HO action's twist is computed once, from the belief at planning time: a POMDP reward ``R(s, a)``
cannot depend on the belief, and this is also what a particle-based solver such as the paper's
HyP-DESPOT does. After hypothetical answers inside the search the HO action keeps that twist
(``docs/model.md``).

Lookahead (``reward.lookahead_steps = H``): a move is judged at the pose it reaches after ``H`` steps of
``reward.step_s``, the robot twist recomputed from the pose at every step (HO with the planning-time
belief) and the user's twist held at its last value (the paper's ``a_{h,t} ~ a_{h,t-1}``); ``H = 1`` is the
literal one-step reading. The opposition penalty is charged at every step of the window where the
robot's twist opposes the held user twist (``reward.opposition_every_step``, the default: a move that
keeps fighting the user for ``H`` steps costs ``H`` penalties), or only on the first step, where the
user's twist is known (the paper's one-step reading). Each goal is represented by its ``k_c``.
"""

from __future__ import annotations

import numpy as np

from ..geometry import FloatArray, integrate_pose, quat_angle
from ..model.actions import Action, ActionKind
from ..model.model import SharedAutonomyModel
from ..model.reward import distance_reward, opposes, opposition_reward
from ..model.twists import blend, ho_robot_twist, move_twist
from .answers import yes_likelihood
from .snapshot import Snapshot


class Problem:
    """The reward matrix, answer likelihoods and bounds of one :class:`Snapshot` (see module doc)."""

    def __init__(self, model: SharedAutonomyModel, snap: Snapshot) -> None:
        cfg = model.cfg
        self.cfg = cfg
        self.snap = snap
        goals = snap.goals
        self.b0 = snap.probs
        self.kp, self.kq = (model.reach_poses(goals, snap.pose, snap.pose_log_w, snap.probs)
                            or model.desired_poses(goals, snap.pose, snap.probs))
        self.moves, self.questions = model.action_set(snap.method, goals, self.b0, snap.pose, snap.asked)
        self.u = snap.user_twist
        self.H = cfg.reward.lookahead_steps
        self.dt = cfg.reward.step_s
        self.gamma = cfg.reward.gamma
        self.q_reward = cfg.reward.question
        # M[g, a]: reward of move a if the goal is g.
        self.M = self._move_rewards() if self.moves else np.zeros((len(goals), 0))
        self.q_reward = self.q_reward - self._question_time_cost()
        self.L_yes = yes_likelihood(self.questions, goals, cfg.intent.answer_p_correct)  # P(yes | g, question q)
        self.U = self._upper_bounds()

    def _rewards_at(self, positions: FloatArray, quats: FloatArray) -> FloatArray:
        """Distance rewards ``(..., G)`` of final poses ``(..., 3/4)`` w.r.t. every goal's ``k_c``."""
        d_t = np.linalg.norm(positions[..., None, :] - self.kp, axis=-1)
        d_r = quat_angle(quats[..., None, :], self.kq)
        return distance_reward(d_t, d_r, self.cfg.reward)

    def _robot_twists(self, pos: FloatArray, quat: FloatArray) -> FloatArray:
        """Robot twist of every move action at its own rollout pose, ``(A, 6)``."""
        cfg, out = self.cfg, np.zeros((len(self.moves), 6))
        if self._is_goal.any():
            out[self._is_goal] = move_twist(
                pos[self._is_goal], quat[self._is_goal], self._gp, self._gq, cfg.move
            )
        if self._ho >= 0:
            out[self._ho] = ho_robot_twist(pos[self._ho], quat[self._ho], self.u, self.kp, self.kq, self.b0, cfg)
        return out

    def _move_rewards(self) -> FloatArray:
        """Roll every move out for ``H`` steps and score the final poses: ``(G, A)``."""
        pose, u, cfg = self.snap.pose, self.u, self.cfg
        n = len(self.moves)
        kinds = [a.kind for a in self.moves]
        self._is_goal = np.array([k is ActionKind.MOVE for k in kinds])
        goal_idx = [a.goal for a in self.moves if a.kind is ActionKind.MOVE]
        self._gp, self._gq = self.kp[goal_idx], self.kq[goal_idx]
        self._ho = kinds.index(ActionKind.HO) if ActionKind.HO in kinds else -1
        blended = np.array([k is not ActionKind.NONE for k in kinds])  # no-assist: the user's twist alone
        pos = np.tile(pose.position, (n, 1))
        quat = np.tile(pose.quat_wxyz, (n, 1))
        penalty = np.zeros(n)
        for step in range(self.H):
            r = self._robot_twists(pos, quat)
            total = np.where(blended[:, None], blend(u, r, cfg.blend), u)
            if step == 0 or cfg.reward.opposition_every_step:
                penalty += opposition_reward(opposes(u, r, cfg.reward.opposition_threshold), cfg.reward)
            pos, quat = integrate_pose(pos, quat, total, self.dt)
        rewards = self._rewards_at(pos, quat) + penalty[:, None]
        if cfg.reward.discount_lookahead:
            rewards = rewards * self.gamma**self.H  # received when the pose is reached
        return rewards.T

    def _question_time_cost(self) -> float:
        """Progress a question forgoes (reward units, >= 0): while it is asked and answered
        (``question_time_s``, the snapshot's where it has one) nothing moves, so it costs that share of the
        lookahead window's gain of the best move over staying put, at the planning-time belief. Constant
        per snapshot, so the solver's bounds (which need ``r_q`` to be one number) stay valid; 0 with
        ``question_time_s = 0``."""
        t_q = self.snap.question_seconds(self.cfg.reward.question_time_s)
        if t_q <= 0.0 or not self.moves:
            return 0.0
        pose = self.snap.pose
        stay = self._rewards_at(pose.position[None, :], pose.quat_wxyz[None, :])[0]
        gain = float(self.move_values(self.b0)[0] - self.b0 @ stay)
        return max(0.0, gain) * t_q / (self.H * self.dt)

    def move_values(self, beliefs: FloatArray) -> FloatArray:
        """Value of the best move for each belief ``(n, G)``: ``(n,)`` (``-inf`` with no move)."""
        beliefs = np.atleast_2d(beliefs)
        return (beliefs @ self.M).max(axis=1) if self.moves else np.full(len(beliefs), -np.inf)

    def best_moves(self, beliefs: FloatArray) -> tuple[FloatArray, list[Action]]:
        """Best move value and action for each belief ``(n, G)``: ``(n,)`` values and ``n`` actions."""
        vals = np.atleast_2d(beliefs) @ self.M
        idx = np.argmax(vals, axis=1)
        return vals[np.arange(len(idx)), idx], [self.moves[i] for i in idx]

    def _upper_bounds(self) -> FloatArray:
        """Per-goal upper bound ``U_g`` on the value of any policy if the goal is ``g``.

        Any policy asks ``k >= 0`` questions then moves with reward ``R``; its discounted return
        ``r_q (1 - gamma^k) / (1 - gamma) + gamma^k R`` is at most ``max(R, r_q / (1 - gamma))``, and
        ``R <= max_a M[g, a]``: the full-information value.
        """
        floor = self.q_reward / (1.0 - self.gamma) if self.gamma < 1.0 else -np.inf
        best = np.full(len(self.kp), floor)
        if self.moves:
            best = np.maximum(best, self.M.max(axis=1))
        return best
