"""Goal-conditioned Huber value functions and the hindsight-optimisation (HO) gradient.

Facts from Javdani, Srinivasa and Bagnell, "Shared autonomy via hindsight optimization" (RSS 2015) and
their published implementation (see ``docs/model.md``):

* ``V(d) = 0.5 (c/delta) d^2 + a d`` for ``d <= delta``, ``(c + a) d - c delta / 2`` beyond; translation
  uses d in m, rotation the quaternion angle in rad with the term scaled by ``weight`` (0.07);
* the step cost of applying an action for ``T`` s is ``T`` times the slope of ``V`` at the current distance;
* ``Q_g(x, u) = cost(x) + V_g(x')`` with ``x'`` the pose after the user's twist ``u`` for ``T`` s;
* a goal with several grasp poses takes ``V`` and ``Q`` from its lowest-value pose (or, ours, sums the
  likelihood over its poses: :func:`marginal_nll`);
* the HO robot twist is the belief-weighted negative gradient of ``Q`` with respect to the action,
  scaled by the robot cost multipliers and shrunk near the goal.

All functions broadcast: positions ``(..., 3)``, quaternions ``(..., 4)``; goal arrays come padded as
``(G, K, ...)`` (see :class:`~sa_daemon.world.goalset.GoalSet`).
"""

from __future__ import annotations

import numpy as np

from ..config import HOConfig, HuberConfig, IntentConfig
from ..geometry import (
    FloatArray,
    integrate_pose,
    norms,
    quat_angle,
    quat_z_axis,
    rotation_error,
    turn,
)


def huber_value(d: FloatArray, h: HuberConfig) -> FloatArray:
    """``weight * V(d)``: quadratic inside ``delta``, linear beyond (units of cost)."""
    d = np.asarray(d, dtype=float)
    quad = 0.5 * (h.c / h.delta) * d * d + h.a * d
    lin = (h.c + h.a) * d - 0.5 * h.c * h.delta
    return h.weight * np.where(d <= h.delta, quad, lin)


def huber_slope(d: FloatArray, h: HuberConfig) -> FloatArray:
    """``weight * dV/dd`` (cost per m or per rad)."""
    d = np.asarray(d, dtype=float)
    return h.weight * np.where(d <= h.delta, (h.c / h.delta) * d + h.a, h.c + h.a)


def pose_values(
    positions: FloatArray, quats: FloatArray, goal_positions: FloatArray, goal_quats: FloatArray, cfg: IntentConfig
) -> FloatArray:
    """Value ``V`` of gripper pose(s) w.r.t. each grasp pose (broadcast shapes)."""
    d_t = np.linalg.norm(goal_positions - positions, axis=-1)
    d_r = quat_angle(goal_quats, quats)
    return huber_value(d_t, cfg.translation) + huber_value(d_r, cfg.rotation)


def pregrasp_points(goal_position: FloatArray, goal_quat: FloatArray, standoff_m: float) -> FloatArray:
    """Points ``standoff_m`` behind goal poses along their approach axis (the gripper's z), ``(..., 3)``."""
    return np.asarray(goal_position) - standoff_m * quat_z_axis(goal_quat)


TURNING_RADPS = 1e-9
"""An input turning slower than this (rad/s) is no turn: it pays no turn charge (rounding near a goal's
orientation must not decide a charge)."""


def turn_charge(position: FloatArray, goal_positions: FloatArray, goal_quats: FloatArray,
                cfg: IntentConfig) -> FloatArray:
    """What a turn that does not move the gripper costs each goal in its translation part (per unit of
    rationality): ``intent.turn_charge x T x slope_t(d)``, a share of the time form's step cost (time
    spent turning is not spent approaching), ``d`` (m) the distance from ``position`` ``(..., 3)`` to the
    nearer of the grasp and its pre-grasp point ``intent.user_standoff_m`` behind it along its approach
    (a user who turns at the stand-off has arrived). ``position`` is where the *user* left the gripper,
    its position at their last translating input (:attr:`~.belief.Belief.anchor`), not where it is: under
    assistance the robot moves it while the user turns, and a charge read there would read the robot's
    own motion as the user's evidence. Goals ``(G, 3)``/``(G, 4)``; shape ``(..., G)``.
    Near the grasp the slope is Huber's constant ``a``, far from it ``c + a``: the charge tells a goal
    the gripper has reached from one it has not, never two goals equally far."""
    p = np.asarray(position)[..., None, :]
    pre = pregrasp_points(goal_positions, goal_quats, cfg.user_standoff_m)
    d = np.minimum(norms(goal_positions - p), norms(pre - p))
    return cfg.turn_charge * cfg.action_apply_time_s * huber_slope(d, cfg.translation)


