"""The rollouts of :mod:`.rollouts`, compiled: one fused loop per rollout instead of numpy passes.

:class:`~.rollouts.Rollouts` integrates every (start ``c``, user goal ``g``, motion action ``a``) rollout
with about sixty numpy passes a step over arrays of ``C G A`` poses; most of a plan's time went into
those passes and their temporaries (``docs/model.md``, "Where the rest goes"). This module computes the
same model rollout by rollout in one compiled loop (numba), with scalar quaternion algebra and no
temporaries. It implements the defaults, ``ho.generator = "moves"`` and ``intent.step_cost = "path"``,
in both joystick modes, both HO beliefs (``planner.ho_belief``), both terminal values
(``planner.terminal``) and with or without the approach corridor (``move.approach_standoff_m``; turning,
a move's position then depends on the orientation and is integrated per goal);
:class:`~.rollouts.Rollouts` keeps the numpy form as the reference (the tests hold the two equal to
rounding) and for the other options.

Per rollout and step, as in :mod:`.rollouts`: the user's twist in the driven part toward ``g`` (the
pre-grasp point first in translation), the robot's twist (move-to-goal toward its own goal; HO the move
generator applied to the belief-weighted mean error at the pose the user's twist reaches in
``action_apply_time_s``; no-assist none), the blend, section III-E's reward. The part the user does not
drive moves by the robot's share alone, so for moves and no-assist it does not depend on ``g``: it is
integrated once per ``(c, a)`` and shared; what every action's rollouts share at step 0 (the user's error
and the reward toward each goal, HO's weights and its goals' angles) is computed once per start. HO
carries its whole pose and, tracked, its own belief per ``(c, g)``. Goals often share an orientation (one
grasp kind on several objects): HO's error, angle and Huber value toward each orientation are computed once
per orientation, and turning (rotation mode), where the user drives the orientation alone and by the
goal's orientation alone, a goal whose orientation an earlier goal has (its *twin*) follows that goal's
path exactly: the path is integrated once and the twin takes only its own rewards. This gives the same
numbers as computing every rollout in full (the tests hold it bit for bit). Units: m, rad, s, m/s, rad/s;
rewards in the paper's units.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..config import Config
from ..geometry import FloatArray
from ..model.huber import TURNING_RADPS
from ..model.twists import assisted_speeds

MOVE, HO, NONE = 0, 1, 2
"""Action kinds as the kernel reads them."""

_TWO_PI = 2.0 * math.pi
_LN2 = math.log(2.0)


@njit(cache=True, inline="always")
def _qmul(aw, ax, ay, az, bw, bx, by, bz):
    """Hamilton product ``a * b`` of wxyz quaternions."""
    return (aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw)


@njit(cache=True, inline="always")
def _rot_err(tw, tx, ty, tz, qw, qx, qy, qz):
    """Rotation vector (rad) turning ``q`` into ``t`` (``geometry.rotation_error``), and its norm, the angle
    between them (``2 atan2``: the same as :func:`_angle`, better conditioned near zero)."""
    w, x, y, z = _qmul(tw, tx, ty, tz, qw, -qx, -qy, -qz)
    s = math.sqrt(x * x + y * y + z * z)
    angle = 2.0 * math.atan2(s, min(abs(w), 1.0))
    scale = angle / max(s, 1e-12) if s > 1e-9 else 2.0
    if w < 0.0:
        scale = -scale
    return x * scale, y * scale, z * scale, angle


@njit(cache=True, inline="always")
def _turn(qw, qx, qy, qz, ax, ay, az, dt):
    """``exp(w dt) q`` renormalised (``geometry.turn``) for angular velocity ``w`` (rad/s)."""
    rx, ry, rz = ax * dt, ay * dt, az * dt
    angle = math.sqrt(rx * rx + ry * ry + rz * rz)
    half = 0.5 * angle
    k = math.sin(half) / max(angle, 1e-12) if angle > 1e-9 else 0.5
    w, x, y, z = _qmul(math.cos(half), rx * k, ry * k, rz * k, qw, qx, qy, qz)
    n = math.sqrt(w * w + x * x + y * y + z * z)
    return w / n, x / n, y / n, z / n


@njit(cache=True, inline="always")
def _angle(aw, ax, ay, az, bw, bx, by, bz):
    """Geodesic angle (rad) between two rotations: ``2 acos |<a, b>|``."""
    return 2.0 * math.acos(min(abs(aw * bw + ax * bx + ay * by + az * bz), 1.0))


@njit(cache=True, inline="always")
def _clip(x, y, z, limit):
    """``(x, y, z)`` scaled down to a norm of at most ``limit``."""
    f = min(1.0, limit / max(math.sqrt(x * x + y * y + z * z), 1e-12))
    return x * f, y * f, z * f


@njit(cache=True)
def _approach_axes(kq):
    """Each goal's approach axis, the gripper's z at its grasp (``geometry.quat_z_axis``), ``(G, 3)``."""
    out = np.empty((kq.shape[0], 3))
    for j in range(kq.shape[0]):
        gw, gx, gy, gz = kq[j, 0], kq[j, 1], kq[j, 2], kq[j, 3]
        n = math.sqrt(gw * gw + gx * gx + gy * gy + gz * gz)
        nw, nx, ny, nz = gw / n, gx / n, gy / n, gz / n
        out[j, 0], out[j, 1], out[j, 2] = 2.0 * (nx * nz + nw * ny), 2.0 * (ny * nz - nw * nx), \
            1.0 - 2.0 * (nx * nx + ny * ny)
    return out


@njit(cache=True, inline="always")
def _aim(px, py, pz, qw, qx, qy, qz, j, kp, kq, kz, standoff, funnel, turn):
    """The point (m) a move or HO heads for toward goal ``j`` from pose ``(p, q)`` with the approach corridor
    on (``twists.approach_points``): ``s`` behind ``j``'s grasp along its approach axis ``kz[j]``
    (:func:`_approach_axes`), ``s = max(min(standoff, funnel l), turn sin(min(theta, pi/2)))``, ``l`` the
    distance from the axis, ``theta`` the angle from the grasp's orientation."""
    zx, zy, zz = kz[j, 0], kz[j, 1], kz[j, 2]
    dx, dy, dz = px - kp[j, 0], py - kp[j, 1], pz - kp[j, 2]
    along = dx * zx + dy * zy + dz * zz
    lx, ly, lz = dx - along * zx, dy - along * zy, dz - along * zz
    lateral = math.sqrt(lx * lx + ly * ly + lz * lz)
    theta = min(_angle(kq[j, 0], kq[j, 1], kq[j, 2], kq[j, 3], qw, qx, qy, qz), 0.5 * math.pi)
    back = max(min(standoff, funnel * lateral), turn * math.sin(theta))
    return kp[j, 0] - zx * back, kp[j, 1] - zy * back, kp[j, 2] - zz * back


