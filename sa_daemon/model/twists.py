"""The velocity generators of the actions (section III-B, Fig. 1), in m/s and rad/s.

* move-to-goal ``g``: proportional twist toward ``k_c``, saturated (translation along ``k_c - x``, rotation
  along the axis-angle of the relative rotation);
* HO: the belief-weighted mean of the goals' negative ``Q`` gradients (:mod:`.huber`,
  ``ho.generator = "gradient"``, Javdani et al.), or the move generator applied to the belief-weighted
  mean error (``"moves"``: the same kind of generator as the move actions, Fig. 1);
* no-assist: zero robot twist, the user's twist passes unscaled;
* question: the robot holds still while the question is asked.

Move actions are blended ``a_total = (1 - alpha) a_h + alpha a_r``; ``a_h`` holds only the components of
the current joystick mode, the robot twist all six.
"""

from __future__ import annotations

import numpy as np

from ..config import BlendConfig, Config, InputConfig, MoveConfig
from ..geometry import (
    FloatArray,
    integrate_pose,
    norms,
    quat_angle,
    quat_z_axis,
    rotation_error,
)
from .actions import Mode
from .huber import (
    assistance_angular,
    assistance_linear,
    goal_gradients,
    nearest_goal_poses,
)


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


def clip_norm(v: FloatArray, limit: float) -> FloatArray:
    """``v`` scaled down, along its last axis, to a norm of at most ``limit``."""
    n = norms(v)[..., None]
    return v * np.minimum(1.0, limit / np.maximum(n, 1e-12))


def move_twist(
    position: FloatArray, quat: FloatArray, goal_position: FloatArray, goal_quat: FloatArray, cfg: MoveConfig
) -> FloatArray:
    """Twist (m/s, rad/s) toward a desired pose: gain times the error, each part norm-saturated.

    Broadcasts, so many (pose, goal) pairs are computed in one call. With ``cfg.approach_standoff_m > 0``
    the translation heads for :func:`approach_points` rather than the grasp itself.
    """
    aim = approach_points(position, quat, goal_position, goal_quat, cfg)
    return np.concatenate((move_linear(position, aim, cfg), move_angular(quat, goal_quat, cfg)), axis=-1)


def approach_points(position: FloatArray, quat: FloatArray, goal_position: FloatArray, goal_quat: FloatArray,
                    cfg: MoveConfig) -> FloatArray:
    """The point (m) a robot twist toward a grasp heads for: a point on the grasp's approach axis (the
    gripper's z at the grasp) a distance ``s`` behind the grasp,

        s = max(min(approach_standoff_m, approach_funnel * l), approach_turn_m * sin(min(theta, pi/2))),

    with ``l`` the gripper's distance (m) from that axis and ``theta`` (rad) its orientation's angle from
    the grasp's. Off the axis it heads for a pre-grasp point behind the grasp; as it comes onto the axis
    the point slides forward to the grasp, so the fingers arrive along the approach; and while the gripper
    is still turned away it stays back, so turning does not sweep the fingers into the object.
    ``approach_standoff_m = 0``: the grasp itself (the paper). Continuous in the pose; broadcasts;
    returns ``(..., 3)``."""
    g = np.asarray(goal_position, dtype=float)
    if cfg.approach_standoff_m <= 0.0:
        return g
    z = quat_z_axis(goal_quat)
    d = np.asarray(position, dtype=float) - g
    along = np.sum(d * z, axis=-1, keepdims=True)
    lateral = norms(d - along * z)[..., None]
    theta = np.minimum(quat_angle(goal_quat, quat), 0.5 * np.pi)[..., None]
    back = np.maximum(np.minimum(cfg.approach_standoff_m, cfg.approach_funnel * lateral),
                      cfg.approach_turn_m * np.sin(theta))
    return g - z * back


def move_linear(position: FloatArray, goal_position: FloatArray, cfg: MoveConfig) -> FloatArray:
    """The linear part of :func:`move_twist` (m/s): it depends on the position alone."""
    return clip_norm(cfg.linear_gain * (np.asarray(goal_position) - position), cfg.linear_max_mps)


def move_angular(quat: FloatArray, goal_quat: FloatArray, cfg: MoveConfig) -> FloatArray:
    """The angular part of :func:`move_twist` (rad/s): it depends on the orientation alone."""
    return clip_norm(cfg.angular_gain * rotation_error(goal_quat, quat), cfg.angular_max_radps)