def q_minus_v(
    position: FloatArray,
    quat: FloatArray,
    user_twist: FloatArray,
    goal_positions: FloatArray,
    goal_quats: FloatArray,
    cfg: IntentConfig,
    rotation_scale: float = 1.0,
    anchor: FloatArray | None = None,
) -> FloatArray:
    """``Q_g(x, u) - V_g(x)`` for every goal, the MaxEnt IOC negative log-likelihood of ``u`` (per unit of
    rationality; ``rotation_scale`` and ``anchor`` as in :func:`q_minus_v_at`).

    ``goal_positions`` is ``(G, K, 3)``; the goal's ``V`` and ``Q`` come from its lowest-value pose.
    Returns shape ``(G,)``.
    """
    gp, gq = nearest_goal_poses(position, quat, goal_positions, goal_quats, cfg)
    return q_minus_v_at(position, quat, user_twist, gp, gq, cfg, rotation_scale, anchor=anchor)


def q_minus_v_at(
    position: FloatArray, quat: FloatArray, user_twist: FloatArray, goal_positions: FloatArray,
    goal_quats: FloatArray, cfg: IntentConfig, rotation_scale: float = 1.0,
    distances: tuple[FloatArray, FloatArray] | None = None, anchor: FloatArray | None = None,
) -> FloatArray:
    """``Q_g(x, u) - V_g(x)`` against one pose per goal, ``(G, 3)``/``(G, 4)``, for poses ``(..., 3)``,
    ``(..., 4)`` and twists ``(..., 6)``: shape ``(..., G)``. ``Q`` applies ``u`` for
    ``action_apply_time_s`` and adds the step's cost: that time times the slope of ``V`` (``step_cost =
    "time"``), each part also times the input's speed in it (m/s, rad/s; ``"path"``). ``Q - V`` is a
    translation part plus a rotation part; ``rotation_scale`` multiplies the latter (the tracker's
    ``IntentConfig.rotation_scale``). ``distances``: the translation (m) and rotation (rad) distances to
    the goals now, ``(..., G)``, if the caller has them (:func:`pose_distances`). ``anchor`` ``(..., 3)``
    (m): where the turn charge is measured (:func:`turn_charge`; ``None``: at ``position``).

    With the path step cost a part the input does not drive costs nothing and, where applying the input
    leaves that part of the pose exactly as it was, its ``V`` does not change: that part is exactly zero
    and is not computed (the joystick drives one part at a time)."""
    T = cfg.action_apply_time_s
    position, quat = np.asarray(position)[..., None, :], np.asarray(quat)[..., None, :]
    u = np.asarray(user_twist)[..., None, :]
    d_t, d_r = pose_distances(position, quat, goal_positions, goal_quats) if distances is None else distances
    p1 = position + u[..., :3] * T
    # turning by nothing renormalises only: the numbers of ``turn`` (but an exact zero's sign, read nowhere
    # here), at a tenth of its cost (the joystick drives one part at a time)
    q1 = turn(quat, u[..., 3:], T) if u[..., 3:].any() else quat / norms(quat)[..., None]
    path = cfg.step_cost == "path"
    if path:
        per_t, per_r = norms(u[..., :3]), norms(u[..., 3:])
    else:
        per_t = per_r = 1.0
    trans = rot = np.zeros(np.shape(d_t))
    if not (path and not u[..., :3].any() and np.array_equal(p1, position)):
        trans = T * huber_slope(d_t, cfg.translation) * per_t + huber_value(norms(goal_positions - p1), cfg.translation) \
            - huber_value(d_t, cfg.translation)
    if not (path and not u[..., 3:].any() and np.array_equal(q1, quat)):
        rot = T * huber_slope(d_r, cfg.rotation) * per_r + huber_value(quat_angle(goal_quats, q1), cfg.rotation) \
            - huber_value(d_r, cfg.rotation)
    if path and cfg.turn_charge > 0.0 and u[..., 3:].any():  # a turn without a move pays for the time
        turning = ~np.any(u[..., :3] != 0.0, axis=-1) & (norms(u[..., 3:]) > TURNING_RADPS)
        at = position[..., 0, :] if anchor is None else anchor
        trans = trans + np.where(turning, turn_charge(at, goal_positions, goal_quats, cfg), 0.0)
    return trans + rotation_scale * rot