@njit(cache=True, inline="always")
def _huber(d, c, delta, a, weight):
    """``weight V(d)`` and ``weight dV/dd`` of the Huber value (``model.huber``)."""
    if d <= delta:
        return weight * (0.5 * (c / delta) * d * d + a * d), weight * ((c / delta) * d + a)
    return weight * ((c + a) * d - 0.5 * c * delta), weight * (c + a)


@njit(cache=True, inline="always")
def _turn_cost(v, slope, d1, speed, T, hp):
    """``Q - V`` of a turn at ``speed`` (rad/s) for ``T`` (s) from the angle whose Huber value and slope
    are ``v``, ``slope`` to the angle ``d1`` after it (path step cost), before the rotation part's scale."""
    v1, _ = _huber(d1, hp[4], hp[5], hp[6], hp[7])
    return T * slope * speed + v1 - v


@njit(cache=True, inline="always")
def _move_cost(v, slope, d1, speed, T, hp):
    """``Q - V`` of a translation at ``speed`` (m/s) for ``T`` (s) from the distance whose Huber value and
    slope are ``v``, ``slope`` to the distance ``d1`` after it (path step cost)."""
    v1, _ = _huber(d1, hp[0], hp[1], hp[2], hp[3])
    return T * slope * speed + v1 - v