def ho_robot_twist(
    position: FloatArray, quat: FloatArray, user_twist: FloatArray, goal_positions: FloatArray,
    goal_quats: FloatArray, weights: FloatArray, cfg: Config,
) -> FloatArray:
    """HO's robot twist (m/s, rad/s) under belief ``weights`` ``(G,)``, by ``cfg.ho.generator``, taken
    at the pose after the user's twist for ``action_apply_time_s``, toward each goal's lowest-value pose.

    ``"gradient"``: the belief-weighted mean of ``-dQ_g/du`` (:func:`.huber.goal_gradients`, Javdani et al.);
    ``"moves"``: the move-to-goal generator applied to the belief-weighted mean of the per-goal errors
    (gain times the expected error, then the same saturation as a move), so HO and a move toward one
    goal have the same gain and top speed (Fig. 1 gives the goals and their distribution generators of one
    kind). Goal arrays are ``(G, K, ...)`` or ``(G, ...)``.
    """
    w = np.asarray(weights, dtype=float)
    if cfg.ho.generator == "gradient":
        return ho_twist(w, goal_gradients(position, quat, user_twist, goal_positions, goal_quats, cfg.intent, cfg.ho))
    p1, q1 = integrate_pose(position, quat, user_twist, cfg.intent.action_apply_time_s)
    gp, gq = nearest_goal_poses(p1, q1, goal_positions, goal_quats, cfg.intent)
    aim = approach_points(np.asarray(p1)[..., None, :], np.asarray(q1)[..., None, :], gp, gq, cfg.move)
    return np.concatenate((ho_linear(p1, aim, w, cfg), ho_angular(q1, gq, w, cfg)), axis=-1)


def _goal_weights(weights: FloatArray) -> FloatArray:
    """Belief ``weights`` ``(..., G)`` normalised over the goals, as ``(..., G, 1)`` to scale per-goal vectors."""
    w = np.asarray(weights, dtype=float)[..., None]
    return w / np.sum(w, axis=-2, keepdims=True)


def ho_linear(position: FloatArray, goal_positions: FloatArray, weights: FloatArray, cfg: Config) -> FloatArray:
    """The linear part of :func:`ho_robot_twist` (m/s) from ``position`` ``(..., 3)`` already moved by the
    user's twist, one pose per goal ``(G, 3)``, belief ``weights`` broadcasting to ``(..., G)``: it
    depends on the position alone. Returns ``(..., 3)``."""
    w = _goal_weights(weights)
    if cfg.ho.generator == "gradient":
        return np.sum(w * assistance_linear(position[..., None, :], goal_positions, cfg.intent, cfg.ho), axis=-2)
    # sum_g w_g (x_g - x) = sum_g w_g x_g - x, the weights summing to 1: one product, not (..., G, 3) errors
    error = np.einsum("...g,...gj->...j", w[..., 0], goal_positions) - np.asarray(position)
    return clip_norm(cfg.move.linear_gain * error, cfg.move.linear_max_mps)


def ho_angular(quat: FloatArray, goal_quats: FloatArray, weights: FloatArray, cfg: Config) -> FloatArray:
    """The angular part of :func:`ho_robot_twist` (rad/s), from ``quat`` ``(..., 4)`` already turned by the
    user's twist; like :func:`ho_linear`, it depends on the orientation alone."""
    w = _goal_weights(weights)
    if cfg.ho.generator == "gradient":
        return np.sum(w * assistance_angular(quat[..., None, :], goal_quats, cfg.intent, cfg.ho), axis=-2)
    error = np.einsum("...g,...gj->...j", w[..., 0], rotation_error(goal_quats, np.asarray(quat)[..., None, :]))
    return clip_norm(cfg.move.angular_gain * error, cfg.move.angular_max_radps)


def user_linear(position: FloatArray, goal_position: FloatArray, pregrasp: FloatArray, speed: float,
                standoff_m: float) -> FloatArray:
    """The watch model's prediction of the joystick in translation mode (m/s; ``docs/model.md``): a user
    heading to ``goal_position`` aims at its ``pregrasp`` point while farther than 1.5 ``standoff_m`` from
    the goal, then at the goal, at its ``speed`` (m/s), slowing within one second of its aim (gain 1/s,
    saturated at the speed). Broadcasts like :func:`move_twist`."""
    far = norms(np.asarray(goal_position) - position)[..., None] > 1.5 * standoff_m
    return clip_norm(np.where(far, pregrasp, goal_position) - position, speed)


def user_angular(quat: FloatArray, goal_quat: FloatArray, speed: float) -> FloatArray:
    """The same in rotation mode (rad/s): toward ``goal_quat`` at ``speed`` (rad/s), gain 1/s."""
    return clip_norm(rotation_error(goal_quat, quat), speed)


def ho_twist(weights: FloatArray, gradients: FloatArray) -> FloatArray:
    """Belief-weighted mean of per-goal assistance twists: ``sum_g b(g) grad_g / sum_g b(g)``.

    ``weights`` ``(..., G)``, ``gradients`` ``(..., G, 6)``.
    """
    w = np.asarray(weights, dtype=float)
    return np.einsum("...g,...gj->...j", w, gradients) / np.sum(w, axis=-1, keepdims=True)


def assisted_speeds(cfg: Config, user_speed: tuple[float, float]) -> tuple[float, float]:
    """The speed of an assisted approach, per part: ``alpha`` x the move generator's top speed plus
    ``1 - alpha`` x the user's (``user_speed``: m/s, rad/s). Returns (m/s, rad/s)."""
    a = cfg.blend.alpha
    return (a * cfg.move.linear_max_mps + (1.0 - a) * user_speed[0],
            a * cfg.move.angular_max_radps + (1.0 - a) * user_speed[1])


def blend(user_twist: FloatArray, robot_twist: FloatArray, cfg: BlendConfig) -> FloatArray:
    """``(1 - alpha) a_h + alpha a_r``."""
    return (1.0 - cfg.alpha) * np.asarray(user_twist) + cfg.alpha * np.asarray(robot_twist)