def pose_distances(position: FloatArray, quat: FloatArray, goal_positions: FloatArray,
                   goal_quats: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Translation (m) and rotation (rad) distances of the gripper to every grasp pose ``(G, K, ...)``:
    ``(G, K)`` each. What :func:`pose_nll` and :func:`pose_log_weights` share."""
    return norms(goal_positions - np.asarray(position)), quat_angle(goal_quats, np.asarray(quat))


def pose_nll(position: FloatArray, quat: FloatArray, user_twist: FloatArray, goal_positions: FloatArray,
             goal_quats: FloatArray, cfg: IntentConfig,
             distances: tuple[FloatArray, FloatArray] | None = None, anchor: FloatArray | None = None) -> FloatArray:
    """``-log P(u | pose)`` (nats) of one input sample against every grasp pose ``(G, K, ...)``: ``Q - V`` of
    the pose with its translation part weighed by ``beta`` (``intent.rationality``) and its rotation part
    by ``beta_r`` (``intent.rotation_rationality``). Shape ``(G, K)``. ``distances``:
    :func:`pose_distances`, if the caller has them; ``anchor`` as in :func:`q_minus_v_at`."""
    G, K = goal_positions.shape[:2]
    gp, gq = goal_positions.reshape(G * K, 3), goal_quats.reshape(G * K, 4)
    if distances is not None:
        distances = (distances[0].reshape(G * K), distances[1].reshape(G * K))
    return cfg.rationality * q_minus_v_at(position, quat, user_twist, gp, gq, cfg, cfg.rotation_scale,
                                          distances, anchor).reshape(G, K)


def tracker_pose_values(position: FloatArray, quat: FloatArray, goal_positions: FloatArray, goal_quats: FloatArray,
                        cfg: IntentConfig, distances: tuple[FloatArray, FloatArray] | None = None) -> FloatArray:
    """``V_k = beta huber(d_trans) + beta_r huber(d_rot)`` of each goal's poses ``(G, K, ...)`` at the gripper's
    pose (m, wxyz), as the tracker weighs them (dimensionless, ``(G, K)``); ``distances`` as in
    :func:`pose_log_weights`, whose weights are ``exp(-V_k)`` normalised per goal."""
    d_t, d_r = pose_distances(position, quat, goal_positions, goal_quats) if distances is None else distances
    return cfg.rationality * huber_value(d_t, cfg.translation) + cfg.rotation_rationality * huber_value(d_r, cfg.rotation)


def pose_log_weights(position: FloatArray, quat: FloatArray, goal_positions: FloatArray, goal_quats: FloatArray,
                     cfg: IntentConfig, distances: tuple[FloatArray, FloatArray] | None = None) -> FloatArray:
    """``log w_k``, ``w_k = exp(-V_k) / sum_j exp(-V_j)`` over each goal's poses ``(G, K, ...)`` at the
    gripper's pose, ``V`` weighed like :func:`pose_nll` (padding, far away, weighs nothing). ``(G, K)``.
    ``distances``: :func:`pose_distances`, if the caller has them (a batch ``(..., G, K)`` each gives
    ``(..., G, K)``)."""
    v = tracker_pose_values(position, quat, goal_positions, goal_quats, cfg, distances)
    v = v - v.min(axis=-1, keepdims=True)
    return -v - np.log(np.sum(np.exp(-v), axis=-1, keepdims=True))


def mixture_nll(log_w: FloatArray, nll: FloatArray) -> FloatArray:
    """``-log sum_k w_k exp(-nll_k)`` per goal from ``(..., G, K)`` log-weights (``-inf``: no such pose)
    and per-pose ``nll``. Shape ``(..., G)``."""
    m = log_w - nll
    top = m.max(axis=-1)
    return -(top + np.log(np.sum(np.exp(m - top[..., None]), axis=-1)))


def point_listing_log_w(log_prior: FloatArray, log_post: FloatArray, same_point: np.ndarray) -> FloatArray:
    """Pose log-weights ``(G, K)`` of ``intent.poses = "points"``: a grasp point weighs the sum of its
    listings' ``exp(-V)`` weights (``log_prior``, :func:`pose_log_weights`), as under ``marginal``,
    and shares it among its listings by their posterior from the input so far (``log_post``,
    :attr:`~.belief.Belief.pose_log_w`): ``w_k = (sum_{j at k's point} pi_j) P(k | g, input) / sum_{j at k's point}
    P(j | g, input)``. Translation input moves the listings of one point alike, so their posterior ratio is
    what the turning has said; a listing the turn points at is not charged for needing more turn from
    where the gripper is. Each row stays normalised; padding stays ``-inf``."""
    def at_point(log_x: FloatArray) -> FloatArray:  # log sum_{j at k's point} x_j; NaN on padding
        return -mixture_nll(np.where(same_point, log_x[:, None, :], -np.inf), 0.0)

    with np.errstate(invalid="ignore"):
        out = at_point(log_prior) + log_post - at_point(log_post)
    return np.where(np.isnan(out), -np.inf, out)


def switched_pose_log_w(log_w: FloatArray, log_prior: FloatArray, switch: float) -> FloatArray:
    """One step of a sticky Markov chain over each goal's grasp poses (``intent.poses = "switching"``):
    ``w'_k = (1 - s) w_k + s pi_k``, the user keeping its pose with probability ``1 - s`` and drawing it
    afresh from ``pi`` (the weights ``exp(-V)`` at the gripper, :func:`pose_log_weights`) with
    probability ``s`` (``intent.pose_switch``, per input sample). Logs in and out ``(G, K)``; each row's
    weights stay normalised, and padding (``-inf`` in both) stays ``-inf``."""
    if switch <= 0.0:
        return log_w
    if switch >= 1.0:
        return log_prior
    return np.logaddexp(np.log1p(-switch) + log_w, np.log(switch) + log_prior)


def marginal_nll(position: FloatArray, quat: FloatArray, user_twist: FloatArray, goal_positions: FloatArray,
                 goal_quats: FloatArray, cfg: IntentConfig, anchor: FloatArray | None = None) -> FloatArray:
    """``-log P(u | g)`` (nats) of one input sample for goals with several grasp poses ``(G, K, ...)``, the
    poses marginalised: ``P(u | g) = sum_k w_k exp(-(Q_k - V_k))`` with ``w_k = exp(-V_k) / sum_j exp(-V_j)``
    (:func:`pose_log_weights`, :func:`pose_nll`). This is MaxEnt IOC with the pose a latent sub-goal
    (``exp(-Q_k)`` summed over poses, normalised by ``exp(-V_k)`` summed): a goal's value is the soft
    minimum over its poses, and an input toward any of them is evidence for it. As the rationalities grow
    it tends to ``beta (Q - V)`` of the lowest-value pose (``intent.poses = "nearest"``). ``anchor`` as in
    :func:`q_minus_v_at`. Shape ``(G,)``."""
    d = pose_distances(position, quat, goal_positions, goal_quats)
    return mixture_nll(pose_log_weights(position, quat, goal_positions, goal_quats, cfg, d),
                       pose_nll(position, quat, user_twist, goal_positions, goal_quats, cfg, d, anchor))


def q_minus_v_driven(
    position: FloatArray, quat: FloatArray, user_linear: FloatArray | None, user_angular: FloatArray | None,
    goal_positions: FloatArray, goal_quats: FloatArray, cfg: IntentConfig, rotation_scale: float = 1.0,
    anchor: FloatArray | None = None,
) -> FloatArray:
    """:func:`q_minus_v_at` for an input that drives one part only (the joystick's mode): ``user_linear``
    ``(..., 3)`` m/s with ``user_angular`` ``None``, or the reverse (rad/s). With the path step cost
    the part not driven adds nothing (its pose does not move, its cost is zero), so only the driven
    part's Huber terms are computed: the same value, without the other part's distances. ``anchor``
    ``(..., 3)`` (m): where a turn's charge is measured (:func:`turn_charge`; ``None``: at ``position``)."""
    if cfg.step_cost != "path":
        lin = np.zeros(np.shape(user_angular)) if user_linear is None else user_linear
        ang = np.zeros(np.shape(user_linear)) if user_angular is None else user_angular
        return q_minus_v_at(position, quat, np.concatenate((lin, ang), axis=-1), goal_positions, goal_quats, cfg,
                            rotation_scale, anchor=anchor)
    T = cfg.action_apply_time_s
    scale = 1.0
    if user_angular is None:
        p = np.asarray(position)[..., None, :]
        u = np.asarray(user_linear)[..., None, :]
        d = norms(goal_positions - p)
        d1 = norms(goal_positions - (p + u * T))
        h, speed = cfg.translation, norms(u)
    else:
        q = np.asarray(quat)[..., None, :]
        w = np.asarray(user_angular)[..., None, :]
        d = quat_angle(goal_quats, q)
        d1 = quat_angle(goal_quats, turn(q, w, T))
        h, speed, scale = cfg.rotation, norms(w), rotation_scale
    out = scale * (T * huber_slope(d, h) * speed + huber_value(d1, h) - huber_value(d, h))
    if user_angular is not None and cfg.turn_charge > 0.0:  # a turn pays for the time (none standing still)
        at = position if anchor is None else anchor
        out = out + np.where(speed > TURNING_RADPS, turn_charge(at, goal_positions, goal_quats, cfg), 0.0)
    return out


def marginal_nll_driven(
    position: FloatArray, quat: FloatArray, user_linear: FloatArray | None, user_angular: FloatArray | None,
    goal_positions: FloatArray, goal_quats: FloatArray, cfg: IntentConfig, anchor: FloatArray | None = None,
) -> FloatArray:
    """:func:`marginal_nll` for a batch of poses ``(..., 3)``/``(..., 4)`` and an input that drives one part
    (:func:`q_minus_v_driven`'s arguments): ``-log sum_k w_k exp(-beta (Q_k - V_k))`` (nats per input
    sample), ``w_k`` each goal's ``exp(-V_k)`` normalised over its poses ``(G, K, ...)`` at the pose.
    Shape ``(..., G)``. The tracker's likelihood (``intent.poses = "marginal"``), as the watch model's
    rollouts read the input they predict under ``planner.watch_likelihood = "marginal"``."""
    G, K = goal_positions.shape[:2]
    flat_p, flat_q = goal_positions.reshape(G * K, 3), goal_quats.reshape(G * K, 4)
    per = cfg.rationality * q_minus_v_driven(position, quat, user_linear, user_angular, flat_p, flat_q, cfg,
                                             cfg.rotation_scale, anchor)
    shape = per.shape[:-1] + (G, K)
    # distances against the flat (G K) set, reshaped: quat_angle then takes its one-matrix-product path, as
    # the recorded files were made (the broadcast (..., G, K) form differs in the last bit)
    d = (norms(flat_p - np.asarray(position)[..., None, :]).reshape(shape),
         quat_angle(flat_q, np.asarray(quat)[..., None, :]).reshape(shape))
    return mixture_nll(pose_log_weights(position, quat, goal_positions, goal_quats, cfg, d), per.reshape(shape))


def assistance_twists(
    position: FloatArray, quat: FloatArray, goal_positions: FloatArray, goal_quats: FloatArray,
    intent: IntentConfig, ho: HOConfig,
) -> FloatArray:
    """Negative ``Q`` gradient toward one pose per goal, as a twist (m/s, rad/s).

    ``position`` ``(..., 1, 3)`` and ``quat`` ``(..., 1, 4)`` against goal poses ``(..., G, 3)`` and
    ``(..., G, 4)``; returns ``(..., G, 6)``. Magnitude: the Huber slope divided by the robot's cost
    multiplier, shrunk linearly inside ``translation_shrink_m`` / ``rotation_shrink_rad``.
    """
    return np.concatenate((assistance_linear(position, goal_positions, intent, ho),
                           assistance_angular(quat, goal_quats, intent, ho)), axis=-1)


def assistance_linear(position: FloatArray, goal_positions: FloatArray, intent: IntentConfig, ho: HOConfig) -> FloatArray:
    """The linear part of :func:`assistance_twists` (m/s), broadcasting like it."""
    diff = goal_positions - position
    d_t = norms(diff)
    lin_mag = huber_slope(d_t, intent.translation) / ho.translation_cost_multiplier
    lin_mag = lin_mag * np.minimum(1.0, d_t / ho.translation_shrink_m) / np.maximum(d_t, 1e-12)
    return diff * lin_mag[..., None]


def assistance_angular(quat: FloatArray, goal_quats: FloatArray, intent: IntentConfig, ho: HOConfig) -> FloatArray:
    """The angular part of :func:`assistance_twists` (rad/s), broadcasting like it."""
    axis = rotation_error(goal_quats, quat)  # |axis| = d_r
    d_r = norms(axis)
    rot_mag = huber_slope(d_r, intent.rotation) / ho.rotation_cost_multiplier
    rot_mag = rot_mag * np.minimum(1.0, d_r / ho.rotation_shrink_rad) / np.maximum(d_r, 1e-12)
    return axis * rot_mag[..., None]


def goal_gradients(
    position: FloatArray,
    quat: FloatArray,
    user_twist: FloatArray,
    goal_positions: FloatArray,
    goal_quats: FloatArray,
    intent: IntentConfig,
    ho: HOConfig,
) -> FloatArray:
    """Per-goal assistance twist ``-dQ_g/du`` (m/s, rad/s), shape ``(..., G, 6)``.

    Evaluated at ``x'``, the pose after the user's twist for ``action_apply_time_s`` (where the gradient
    of ``Q`` w.r.t. the action is taken). Goal arrays are ``(G, K, ...)``: each goal's gradient points to
    its lowest-value pose. ``(G, 3)``/``(G, 4)`` arrays give one pose per goal (used by the lookahead).
    ``position`` may carry leading batch axes ``(B, 3)`` to evaluate many candidate poses at once.
    """
    p1, q1 = integrate_pose(position, quat, user_twist, intent.action_apply_time_s)
    goal_positions, goal_quats = nearest_goal_poses(p1, q1, goal_positions, goal_quats, intent)
    return assistance_twists(p1[..., None, :], q1[..., None, :], goal_positions, goal_quats, intent, ho)


def nearest_goal_poses(
    position: FloatArray, quat: FloatArray, goal_positions: FloatArray, goal_quats: FloatArray, cfg: IntentConfig
) -> tuple[FloatArray, FloatArray]:
    """Each goal's lowest-value pose from ``position`` ``(3,)`` / ``quat`` ``(4,)``: ``(G, 3)``, ``(G, 4)``.
    Goal arrays that are already one pose per goal, ``(G, 3)``/``(G, 4)``, come back unchanged."""
    if goal_positions.ndim != 3:
        return goal_positions, goal_quats
    v = pose_values(position[..., None, None, :], quat[..., None, None, :], goal_positions, goal_quats, cfg)
    k = np.argmin(v, axis=-1)
    rows = np.arange(goal_positions.shape[0])
    return goal_positions[rows, k], goal_quats[rows, k]


def tracked_pose_scores(position: FloatArray, quat: FloatArray, goal_positions: FloatArray, goal_quats: FloatArray,
                        pose_log_w: FloatArray, cfg: IntentConfig) -> FloatArray:
    """``log P(k | g, input) + log w_k(x)`` ``(G, K)``, the score by which the tracked reach picks each goal's
    grasp pose (:func:`tracked_goal_poses`): the goal's posterior over its poses ``pose_log_w`` ``(G, K)``
    (:attr:`~.belief.Belief.pose_log_w`) times the weights ``exp(-V_k)`` at the gripper's ``position`` (m) /
    ``quat`` (wxyz) (:func:`pose_log_weights`); ``-inf`` on padding."""
    return np.asarray(pose_log_w) + pose_log_weights(position, quat, goal_positions, goal_quats, cfg)


def tracked_goal_poses(position: FloatArray, quat: FloatArray, goal_positions: FloatArray, goal_quats: FloatArray,
                       pose_log_w: FloatArray, cfg: IntentConfig) -> tuple[FloatArray, FloatArray]:
    """Each goal's grasp pose that the input so far points at, ``(G, 3)``, ``(G, 4)``
    (``intent.reach_pose = "tracked"``): ``argmax_k log P(k | g, input) + log w_k(x)``
    (:func:`tracked_pose_scores`). With no input yet (a uniform posterior) this is the pose of least ``V``
    as the tracker weighs it (its rotation part ``beta_r / beta`` times the translation's): among poses of
    one orientation, the nearest, as :func:`nearest_goal_poses`, whose ``V`` weighs rotation as HO's
    reference does, picks."""
    k = np.argmax(tracked_pose_scores(position, quat, goal_positions, goal_quats, pose_log_w, cfg), axis=1)
    rows = np.arange(goal_positions.shape[0])
    return goal_positions[rows, k], goal_quats[rows, k]
