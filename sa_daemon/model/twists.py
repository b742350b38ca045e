"""The velocity generators of the actions (section III-B, Fig. 1), in m/s and rad/s.

* move-to-goal ``g``: proportional twist toward ``k_c``, saturated (translation along ``k_c - x``, rotation
  along the axis-angle of the relative rotation);
* HO: the belief-weighted negative gradient of the goals' ``Q`` (:mod:`.huber`);
* no-assist: zero robot twist, the user's twist passes unscaled;
* question: the robot holds still while the question is asked.

Move actions are blended ``a_total = (1 - alpha) a_h + alpha a_r``; ``a_h`` holds only the components of
the current joystick mode, the robot twist all six.
"""

from __future__ import annotations

import numpy as np

from ..config import BlendConfig, InputConfig, MoveConfig
from ..geometry import FloatArray, rotation_error
from .actions import Mode


def mask_to_mode(twist: FloatArray, mode: Mode) -> FloatArray:
    """Keep only the components the joystick mode drives (the others become 0)."""
    t = np.array(twist, dtype=float)
    if Mode(mode) is Mode.TRANSLATION:
        t[..., 3:] = 0.0
    else:
        t[..., :3] = 0.0
    return t


def axes_to_twist(axes: FloatArray, mode: Mode, scale: InputConfig) -> FloatArray:
    """The user's twist (m/s, rad/s) from three joystick axes in [-1, 1] driving ``mode``."""
    t = np.zeros(6)
    if Mode(mode) is Mode.TRANSLATION:
        t[:3] = np.asarray(axes, dtype=float) * scale.linear_scale_mps
    else:
        t[3:] = np.asarray(axes, dtype=float) * scale.angular_scale_radps
    return t


def _clip_norm(v: FloatArray, limit: float) -> FloatArray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v * np.minimum(1.0, limit / np.maximum(n, 1e-12))


def move_twist(
    position: FloatArray, quat: FloatArray, goal_position: FloatArray, goal_quat: FloatArray, cfg: MoveConfig
) -> FloatArray:
    """Twist (m/s, rad/s) toward a desired pose: gain times the error, each part norm-saturated.

    Broadcasts, so many (pose, goal) pairs are computed in one call.
    """
    lin = _clip_norm(cfg.linear_gain * (np.asarray(goal_position) - position), cfg.linear_max_mps)
    ang = _clip_norm(cfg.angular_gain * rotation_error(goal_quat, quat), cfg.angular_max_radps)
    return np.concatenate((lin, ang), axis=-1)


def ho_twist(weights: FloatArray, gradients: FloatArray) -> FloatArray:
    """Belief-weighted mean of per-goal assistance twists: ``sum_g b(g) grad_g / sum_g b(g)``.

    ``weights`` ``(..., G)``, ``gradients`` ``(..., G, 6)``.
    """
    w = np.asarray(weights, dtype=float)
    return np.einsum("...g,...gj->...j", w, gradients) / np.sum(w, axis=-1, keepdims=True)


def blend(user_twist: FloatArray, robot_twist: FloatArray, cfg: BlendConfig) -> FloatArray:
    """``(1 - alpha) a_h + alpha a_r``."""
    return (1.0 - cfg.alpha) * np.asarray(user_twist) + cfg.alpha * np.asarray(robot_twist)