@njit(cache=True, inline="always")
def _turn_charge(px, py, pz, j, kp, pre, ct, hp):
    """``huber.turn_charge`` of goal ``j`` at ``p``: ``ct`` (``intent.turn_charge`` x ``T``) times the
    translation slope at the distance to the nearer of ``j``'s grasp and its pre-grasp point."""
    dx, dy, dz = kp[j, 0] - px, kp[j, 1] - py, kp[j, 2] - pz
    ex, ey, ez = pre[j, 0] - px, pre[j, 1] - py, pre[j, 2] - pz
    d = min(math.sqrt(dx * dx + dy * dy + dz * dz), math.sqrt(ex * ex + ey * ey + ez * ez))
    _, slope = _huber(d, hp[0], hp[1], hp[2], hp[3])
    return ct * slope


@njit(cache=True)
def _q_minus_v(translating, px, py, pz, qw, qx, qy, qz, ux, uy, uz, tw, tx, ty, tz, j,
               kp, kq, pre, anchor, T, ct, hp, rot_scale):
    """``Q_j - V_j`` of goal ``j`` for an input driving one part (``huber.q_minus_v_driven``, path step
    cost; a turn also pays the turn charge ``ct`` measured at ``anchor``, :func:`_turn_charge`); ``t`` is
    ``q`` turned by the input for ``T`` (used in rotation mode only)."""
    speed = math.sqrt(ux * ux + uy * uy + uz * uz)
    if translating:
        dx, dy, dz = kp[j, 0] - px, kp[j, 1] - py, kp[j, 2] - pz
        d = math.sqrt(dx * dx + dy * dy + dz * dz)
        ex, ey, ez = dx - ux * T, dy - uy * T, dz - uz * T
        d1 = math.sqrt(ex * ex + ey * ey + ez * ez)
        v, slope = _huber(d, hp[0], hp[1], hp[2], hp[3])
        return _move_cost(v, slope, d1, speed, T, hp)
    v, slope = _huber(_angle(kq[j, 0], kq[j, 1], kq[j, 2], kq[j, 3], qw, qx, qy, qz), hp[4], hp[5], hp[6], hp[7])
    out = rot_scale * _turn_cost(v, slope, _angle(kq[j, 0], kq[j, 1], kq[j, 2], kq[j, 3], tw, tx, ty, tz), speed,
                                 T, hp)
    if ct > 0.0 and speed > TURNING_RADPS:
        out += _turn_charge(anchor[0], anchor[1], anchor[2], j, kp, pre, ct, hp)
    return out


@njit(cache=True)
def _reward(d_t, d_r, rp, tail, approach):
    """``R_d`` without the bonus, whether ``k_c`` is reached, and what the pose is worth after the horizon:
    ``tail`` paper steps of ``R_d``, or with ``approach`` the return of finishing the approach
    (``reward.distance_reward``, ``reward.approach_return``). ``rp``: scale, beta, rotation threshold (m),
    goal translation (m), goal rotation (rad), goal bonus, step (s), v_t (m/s), v_r (rad/s)."""
    scale, beta, thr = rp[0], rp[1], rp[2]
    r = -scale * (1.0 - math.exp(-beta * _LN2 * d_t))
    if d_t <= thr:
        r -= scale * d_r / _TWO_PI
    reached = d_t <= rp[3] and d_r <= rp[4]
    if not approach:
        return r, reached, r * tail
    steps = max(d_t / rp[7], d_r / rp[8]) / rp[6]
    x = beta * _LN2 * d_t
    mean_left = -math.expm1(-x) / x if x > 1e-9 else 1.0 - x / 2.0
    m = min(1.0, thr / d_t) if d_t > 0.0 else 1.0
    return r, reached, -scale * steps * (1.0 - mean_left) - scale / _TWO_PI * d_r * steps * m * m / 2.0 + rp[5]


@njit(cache=True)
def _first_same(kq):
    """For each goal the first goal with the same orientation (goals often share one: what HO computes
    from a goal's orientation alone is computed once per orientation, the same numbers)."""
    G = kq.shape[0]
    first = np.arange(G)
    for j in range(G):
        for i in range(j):
            if kq[i, 0] == kq[j, 0] and kq[i, 1] == kq[j, 1] and kq[i, 2] == kq[j, 2] and kq[i, 3] == kq[j, 3]:
                first[j] = i
                break
    return first


