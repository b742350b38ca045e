"""Planner input and output: plain, picklable records that cross the worker-process boundary."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..geometry import FloatArray, Pose
from ..model.actions import Action, ActionKind, Mode
from ..world.goals import Goal
from ..world.goalset import GoalSet


def _log(w: FloatArray) -> FloatArray:
    """``log w`` with ``log 0 = -inf`` (a padded grasp pose), without numpy's warning."""
    with np.errstate(divide="ignore"):
        return np.log(w)


@dataclass(frozen=True, eq=False)
class Snapshot:
    """Everything the planner needs, frozen at one instant.

    ``probs`` are the goals' probabilities the planner plans with
    (:meth:`~..model.model.SharedAutonomyModel.planning_probs`: the belief's, unless ``intent.copy_reach =
    "ranked"``). ``user_twist`` is the user's last commanded twist (m/s, rad/s), already holding only the components of
    ``mode``; ``user_speed`` the user's smoothed speed ``(linear m/s, angular rad/s)``, which the watch
    model's predicted user twists use (``None``: the norms of ``user_twist``); ``asked`` the high-level targets already asked about in this task. ``budget_s`` is the
    wall-clock deadline (``None``: no deadline) and ``node_budget`` a deterministic cap on expanded
    beliefs (``None``: none); with both ``None`` the planner runs to the proven optimum.
    ``questions_left`` caps the questions the rest of the task may hold (the person's
    ``asking.max_per_task``; ``None``: no cap, 0: no question). ``anchor``: where the user last
    translated (m, base frame; :attr:`~..model.belief.Belief.anchor`), from which the watch model's
    tracker measures a turn's charge (``None``: at ``pose``, as a belief that has seen no input).
    ``pose_log_w``: each goal's posterior over its grasp poses, ``(G, K)`` log-weights
    (:attr:`~..model.belief.Belief.pose_log_w`; ``None``: uniform), from which the goals' poses are
    taken under a tracked ``intent.reach_pose`` (under ``intent.copy_reach = "pooled"`` each target's
    posterior over its poses across its copies: :meth:`~..model.model.SharedAutonomyModel.reach_log_w`). ``question_time_s``: how long a question would stop the
    arm for this person (s, :class:`~..control.answer_time.AnswerTime`; ``None``: ``reward.question_time_s``).
    """

    goals: GoalSet
    probs: FloatArray
    pose: Pose
    user_twist: FloatArray
    mode: Mode = Mode.TRANSLATION
    asked: frozenset[str] = frozenset()
    method: str = "policy"
    budget_s: float | None = 0.1
    node_budget: int | None = None
    user_speed: tuple[float, float] | None = None
    questions_left: int | None = None
    anchor: FloatArray | None = None
    pose_log_w: FloatArray | None = None
    question_time_s: float | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.goals, GoalSet):
            object.__setattr__(self, "goals", GoalSet(tuple(self.goals)))
        p = np.array(self.probs, dtype=float)
        u = np.array(self.user_twist, dtype=float)
        if p.shape != (len(self.goals),) or not np.all(np.isfinite(p)) or np.any(p < 0) or p.sum() <= 0:
            raise ValueError("probs must be finite, non-negative, one per goal, with a positive sum")
        if u.shape != (6,) or not np.all(np.isfinite(u)):
            raise ValueError("user_twist must be 6 finite numbers")
        object.__setattr__(self, "probs", p / p.sum())
        object.__setattr__(self, "user_twist", u)
        object.__setattr__(self, "mode", Mode(self.mode))
        object.__setattr__(self, "asked", frozenset(self.asked))
        if self.user_speed is None:
            speed = (float(np.linalg.norm(u[:3])), float(np.linalg.norm(u[3:])))
        else:
            speed = tuple(float(v) for v in self.user_speed)
            if len(speed) != 2 or not all(math.isfinite(v) and v >= 0 for v in speed):
                raise ValueError("user_speed must be two finite, non-negative numbers (m/s, rad/s)")
        object.__setattr__(self, "user_speed", speed)
        a = np.array(self.pose.position if self.anchor is None else self.anchor, dtype=float)
        if a.shape != (3,) or not np.all(np.isfinite(a)):
            raise ValueError("anchor must be None or 3 finite numbers (m)")
        object.__setattr__(self, "anchor", a)
        if self.pose_log_w is not None:
            w = np.array(self.pose_log_w, dtype=float)
            mask = self.goals.pose_mask
            if w.shape != mask.shape or np.isnan(w).any() or np.any(w[mask] == np.inf) or np.any(w[mask] == -np.inf):
                raise ValueError("pose_log_w must be None or (G, K) log-weights, finite on every grasp pose")
            w[~mask] = -np.inf
            object.__setattr__(self, "pose_log_w", w)
        if self.questions_left is not None and (not isinstance(self.questions_left, int) or self.questions_left < 0):
            raise ValueError("questions_left must be None or an integer >= 0")
        t_q = self.question_time_s
        if t_q is not None and not (math.isfinite(t_q) and t_q >= 0):
            raise ValueError("question_time_s must be None or a finite number of seconds >= 0")

    def question_seconds(self, default_s: float) -> float:
        """What a question stops the arm for (s): :attr:`question_time_s`, else ``default_s``
        (``reward.question_time_s``)."""
        return default_s if self.question_time_s is None else float(self.question_time_s)

    def to_dict(self) -> dict:
        """Plain (JSON-ready) form."""
        return {
            "goals": [g.to_dict() for g in self.goals.goals],
            "probs": self.probs.tolist(),
            "pose": self.pose.as_dict(),
            "user_twist": self.user_twist.tolist(),
            "mode": self.mode.value,
            "asked": sorted(self.asked),
            "method": self.method,
            "budget_s": self.budget_s,
            "node_budget": self.node_budget,
            "user_speed": list(self.user_speed),
            "questions_left": self.questions_left,
            "anchor": self.anchor.tolist(),
            "pose_weights": None if self.pose_log_w is None else self._pose_weights().tolist(),
            "question_time_s": self.question_time_s,
        }

    def _pose_weights(self) -> FloatArray:
        """``exp(pose_log_w)``, a grasp pose's weight held at the smallest positive float64 where ``exp``
        would round it to zero (below ``exp(-745)``): zero is a padded pose (:meth:`from_dict`)."""
        w = np.exp(self.pose_log_w)
        return np.where(self.goals.pose_mask, np.maximum(w, np.finfo(float).smallest_subnormal), 0.0)

    @classmethod
    def from_dict(cls, d: dict) -> Snapshot:
        return cls(
            goals=GoalSet(tuple(Goal.from_dict(g) for g in d["goals"])),
            probs=np.asarray(d["probs"], dtype=float),
            pose=Pose.from_dict(d["pose"]),
            user_twist=np.asarray(d["user_twist"], dtype=float),
            mode=Mode(d["mode"]),
            asked=frozenset(d["asked"]),
            method=d["method"],
            budget_s=d["budget_s"],
            node_budget=d["node_budget"],
            user_speed=d.get("user_speed"),
            questions_left=d.get("questions_left"),
            anchor=d.get("anchor"),
            pose_log_w=None if d.get("pose_weights") is None else _log(np.asarray(d["pose_weights"], dtype=float)),
            question_time_s=d.get("question_time_s"),
        )


@dataclass(frozen=True)
class PlanResult:
    """The chosen action and the statistics of the search that chose it.

    ``value`` is the expected discounted reward of the chosen policy (a proven lower bound on the optimum),
    ``upper_bound`` a proven upper bound; ``complete`` means ``value`` is the proven optimum.
    """

    action: Action
    value: float
    upper_bound: float
    depth: int
    nodes: int
    time_ms: float
    complete: bool
    root_values: dict[Action, float] = field(default_factory=dict)

    @property
    def gap(self) -> float:
        return max(0.0, self.upper_bound - self.value)

    def to_dict(self) -> dict:
        return {
            "action": self.action.to_dict(),
            "label": self.action.label,
            "value": self.value,
            "upper_bound": self.upper_bound,
            "gap": self.gap,
            "depth": self.depth,
            "nodes": self.nodes,
            "time_ms": self.time_ms,
            "complete": self.complete,
        }

    @property
    def is_question(self) -> bool:
        return self.action.kind is ActionKind.QUESTION
