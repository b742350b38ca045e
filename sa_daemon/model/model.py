"""The POMDP model of the paper as one pure object, shared by the planner, the evaluation and the daemon.

It holds no state of its own beyond its configuration: the belief, the pose and the user's twist are
passed in. It answers

* how the belief changes (joystick input, answers, resampling) - observation model, section III-D;
* which actions exist (top ``G_m`` goals, method) - section III-B;
* what twist an action commands now, blended with the user's - the velocity command generator;
* what an action is worth - the reward, section III-E (with the lookahead rollouts in :mod:`.problem`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..config import Config
from ..geometry import FloatArray, Pose, quat_angle
from ..world.goalset import GoalSet
from .actions import HO_ACTION, NO_ASSIST, Action, ActionKind
from .belief import Belief
from .huber import mixture_nll, tracked_pose_scores, tracker_pose_values
from .methods import MethodSpec, method_spec
from .reward import opposes
from .twists import blend, ho_robot_twist, move_twist

ZERO_TWIST = np.zeros(6)


def _first_positions(targets_in_order: np.ndarray, n_targets: int) -> np.ndarray:
    """``(n_targets,)``: where each target first appears in ``targets_in_order`` (the target index of
    each goal, in a ranking's order), i.e. the position of its highest-ranked copy; ``len`` for a target
    with no goal."""
    first = np.full(n_targets, len(targets_in_order))
    present, at = np.unique(targets_in_order, return_index=True)
    first[present] = at
    return first


@dataclass(frozen=True)
class Command:
    """What one control tick sends: the action actually applied (``ho+noassist`` may turn HO into
    no-assist), the robot's twist, the blended total (m/s, rad/s) and whether the robot opposed the user."""

    action: Action
    robot_twist: FloatArray
    total_twist: FloatArray
    opposed: bool


class SharedAutonomyModel:
    """Transition, observation and reward of the shared-autonomy POMDP (pure; see module doc)."""

    def __init__(self, cfg: Config | None = None) -> None:
        self.cfg = cfg or Config()

    # -- belief (observation model) ----------------------------------------------------------------------

    def initial_belief(self, goals: GoalSet | tuple) -> Belief:
        """Uniform prior over the scene's goals."""
        return Belief.uniform(goals)

    def update_input(self, belief: Belief, pose: Pose, user_twist: FloatArray) -> Belief:
        """Joystick observation at one input sample, then resampling if it is due."""
        return belief.after_input(pose, user_twist, self.cfg.intent).resampled(pose, self.cfg.intent)

    def update_answer(self, belief: Belief, target: str, answer: bool | str) -> Belief:
        """Answer observation to the question about ``target``: ``"yes"``/``True``, ``"no"``/``False``, or
        ``"other"`` (that object, another grasp: ``asking.third_answer``)."""
        if answer == "other":
            return belief.after_other_grasp(target, self.cfg.intent)
        return belief.after_answer(target, answer in (True, "yes"), self.cfg.intent)

    # -- actions -------------------------------------------------------------------------------------------

    def candidate_goals(self, goals: GoalSet, probs: FloatArray, pose: Pose,
                        desired: tuple[FloatArray, FloatArray] | None = None) -> np.ndarray:
        """Indices of the top ``G_m`` goals by probability, ties broken by distance to the gripper.
        ``desired``: the goals' ``k_c`` at ``pose`` (``GoalSet.desired_poses``) if the caller has them.

        The probability is ``planner.rank_goals``'s: ``"goal"`` (the paper's words) each goal's
        own, so a likely target that resampling split five ways ranks each copy at a fifth of it, behind
        every unsplit target above that; ``"lead"`` the same, but each target's likeliest copy (the nearest
        of equals) by the whole target's; ``"target"`` every goal by its target's, then by its own
        (screened in session 32 and left off: ``docs/model.md``); ``"cover"`` the goals ``"goal"`` ranks,
        but the likeliest copy of each of the ``planner.cover_targets`` likeliest targets always among
        them, in place of the last of the others (session 33, the default since: the fewest changes that
        keep a likely split target in the plan). The result keeps ``"goal"``'s order, so ``"cover"``
        equals ``"goal"`` whenever those copies already rank among the top ``G_m``."""
        if desired is None:
            desired = self.desired_poses(goals, pose, probs)
        kp, kq = desired
        p = np.asarray(probs, dtype=float)
        dist = np.linalg.norm(kp - pose.position, axis=-1)
        dist = dist + self.cfg.intent.rotation_weight_m_per_rad * quat_angle(kq, pose.quat_wxyz)
        order = np.lexsort((dist, -p))
        rank = self.cfg.planner.rank_goals
        g_m = self.cfg.planner.top_goals
        if rank == "cover":
            return self._covered(goals, p, order, g_m)
        if rank != "goal":
            ti = goals.target_index
            tp = goals.target_sums(p)[ti]
            if rank == "lead":
                lead = np.zeros(len(p), dtype=bool)
                lead[order[_first_positions(ti[order], len(goals.targets))]] = True
                tp = np.where(lead, tp, p)
            order = np.lexsort((dist, -p, -tp))
        return order[:g_m]

    def _covered(self, goals: GoalSet, p: FloatArray, order: np.ndarray, g_m: int) -> np.ndarray:
        """``"cover"``'s top ``G_m`` goals from ``"goal"``'s ``order``: the likeliest copy (first in
        ``order``) of each of the ``planner.cover_targets`` likeliest targets (ties: the target whose
        likeliest copy comes first in ``order``, so that unsplit targets rank as ``"goal"`` ranks them),
        then the rest of ``order`` to ``G_m`` goals, returned in ``order``'s order."""
        sums = goals.target_sums(p)
        lead = _first_positions(goals.target_index[order], len(sums))
        top = np.lexsort((lead, -sums))[: min(self.cfg.planner.cover_targets, g_m)]
        chosen = np.zeros(len(order), dtype=bool)  # over positions in ``order``
        chosen[lead[top]] = True
        chosen[np.flatnonzero(~chosen)[: g_m - int(chosen.sum())]] = True
        return order[chosen]

    def action_set(
        self, method: str | MethodSpec, goals: GoalSet, probs: FloatArray, pose: Pose, asked: frozenset[str]
    ) -> tuple[list[Action], list[Action]]:
        """(move actions, question actions) available to a planned method.

        Move-to-goal and questions for the top ``G_m`` goals (questions deduplicated by high-level target
        and never about a target already asked: a repeated question costs ``repeated_question`` and is
        left out of the search), plus HO and no-assist as the method allows.
        """
        return self.actions_for(method, goals, self.candidate_goals(goals, probs, pose), asked)

    @staticmethod
    def actions_for(
        method: str | MethodSpec, goals: GoalSet, cands: np.ndarray, asked: frozenset[str]
    ) -> tuple[list[Action], list[Action]]:
        """:meth:`action_set` for the candidate goals ``cands`` (:meth:`candidate_goals`)."""
        spec = method if isinstance(method, MethodSpec) else method_spec(method)
        moves: list[Action] = []
        if spec.moves:
            moves += [Action(ActionKind.MOVE, int(i), goals.goals[i].target) for i in cands]
        if spec.ho:
            moves.append(HO_ACTION)
        if spec.noassist:
            moves.append(NO_ASSIST)
        questions: list[Action] = []
        if spec.questions:
            seen: set[str] = set(asked)
            for i in cands:
                t = goals.goals[i].target
                if t not in seen:
                    seen.add(t)
                    questions.append(Action(ActionKind.QUESTION, None, t))
        return moves, questions

    def fixed_action(self, method: str, goals: GoalSet, probs: FloatArray) -> Action:
        """The action of a rule-based baseline (``manual``, ``ho``, ``ho+noassist``, ``blend``)."""
        spec = method_spec(method)
        if spec.planned:
            raise ValueError(f"method {method!r} is planned, not rule-based")
        if spec.name == "manual":
            return NO_ASSIST
        if spec.name in ("ho", "ho+noassist"):
            return HO_ACTION
        tp = goals.target_probabilities(np.asarray(probs))
        ranked = sorted(tp.values(), reverse=True) + [0.0]
        if ranked[0] - ranked[1] > self.cfg.blend.predict_margin:
            top = max(tp, key=tp.__getitem__)
            copies = np.flatnonzero(goals.target_mask(top))
            i = copies[np.argmax(np.asarray(probs)[copies])]
            return Action(ActionKind.MOVE, int(i), top)
        return NO_ASSIST

    def remap_action(self, action: Action, old: GoalSet, new: GoalSet, pose: Pose) -> Action:
        """Carry a move action across a resampling that replaced the goal set.

        The new goal is the copy of the same high-level target that owns the old goal's ``k_c``
        (redistribution keeps the pose objects), else that target's first copy.
        """
        if action.kind is not ActionKind.MOVE or old is new:
            return action
        w = self.cfg.intent.rotation_weight_m_per_rad
        kc = old.goals[action.goal].desired_pose(pose, w)
        same = [int(i) for i in np.flatnonzero(new.target_mask(action.target))]
        owner = [i for i in same if any(p is kc for p in new.goals[i].poses)]
        return Action(ActionKind.MOVE, (owner or same)[0], action.target)

    # -- velocity commands ---------------------------------------------------------------------------------

    def desired_poses(self, goals: GoalSet, pose: Pose,
                      probs: FloatArray | None = None) -> tuple[FloatArray, FloatArray]:
        """``k_c`` of every goal at ``pose``, ``((G, 3), (G, 4))``, as ``intent.copy_reach`` shares it among the
        copies of one target (:meth:`GoalSet.desired_poses`): ``own`` each copy its own; ``target`` the
        closest over all the target's poses; ``likeliest`` the ``k_c`` of the target's most probable copy
        (``probs``, ``(G,)``; ties and ``None``: the first copy)."""
        w = self.cfg.intent.rotation_weight_m_per_rad
        share = self.cfg.intent.copy_reach
        if share in ("own", "pooled", "ranked"):  # pooled, ranked: a tracked reach's
            return goals.desired_poses(pose, w)
        if share == "target":
            return goals.desired_poses(pose, w, goals.desired_distances(pose, w))
        score = -np.asarray(probs, dtype=float) if probs is not None else np.zeros(len(goals))
        return goals.desired_poses(pose, w, score)

    def reach_poses(self, goals: GoalSet, pose: Pose, pose_log_w: FloatArray | None = None,
                    probs: FloatArray | None = None) -> tuple[FloatArray, FloatArray] | None:
        """The grasp pose each goal is driven to and scored at, ``((G, 3), (G, 4))``, when
        ``intent.reach_pose`` is ``"tracked"`` or ``"tracked_moves"``: the pose the input since the last
        resampling points at (:func:`~.huber.tracked_goal_poses`; ``pose_log_w`` the belief's
        :attr:`~.belief.Belief.pose_log_w`, ``None``: no input yet), shared among the copies of one target as
        ``intent.copy_reach`` says:

        * ``own`` and ``ranked``: each copy its own;
        * ``target``: the pose of highest ``P(g) P(k | g, input) w_k(x | g)`` over the target's copies ``g``
          and their poses ``k`` (:func:`~.huber.tracked_pose_scores` plus ``log probs``; ``probs`` ``(G,)``,
          ``None``: equal), the weights ``w`` normalised over each copy's own poses;
        * ``likeliest``: the tracked pose of the target's most probable copy;
        * ``pooled``: the pose of highest ``P(k | target, input) exp(-V_k)`` over all the target's poses,
          ``pose_log_w`` then the target's posterior (:meth:`reach_log_w`).

        ``None`` with ``"closest"``: the moves and the planner's rollouts take ``k_c`` (:meth:`desired_poses`)
        and HO each goal's lowest-value pose, as they always have. (Under ``"tracked_moves"``
        :meth:`robot_twist` gives these to a move only.)"""
        if self.cfg.intent.reach_pose == "closest":
            return None
        if pose_log_w is None:
            with np.errstate(divide="ignore"):
                pose_log_w = np.log(goals.pose_mask.astype(float))
        share = self.cfg.intent.copy_reach
        if share == "pooled":  # pose_log_w: the target's posterior over its poses (reach_log_w)
            score = np.asarray(pose_log_w) - tracker_pose_values(pose.position, pose.quat_wxyz, goals.positions,
                                                                 goals.quats_wxyz, self.cfg.intent)
            return goals.poses_at(np.argmax(score, axis=1), -np.max(score, axis=1))
        score = tracked_pose_scores(pose.position, pose.quat_wxyz, goals.positions, goals.quats_wxyz, pose_log_w,
                                    self.cfg.intent)
        lender = None  # own, ranked
        if share in ("target", "likeliest"):
            p = np.full(len(goals), 1.0 / len(goals)) if probs is None else np.asarray(probs, dtype=float)
            with np.errstate(divide="ignore"):
                lender = -(np.max(score, axis=1) + np.log(p)) if share == "target" else -p
        return goals.poses_at(np.argmax(score, axis=1), lender)

    def reach_log_w(self, belief: Belief) -> FloatArray | None:
        """The pose log-weights :meth:`reach_poses` picks each goal's pose by: each target's posterior over
        its poses across its copies (:attr:`~.belief.Belief.pose_joint_log_w`) under ``intent.copy_reach =
        "pooled"``, else each goal's over its own (:attr:`~.belief.Belief.pose_log_w`)."""
        if self.cfg.intent.copy_reach == "pooled" and belief.pose_joint_log_w is not None:
            return belief.pose_joint_log_w
        return belief.pose_log_w

    def planning_probs(self, belief: Belief, pose: Pose) -> FloatArray:
        """The goals' probabilities the planner plans with ``(G,)``: the belief's, except under
        ``intent.copy_reach = "ranked"``, where each target keeps its probability and deals it to its copies
        as ``sum_k P(k | target, input) exp(-V_k(x))`` over each copy's poses ``k``
        (:attr:`~.belief.Belief.pose_joint_log_w`, ``V`` at the gripper's ``pose``): the copies are weighed
        by what the input says of the pose, while the belief's own (``intent.copy_weights``) keep the
        target's likelihood of the next input as it was. (The controller's HO still pulls by the
        belief's.)"""
        if self.cfg.intent.copy_reach != "ranked" or belief.pose_joint_log_w is None:
            return belief.probs
        goals = belief.goals
        log_share = -mixture_nll(belief.pose_joint_log_w, tracker_pose_values(
            pose.position, pose.quat_wxyz, goals.positions, goals.quats_wxyz, self.cfg.intent))
        share = np.exp(log_share - np.max(log_share))
        ti = goals.target_index
        within = share / np.bincount(ti, weights=share)[ti]
        probs = goals.target_sums(belief.probs)[ti] * within
        return probs / probs.sum()

    def robot_twist(
        self, action: Action, goals: GoalSet, probs: FloatArray, pose: Pose, user_twist: FloatArray,
        reach: tuple[FloatArray, FloatArray] | None = None,
    ) -> FloatArray:
        """The robot's twist ``a_r`` (m/s, rad/s) for ``action`` at ``pose``; ``reach``: the goals' poses from
        :meth:`reach_poses` (``None``: ``k_c`` for a move, the lowest-value poses for HO; HO ignores them
        under ``intent.reach_pose = "tracked_moves"``)."""
        if action.kind is ActionKind.MOVE:
            if action.goal is None or not 0 <= action.goal < len(goals):
                raise ValueError(f"move action needs a goal index in range, got {action.goal}")
            kp, kq = reach or self.desired_poses(goals, pose, probs)
            return move_twist(pose.position, pose.quat_wxyz, kp[action.goal], kq[action.goal], self.cfg.move)
        if action.kind is ActionKind.HO:
            if self.cfg.intent.reach_pose == "tracked_moves":
                reach = None
            gp, gq = reach or (goals.positions, goals.quats_wxyz)
            return ho_robot_twist(pose.position, pose.quat_wxyz, user_twist, gp, gq, np.asarray(probs), self.cfg)
        return ZERO_TWIST.copy()

    def command(
        self,
        action: Action,
        goals: GoalSet,
        probs: FloatArray,
        pose: Pose,
        user_twist: FloatArray,
        method: str = "policy",
        reach: tuple[FloatArray, FloatArray] | None = None,
    ) -> Command:
        """Blend ``action``'s robot twist with the user's twist (current mode only).

        No-assist passes the user's twist unscaled; a question holds the robot still; ``ho+noassist``
        falls back to no-assist whenever HO opposes the user. ``reach`` as in :meth:`robot_twist`.
        """
        u = np.asarray(user_twist, dtype=float)
        if action.kind is ActionKind.QUESTION:
            return Command(action, ZERO_TWIST.copy(), ZERO_TWIST.copy(), False)
        if action.kind is ActionKind.NONE:
            return Command(action, ZERO_TWIST.copy(), u.copy(), False)
        r = self.robot_twist(action, goals, probs, pose, u, reach)
        opposed = bool(opposes(u, r, self.cfg.reward.opposition_threshold))
        if opposed and method == "ho+noassist":
            return Command(NO_ASSIST, ZERO_TWIST.copy(), u.copy(), False)
        return Command(action, r, blend(u, r, self.cfg.blend), opposed)