@njit(cache=True, nogil=True)
def roll(positions, quats, log_w0, kp, kq, pre, anchor, kind, targets, translating, tracked, approach,
         steps, watch_steps, dt, fp, hp, rp, order, claimed, g_lo, g_hi,
         value, stay, watch_p, watch_q, watch_ret, loglik):
    """Fill the outputs of :class:`~.rollouts.Rollouts` (``value``, ``stay``, the watch arrays, ``loglik``)
    for the starts in ``order`` not yet ``claimed``, claiming each before rolling it out, and the user's
    goals ``g_lo`` to ``g_hi - 1`` (:mod:`.split`). Threads share ``claimed`` without a lock: a start a
    thread sees claimed is being computed by another, and two threads that claim the same start at once
    compute it twice and store the same numbers (every output of a rollout is stored, none accumulated),
    so none is missed or spoiled.

    ``fp``: user speed (m/s, rad/s), stand-off (m), alpha, the apply time ``T`` (s), opposition penalty per
    rollout step, opposition threshold, input samples per step x rationality, rotation scale, paper steps
    per rollout step ``k``, terminal paper steps, move gains and top speeds (linear, angular), the turn
    charge times ``T``, the approach corridor's stand-off (m; 0: the straight line), funnel and turn term (m).
    ``pre``: the goals' pre-grasp points; ``anchor``: where the turn charge is
    measured (m, :class:`~.rollouts.Rollouts`).
    ``hp``: the translation and rotation Huber ``c, delta, a, weight``. ``kind``/``targets``: per action
    its kind and, for moves, its goal.
    """
    G, A = kp.shape[0], kind.shape[0]
    sp_t, sp_r, standoff, alpha, T = fp[0], fp[1], fp[2], fp[3], fp[4]
    per_step, th, samples, rot_scale, k, tail = fp[5], fp[6], fp[7], fp[8], fp[9], fp[10]
    g_t, m_t, g_r, m_r, ct = fp[11], fp[12], fp[13], fp[14], fp[15]
    a_s, a_f, a_t = fp[16], fp[17], fp[18]  # the approach corridor (off at a_s = 0)
    corridor = a_s > 0.0
    goal = rp[5]
    shared = np.empty((steps + 1, 4))  # the part the user does not drive, per (c, a) for moves and no-assist
    lw = np.empty(G)
    w = np.empty(G)
    # per start, what every action's rollouts share at step 0: toward each goal the user's error, the
    # reward and its value after the horizon, the tracker's reading of the user's first input (``ll0``);
    # HO's weights, its goals' Huber values and slopes (the driven part's) and, translating, its error
    # toward each goal orientation (``rot0``: HO has not turned yet)
    s_err = np.empty((G, 3))
    s_r = np.empty(G)
    s_end = np.empty(G)
    s_arr = np.empty(G, dtype=np.bool_)
    w0 = np.empty(G)
    v0 = np.empty(G)
    sl0 = np.empty(G)
    rot = np.empty((G, 6))  # HO, per step and goal orientation: error after the user's turn, its angle, V and slope
    rot0 = np.empty((G, 4))
    ll0 = np.empty((G if watch_steps > 0 else 0, G))
    acc = np.empty(G)  # a rollout's log-likelihood so far, stored once (a start computed twice stores the same)
    same_q = _first_same(kq)
    kz = _approach_axes(kq) if corridor else np.empty((0, 3))  # the corridor's axes, computed once a call
    path = np.empty((G, steps, 9))  # turning, per rollout and step: position, quaternion, angle to g, opposed
    has_ho = False
    for a in range(A):
        has_ho = has_ho or kind[a] == HO
    for c in order:
        if claimed[c]:
            continue
        claimed[c] = True
        qw, qx, qy, qz = quats[c, 0], quats[c, 1], quats[c, 2], quats[c, 3]
        for g in range(g_lo, g_hi):
            if translating:
                d_r = _angle(qw, qx, qy, qz, kq[g, 0], kq[g, 1], kq[g, 2], kq[g, 3])
            else:  # the error the user drives along, whose norm is the angle to g
                s_err[g, 0], s_err[g, 1], s_err[g, 2], d_r = _rot_err(kq[g, 0], kq[g, 1], kq[g, 2], kq[g, 3],
                                                                      qw, qx, qy, qz)
            dpx, dpy, dpz = positions[c, 0] - kp[g, 0], positions[c, 1] - kp[g, 1], positions[c, 2] - kp[g, 2]
            s_r[g], s_arr[g], s_end[g] = _reward(math.sqrt(dpx * dpx + dpy * dpy + dpz * dpz), d_r, rp, tail,
                                                 approach)
            stay[c, g] = 0.0 if s_arr[g] else s_r[g] * k
        if has_ho:
            mx = log_w0[c, 0]
            for j in range(1, G):
                mx = max(mx, log_w0[c, j])
            total_w0 = 0.0
            for j in range(G):
                w0[j] = math.exp(log_w0[c, j] - mx)
                total_w0 += w0[j]
                if translating and same_q[j] == j:
                    rot0[j, 0], rot0[j, 1], rot0[j, 2], rot0[j, 3] = _rot_err(kq[j, 0], kq[j, 1], kq[j, 2], kq[j, 3],
                                                                              qw, qx, qy, qz)
                if tracked and translating:
                    dpx, dpy, dpz = kp[j, 0] - positions[c, 0], kp[j, 1] - positions[c, 1], kp[j, 2] - positions[c, 2]
                    v0[j], sl0[j] = _huber(math.sqrt(dpx * dpx + dpy * dpy + dpz * dpz), hp[0], hp[1], hp[2], hp[3])
                elif tracked and same_q[j] < j:
                    v0[j], sl0[j] = v0[same_q[j]], sl0[same_q[j]]
                elif tracked:
                    v0[j], sl0[j] = _huber(_angle(kq[j, 0], kq[j, 1], kq[j, 2], kq[j, 3], qw, qx, qy, qz),
                                           hp[4], hp[5], hp[6], hp[7])
        for a in range(A):
            ho = kind[a] == HO
            t = targets[a]
            # a move's position, turning with the corridor on, depends on the orientation, so on g: its own
            own = corridor and not translating and kind[a] == MOVE
            if not (ho or own):  # the undriven part: the robot's share of a move, nothing for no-assist
                if translating:
                    sw, sx, sy, sz = quats[c, 0], quats[c, 1], quats[c, 2], quats[c, 3]
                else:
                    sx, sy, sz = positions[c, 0], positions[c, 1], positions[c, 2]
                    sw = 0.0
                for s in range(steps + 1):
                    shared[s, 0], shared[s, 1], shared[s, 2], shared[s, 3] = sw, sx, sy, sz
                    if kind[a] == MOVE:
                        if translating:
                            ex, ey, ez, _ = _rot_err(kq[t, 0], kq[t, 1], kq[t, 2], kq[t, 3], sw, sx, sy, sz)
                            ax, ay, az = _clip(g_r * ex, g_r * ey, g_r * ez, m_r)
                            sw, sx, sy, sz = _turn(sw, sx, sy, sz, alpha * ax, alpha * ay, alpha * az, dt)
                        else:
                            vx, vy, vz = _clip(g_t * (kp[t, 0] - sx), g_t * (kp[t, 1] - sy), g_t * (kp[t, 2] - sz), m_t)
                            sx, sy, sz = sx + alpha * vx * dt, sy + alpha * vy * dt, sz + alpha * vz * dt
                    elif translating:
                        sw, sx, sy, sz = _turn(sw, sx, sy, sz, 0.0, 0.0, 0.0, dt)
            for g in range(g_lo, g_hi):
                px, py, pz = positions[c, 0], positions[c, 1], positions[c, 2]
                qw, qx, qy, qz = quats[c, 0], quats[c, 1], quats[c, 2], quats[c, 3]
                gw, gx, gy, gz = kq[g, 0], kq[g, 1], kq[g, 2], kq[g, 3]
                if ho:
                    for j in range(G):
                        lw[j] = log_w0[c, j]
                ex, ey, ez = s_err[g, 0], s_err[g, 1], s_err[g, 2]
                arrived = s_arr[g]
                value[c, g, a, 0] = 0.0 if arrived else s_end[g]
                total = 0.0
                # turning, the user drives the orientation alone and by g's orientation alone: a goal with
                # the orientation of an earlier one (``same_q``) moves exactly as that one's rollout did,
                # only its rewards differ (``path``)
                o = same_q[g]
                twin = not translating and g_lo <= o < g
                if twin and watch_steps > 0:
                    for j in range(G):
                        loglik[c, g, a, j] = loglik[c, o, a, j]
                for s in range(steps):
                    if twin:  # its twin's path
                        px, py, pz = path[o, s, 0], path[o, s, 1], path[o, s, 2]
                        qw, qx, qy, qz = path[o, s, 3], path[o, s, 4], path[o, s, 5], path[o, s, 6]
                        d_r, opposed = path[o, s, 7], path[o, s, 8] != 0.0
                    else:
                        # the user's twist toward g, in the driven part
                        if translating:
                            dx, dy, dz = kp[g, 0] - px, kp[g, 1] - py, kp[g, 2] - pz
                            if math.sqrt(dx * dx + dy * dy + dz * dz) > 1.5 * standoff:
                                dx, dy, dz = pre[g, 0] - px, pre[g, 1] - py, pre[g, 2] - pz
                            ux, uy, uz = _clip(dx, dy, dz, sp_t)
                        else:
                            ux, uy, uz = _clip(ex, ey, ez, sp_r)
                        tw, tx, ty, tz = qw, qx, qy, qz  # q turned by the input for T (rotation mode)
                        if not translating and (ho or s < watch_steps):
                            tw, tx, ty, tz = _turn(qw, qx, qy, qz, ux, uy, uz, T)
                        # the robot's twist: driven part (rx, ry, rz), undriven part (ox, oy, oz)
                        rx = ry = rz = ox = oy = oz = 0.0
                        if ho:
                            if s == 0:  # the start's belief, the same for every goal
                                ws, total_w = w0, total_w0
                            else:
                                mx = lw[0]
                                for j in range(1, G):
                                    mx = max(mx, lw[j])
                                total_w = 0.0
                                for j in range(G):
                                    w[j] = math.exp(lw[j] - mx)
                                    total_w += w[j]
                                ws = w
                            if translating:
                                p1x, p1y, p1z = px + ux * T, py + uy * T, pz + uz * T
                            else:
                                p1x, p1y, p1z = px, py, pz
                            update = tracked and s + 1 < steps
                            speed = math.sqrt(ux * ux + uy * uy + uz * uz)
                            lx = ly = lz = hx = hy = hz = 0.0
                            for j in range(G):
                                wj = ws[j] / total_w
                                if corridor:
                                    ax, ay, az = _aim(p1x, p1y, p1z, tw, tx, ty, tz, j, kp, kq, kz, a_s, a_f, a_t)
                                    lx += wj * ax
                                    ly += wj * ay
                                    lz += wj * az
                                else:
                                    lx += wj * kp[j, 0]
                                    ly += wj * kp[j, 1]
                                    lz += wj * kp[j, 2]
                                o = same_q[j]
                                if translating and s == 0:
                                    vx, vy, vz, d1 = rot0[o, 0], rot0[o, 1], rot0[o, 2], rot0[o, 3]
                                else:
                                    if o == j:
                                        rot[j, 0], rot[j, 1], rot[j, 2], rot[j, 3] = _rot_err(
                                            kq[j, 0], kq[j, 1], kq[j, 2], kq[j, 3], tw, tx, ty, tz)
                                    vx, vy, vz, d1 = rot[o, 0], rot[o, 1], rot[o, 2], rot[o, 3]
                                hx += wj * vx
                                hy += wj * vy
                                hz += wj * vz
                                if update and translating and s == 0:  # from the start: its V and slope
                                    ejx = kp[j, 0] - px - ux * T
                                    ejy = kp[j, 1] - py - uy * T
                                    ejz = kp[j, 2] - pz - uz * T
                                    dist1 = math.sqrt(ejx * ejx + ejy * ejy + ejz * ejz)
                                    lw[j] -= samples * _move_cost(v0[j], sl0[j], dist1, speed, T, hp)
                                elif update and translating:
                                    lw[j] -= samples * _q_minus_v(True, px, py, pz, qw, qx, qy, qz, ux, uy, uz,
                                                                  tw, tx, ty, tz, j, kp, kq, pre, anchor, T, ct, hp,
                                                                  rot_scale)
                                elif update:  # Q - V of the turn: d1, the angle after it, is the error's norm
                                    if s == 0:
                                        v, slope = v0[j], sl0[j]
                                    elif o == j:
                                        v, slope = _huber(_angle(kq[j, 0], kq[j, 1], kq[j, 2], kq[j, 3], qw, qx, qy, qz),
                                                          hp[4], hp[5], hp[6], hp[7])
                                        rot[j, 4], rot[j, 5] = v, slope
                                    else:
                                        v, slope = rot[o, 4], rot[o, 5]
                                    lw[j] -= samples * rot_scale * _turn_cost(v, slope, d1, speed, T, hp)
                                    if ct > 0.0 and speed > TURNING_RADPS:
                                        lw[j] -= samples * _turn_charge(anchor[0], anchor[1], anchor[2], j, kp,
                                                                        pre, ct, hp)
                            lx, ly, lz = _clip(g_t * (lx - p1x), g_t * (ly - p1y), g_t * (lz - p1z), m_t)
                            hx, hy, hz = _clip(g_r * hx, g_r * hy, g_r * hz, m_r)
                            if translating:
                                rx, ry, rz, ox, oy, oz = lx, ly, lz, hx, hy, hz
                            else:
                                rx, ry, rz, ox, oy, oz = hx, hy, hz, lx, ly, lz
                        elif kind[a] == MOVE:
                            ax, ay, az = kp[t, 0], kp[t, 1], kp[t, 2]
                            if corridor:
                                ax, ay, az = _aim(px, py, pz, qw, qx, qy, qz, t, kp, kq, kz, a_s, a_f, a_t)
                            if translating:
                                rx, ry, rz = _clip(g_t * (ax - px), g_t * (ay - py), g_t * (az - pz), m_t)
                            else:
                                vx, vy, vz, _ = _rot_err(kq[t, 0], kq[t, 1], kq[t, 2], kq[t, 3], qw, qx, qy, qz)
                                rx, ry, rz = _clip(g_r * vx, g_r * vy, g_r * vz, m_r)
                                if own:
                                    ox, oy, oz = _clip(g_t * (ax - px), g_t * (ay - py), g_t * (az - pz), m_t)
                        opposed = ((ux * rx < 0.0 and abs(ux) > th and abs(rx) > th)
                                   or (uy * ry < 0.0 and abs(uy) > th and abs(ry) > th)
                                   or (uz * rz < 0.0 and abs(uz) > th and abs(rz) > th))
                        if s == 0 and s < watch_steps:  # from the start pose: the same for every action
                            for j in range(G):
                                if a == 0:
                                    ll0[g, j] = samples * _q_minus_v(translating, px, py, pz, qw, qx, qy, qz, ux, uy,
                                                                     uz, tw, tx, ty, tz, j, kp, kq, pre, anchor, T, ct,
                                                                     hp, rot_scale)
                                acc[j] = 0.0 - ll0[g, j]
                        elif s < watch_steps:
                            for j in range(G):
                                acc[j] -= samples * _q_minus_v(translating, px, py, pz, qw, qx, qy, qz, ux, uy, uz,
                                                               tw, tx, ty, tz, j, kp, kq, pre, anchor, T, ct, hp,
                                                               rot_scale)
                        if s + 1 == watch_steps:
                            for j in range(G):
                                loglik[c, g, a, j] = acc[j]
                        # the blend: the user's twist alone for no-assist
                        if kind[a] == NONE:
                            bx, by, bz = ux, uy, uz
                        else:
                            bx, by, bz = (1.0 - alpha) * ux + alpha * rx, (1.0 - alpha) * uy + alpha * ry, \
                                (1.0 - alpha) * uz + alpha * rz
                        if translating:
                            px, py, pz = px + bx * dt, py + by * dt, pz + bz * dt
                            if ho:
                                qw, qx, qy, qz = _turn(qw, qx, qy, qz, alpha * ox, alpha * oy, alpha * oz, dt)
                            else:
                                qw, qx, qy, qz = shared[s + 1, 0], shared[s + 1, 1], shared[s + 1, 2], shared[s + 1, 3]
                        else:
                            qw, qx, qy, qz = _turn(qw, qx, qy, qz, bx, by, bz, dt)
                            if ho or own:
                                px, py, pz = px + alpha * ox * dt, py + alpha * oy * dt, pz + alpha * oz * dt
                            else:
                                px, py, pz = shared[s + 1, 1], shared[s + 1, 2], shared[s + 1, 3]
                        if translating:
                            d_r = _angle(qw, qx, qy, qz, gw, gx, gy, gz)
                        else:  # the user's next error, and the angle to g
                            ex, ey, ez, d_r = _rot_err(gw, gx, gy, gz, qw, qx, qy, qz)
                            path[g, s, 0], path[g, s, 1], path[g, s, 2] = px, py, pz
                            path[g, s, 3], path[g, s, 4], path[g, s, 5], path[g, s, 6] = qw, qx, qy, qz
                            path[g, s, 7], path[g, s, 8] = d_r, 1.0 if opposed else 0.0
                    dpx, dpy, dpz = px - kp[g, 0], py - kp[g, 1], pz - kp[g, 2]
                    r, reached, end = _reward(math.sqrt(dpx * dpx + dpy * dpy + dpz * dpz), d_r, rp, tail, approach)
                    if not arrived:
                        total += r * k + (per_step if opposed else 0.0) + (goal if reached else 0.0)
                    arrived = arrived or reached
                    value[c, g, a, s + 1] = total + (0.0 if arrived else end)
                    if s + 1 == watch_steps:
                        watch_p[c, g, a, 0], watch_p[c, g, a, 1], watch_p[c, g, a, 2] = px, py, pz
                        watch_q[c, g, a, 0], watch_q[c, g, a, 1], watch_q[c, g, a, 2], watch_q[c, g, a, 3] = \
                            qw, qx, qy, qz
                        watch_ret[c, g, a] = total


