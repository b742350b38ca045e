"""Reward of section III-E, vectorised over goals and candidate poses.

``R(s, move) = R_d + R_u`` with ``R_t = -scale (1 - 2^(-beta d_trans))``, ``R_r = -scale d_rot / (2 pi)``
added when ``d_trans <= delta``, ``+goal`` when the pose reaches ``k_c`` (within ``goal_translation_m`` and
``goal_rotation_rad``), and ``R_u = opposition_penalty`` when the robot's twist opposes the user's.
Questions cost ``question``, repeated questions ``repeated_question``. Values are in reward units.
"""

from __future__ import annotations

import math

import numpy as np

from ..config import RewardConfig
from ..geometry import FloatArray


def distance_reward(d_trans: FloatArray, d_rot: FloatArray, cfg: RewardConfig) -> FloatArray:
    """``R_d`` plus the goal bonus for translation ``d_trans`` (m) and rotation ``d_rot`` (rad) to ``k_c``."""
    d_trans = np.asarray(d_trans, dtype=float)
    d_rot = np.asarray(d_rot, dtype=float)
    r_t = -cfg.scale * (1.0 - np.exp2(-cfg.beta * d_trans))
    r_r = np.where(d_trans <= cfg.rotation_threshold_m, -cfg.scale * d_rot / (2.0 * math.pi), 0.0)
    reached = (d_trans <= cfg.goal_translation_m) & (d_rot <= cfg.goal_rotation_rad)
    return r_t + r_r + np.where(reached, cfg.goal, 0.0)


def approach_return(d_trans: FloatArray, d_rot: FloatArray, v_trans: float, v_rot: float,
                    cfg: RewardConfig) -> FloatArray:
    """The return of finishing the approach from ``d_trans`` (m) and ``d_rot`` (rad) to ``k_c``, in reward
    units (``R_d`` per paper step of ``step_s``), with the goal bonus at the end.

    The approach is a straight line at constant speed in both parts, arriving together after ``tau =
    max(d_trans / v_trans, d_rot / v_rot)`` s (m/s, rad/s), so at the fraction ``u`` of the way still to go
    the distances are ``u d_trans`` and ``u d_rot``. Integrating ``R_d`` over it, per ``step_s``:

        R_t:  -scale (tau / step_s) (1 - (1 - 2^(-beta d_trans)) / (beta d_trans ln 2))
        R_r:  -scale / (2 pi) d_rot (tau / step_s) m^2 / 2,   m = min(1, delta / d_trans)

    (``R_r`` counts once ``u d_trans <= delta``, the last fraction ``m`` of the way). Zero distance, zero
    cost; a slower approach costs proportionally more: time still to go is what it charges.
    """
    d_t = np.asarray(d_trans, dtype=float)
    d_r = np.asarray(d_rot, dtype=float)
    steps = np.maximum(d_t / v_trans, d_r / v_rot) / cfg.step_s
    x = cfg.beta * math.log(2.0) * d_t
    with np.errstate(divide="ignore", invalid="ignore"):
        mean_left = np.where(x > 1e-9, -np.expm1(-x) / x, 1.0 - x / 2.0)  # mean of 2^(-beta u d_t) over u
        m = np.minimum(1.0, cfg.rotation_threshold_m / d_t)
    r_t = -cfg.scale * steps * (1.0 - mean_left)
    r_r = -cfg.scale / (2.0 * math.pi) * d_r * steps * m * m / 2.0
    return r_t + r_r + cfg.goal


def opposes(user_twist: FloatArray, robot_twist: FloatArray, threshold: float) -> FloatArray:
    """True where, in any of the six dimensions, the twists have opposite signs and both magnitudes
    exceed ``threshold`` (section III-E). Broadcasts over leading axes; returns a bool array."""
    u = np.asarray(user_twist, dtype=float)
    r = np.asarray(robot_twist, dtype=float)
    return np.any((u * r < 0.0) & (np.abs(u) > threshold) & (np.abs(r) > threshold), axis=-1)


def opposition_reward(opposed: FloatArray, cfg: RewardConfig) -> FloatArray:
    """``R_u``: the opposition penalty where ``opposed``, else 0."""
    return np.where(opposed, cfg.opposition_penalty, 0.0)


def question_reward(repeated: bool, cfg: RewardConfig) -> float:
    """Reward of asking a question (``repeated``: about a target already asked)."""
    return cfg.repeated_question if repeated else cfg.question