def warm_up(cfg: Config) -> None:
    """Compile :func:`roll` (first run on a machine: 5-15 s) or load it from numba's cache, on a one-start
    problem, so the first plan does not pay for it."""
    if not supported(cfg):
        return
    kp, kq = np.array([[0.3, 0.0, 0.1], [0.3, 0.1, 0.1]]), np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0]])
    fp, hp, rp = parameters(cfg, (0.05, 0.2), 1.0)
    outputs = (np.empty((1, 2, 3, 3)), np.empty((1, 2)), np.empty((1, 2, 3, 3)), np.empty((1, 2, 3, 4)),
               np.empty((1, 2, 3)), np.zeros((1, 2, 3, 2)))
    inputs = (kp[:1] + 0.1, kq[:1].copy(), np.log(np.full((1, 2), 0.5)), kp, kq, kp - 0.05, kp[0] + 0.1,
              np.array([MOVE, HO, NONE]), np.array([1, 0, 0]), True, True, False, 2, 1, 1.0, fp, hp, rp)
    roll(*inputs, np.zeros(1, dtype=np.int64), np.zeros(1, dtype=np.bool_), 0, 2, *outputs)


def supported(cfg: Config) -> bool:
    """Whether :func:`roll` implements ``cfg``'s model (the default HO generator and step cost)."""
    return cfg.ho.generator == "moves" and cfg.intent.step_cost == "path"


def parameters(cfg: Config, speed: tuple[float, float], dt: float) -> tuple[FloatArray, FloatArray, FloatArray]:
    """``fp``, ``hp`` and ``rp`` of :func:`roll` from the configuration, the user's speed (m/s, rad/s) and
    the rollout step (s)."""
    rw, it, mv, alpha = cfg.reward, cfg.intent, cfg.move, cfg.blend.alpha
    v_t, v_r = assisted_speeds(cfg, speed)
    fp = np.array([speed[0], speed[1], cfg.intent.user_standoff_m, alpha, it.action_apply_time_s,
                   rw.opposition_penalty * dt / rw.step_s, rw.opposition_threshold,
                   cfg.runtime.belief_hz * dt * it.rationality, it.rotation_scale, dt / rw.step_s,
                   cfg.planner.terminal_s / rw.step_s, mv.linear_gain, mv.linear_max_mps, mv.angular_gain,
                   mv.angular_max_radps, it.turn_charge * it.action_apply_time_s, mv.approach_standoff_m,
                   mv.approach_funnel, mv.approach_turn_m], dtype=float)
    hp = np.array([it.translation.c, it.translation.delta, it.translation.a, it.translation.weight,
                   it.rotation.c, it.rotation.delta, it.rotation.a, it.rotation.weight], dtype=float)
    rp = np.array([rw.scale, rw.beta, rw.rotation_threshold_m, rw.goal_translation_m, rw.goal_rotation_rad, rw.goal,
                   rw.step_s, v_t, v_r], dtype=float)
    return fp, hp, rp
