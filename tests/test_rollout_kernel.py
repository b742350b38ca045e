"""The compiled rollouts (``planner/kernel.py``) against the numpy form of the same model (``Rollouts``
with ``compiled=False``), on random problems in every combination the kernel implements."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from sa_daemon.config import config_from_dict
from sa_daemon.cores import cores
from sa_daemon.geometry import quat_normalize
from sa_daemon.model.actions import HO_ACTION, NO_ASSIST, Action, ActionKind, Mode
from sa_daemon.model.huber import pregrasp_points
from sa_daemon.planner import kernel
from sa_daemon.planner.rollouts import Rollouts
from sa_daemon.planner.split import threads

FIELDS = ("value", "stay", "watch_positions", "watch_quats", "watch_return", "loglik")


def _problem(rng: np.random.Generator, C: int = 3, G: int = 5, twins: bool = False):
    """Random start poses near random goal poses (some within the goal's reach, so arrivals happen), a
    random belief per start with one goal at zero, and moves to three goals with HO and no-assist. With
    ``twins`` goals 3 and 4 have the orientations of goals 1 and 0 (other positions), as grasps of one kind
    on different objects do: turning, the kernel computes such a goal's path once."""
    kp = rng.uniform([0.2, -0.3, 0.0], [0.5, 0.3, 0.3], (G, 3))
    kq = quat_normalize(rng.normal(size=(G, 4)))
    if twins:
        kq[3], kq[4] = kq[1], kq[0]
    near = rng.integers(0, G, C)
    positions = kp[near] + rng.normal(scale=[0.15, 0.15, 0.15], size=(C, 3))
    positions[0] = kp[near[0]] + 0.004  # within the goal's translation tolerance
    quats = quat_normalize(kq[near] + rng.normal(scale=0.4, size=(C, 4)))
    quats[0] = kq[near[0]] * -1.0  # the same rotation, the other sign
    weights = rng.dirichlet(np.ones(G), C)
    weights[:, -1] = 0.0
    weights /= weights.sum(axis=1, keepdims=True)
    actions = [Action(ActionKind.MOVE, goal=g) for g in (0, 2, 3)] + [HO_ACTION, NO_ASSIST]
    return positions, quats, weights, kp, kq, actions


@pytest.mark.parametrize("mode, belief, terminal, watch_steps, charge, corridor", [
    *itertools.product((Mode.TRANSLATION, Mode.ROTATION), ("tracked", "fixed"), ("fixed", "approach"), (0, 2),
                       (0.0, 0.2), (0.0,)),
    # the approach corridor (move.approach_standoff_m), in both modes and both HO beliefs
    *itertools.product((Mode.TRANSLATION, Mode.ROTATION), ("tracked", "fixed"), ("fixed",), (2,), (0.0,), (0.06,)),
])
def test_the_compiled_rollouts_equal_the_numpy_ones(mode, belief, terminal, watch_steps, charge, corridor):
    cfg = config_from_dict({"planner": {"ho_belief": belief, "terminal": terminal, "threads": 1},  # one block
                            "intent": {"rotation_rationality": 200.0, "turn_charge": charge},
                            "move": {"approach_standoff_m": corridor}}, "test")
    assert kernel.supported(cfg)
    rng = np.random.default_rng(7)
    arrivals = 0
    for trial in range(4):
        positions, quats, weights, kp, kq, actions = _problem(rng, twins=trial % 2 == 1)
        speed, dt = (rng.uniform(0.0, 0.08), rng.uniform(0.0, 0.4)), rng.uniform(0.3, 1.0)
        anchor = None if trial < 2 else kp[trial] + 0.01  # where the user last translated (None: start 0)
        R = [Rollouts(cfg, positions, quats, weights, kp, kq, actions, mode, speed, steps=4, dt=dt,
                      watch_steps=watch_steps, compiled=compiled, anchor=anchor) for compiled in (False, True)]
        arrivals += int(np.sum(np.diff(R[1].value, axis=-1) > 50.0))  # the +100 bonus net of a step's R_d
        for field in FIELDS[:2] + (FIELDS[2:] if watch_steps else ()):
            a, b = getattr(R[0], field), getattr(R[1], field)
            assert a.shape == b.shape, field
            # atol: 2 acos|<a, b>| near a zero angle turns a last-digit difference of the dot product into
            # ~1e-8 rad, which the likelihood's samples x rationality multiply
            assert np.allclose(a, b, rtol=1e-9, atol=1e-6), (trial, field, np.abs(a - b).max())
        assert np.all(R[1].stay[0][R[1].value[0, :, 0, 0] == 0.0] == 0.0)
    assert arrivals, "no rollout reached its goal: the bonus went untested"


def test_the_options_the_kernel_does_not_implement_keep_the_numpy_form():
    base = config_from_dict({}, "test")
    assert kernel.supported(base)
    gradient = config_from_dict({"ho": {"generator": "gradient"}}, "test")
    time_cost = config_from_dict({"intent": {"step_cost": "time"}}, "test")
    assert not kernel.supported(gradient) and not kernel.supported(time_cost)
    rng = np.random.default_rng(3)
    positions, quats, weights, kp, kq, actions = _problem(rng)
    for cfg in (gradient, time_cost):
        auto = Rollouts(cfg, positions, quats, weights, kp, kq, actions, Mode.TRANSLATION, (0.05, 0.0), 3, 1.0)
        numpy_form = Rollouts(cfg, positions, quats, weights, kp, kq, actions, Mode.TRANSLATION, (0.05, 0.0), 3, 1.0,
                              compiled=False)
        assert np.array_equal(auto.value, numpy_form.value)


def test_the_rollouts_do_not_depend_on_how_many_threads_share_them():
    """``planner.threads`` splits the starts or the user's goals into blocks; every rollout is computed
    alone, so the outputs are bit for bit the same for any split (including more threads than goals: one
    goal a block, so a goal whose orientation twin is in another block computes its path in full, which
    must equal the copy it takes with one thread)."""
    rng = np.random.default_rng(11)
    positions, quats, weights, kp, kq, actions = _problem(rng, C=7, twins=True)
    out = []
    for n in (1, 2, 3, 16):
        cfg = config_from_dict({"planner": {"threads": n}}, "test")
        R = Rollouts(cfg, positions, quats, weights, kp, kq, actions, Mode.ROTATION, (0.03, 0.3), steps=4, dt=0.5,
                     watch_steps=1)
        out.append([getattr(R, f) for f in FIELDS])
    for other in out[1:]:
        for a, b in zip(out[0], other, strict=True):
            assert np.array_equal(a, b)


def test_a_start_rolled_out_twice_stores_the_same_numbers():
    """Threads claim starts without a lock (``kernel.roll``): two may roll out the same start at
    once. That is harmless only if every output of a rollout is stored, not added to: a start rolled out
    again over its own outputs (watched steps included) leaves them bit for bit as they were."""
    rng = np.random.default_rng(3)
    positions, quats, weights, kp, kq, actions = _problem(rng, C=4, twins=True)
    for mode in (Mode.TRANSLATION, Mode.ROTATION):
        R = Rollouts(config_from_dict({"planner": {"threads": 1}}, "test"), positions, quats, weights, kp, kq,
                     actions, mode, (0.03, 0.3), steps=4, dt=0.5, watch_steps=2)
        once = [getattr(R, f).copy() for f in FIELDS]
        kind = np.array([kernel.MOVE if a.kind is ActionKind.MOVE else kernel.HO if a.kind is ActionKind.HO
                         else kernel.NONE for a in actions])
        targets = np.array([a.goal if a.kind is ActionKind.MOVE else 0 for a in actions])
        fp, hp, rp = kernel.parameters(config_from_dict({}, "test"), (0.03, 0.3), 0.5)
        again = np.zeros(len(positions), dtype=bool)
        inputs = (positions, quats, np.log(np.maximum(weights, 1e-300)), kp, kq, pregrasp_points(kp, kq, 0.06),
                  positions[0], kind, targets, mode is Mode.TRANSLATION, True, False, 4, 2, 0.5, fp, hp, rp)
        outputs = tuple(getattr(R, f) for f in FIELDS)
        kernel.roll(*inputs, np.array([2, 0, 2]), again, 0, len(kp), *outputs)
        kernel.roll(*inputs, np.array([2]), np.zeros(len(positions), dtype=bool), 0, len(kp), *outputs)
        assert list(again) == [True, False, True, False]  # claimed once each, the repeat skipped
        for field, before in zip(FIELDS, once, strict=True):
            assert np.array_equal(getattr(R, field), before), (mode, field)


def test_rollouts_started_in_the_background_equal_those_computed_now_and_can_be_cancelled():
    """``background=True`` starts the rollouts on the pool's threads and returns; after ``join`` the arrays
    are those of a plain construction. ``cancel`` stops them (the starts in progress finish) and leaves
    the pool free for the next batch."""
    rng = np.random.default_rng(8)
    problem = _problem(rng, C=40, G=6)
    cfg = config_from_dict({"planner": {"threads": 2}}, "test")
    now = Rollouts(cfg, *problem, Mode.TRANSLATION, (0.05, 0.3), steps=4, dt=1.0)
    later = Rollouts(cfg, *problem, Mode.TRANSLATION, (0.05, 0.3), steps=4, dt=1.0, background=True)
    later.join()
    later.join()  # idempotent
    assert np.array_equal(now.value, later.value) and np.array_equal(now.stay, later.stay)
    dropped = Rollouts(cfg, *problem, Mode.TRANSLATION, (0.05, 0.3), steps=4, dt=1.0, background=True)
    dropped.cancel()
    again = Rollouts(cfg, *problem, Mode.TRANSLATION, (0.05, 0.3), steps=4, dt=1.0)
    assert np.array_equal(now.value, again.value)


def test_threads_zero_means_one_per_usable_core():
    assert threads(config_from_dict({}, "test")) == cores() >= 1
    assert threads(config_from_dict({"planner": {"threads": 3}}, "test")) == 3


def test_a_forked_child_makes_its_own_rollout_threads():
    """After ``fork`` the parent's pool threads do not exist in the child; the child's rollouts must
    still run (not wait for ever on a pool with no threads) and give the parent's result."""
    import multiprocessing as mp

    rng = np.random.default_rng(5)
    problem = _problem(rng, C=4)
    cfg = config_from_dict({"planner": {"threads": 2}}, "test")
    parent = Rollouts(cfg, *problem, Mode.ROTATION, (0.03, 0.3), steps=3, dt=1.0).value  # the pool exists now
    ctx = mp.get_context("fork")
    with ctx.Pool(1) as pool:
        child = pool.apply_async(_rollout_values, (cfg, problem)).get(timeout=30)
    assert np.array_equal(parent, child)


def _rollout_values(cfg, problem):
    return Rollouts(cfg, *problem, Mode.ROTATION, (0.03, 0.3), steps=3, dt=1.0).value


@pytest.mark.parametrize("compiled", [False, True])
def test_without_watched_steps_the_watch_arrays_are_empty_in_both_forms(compiled):
    """No watched steps: nothing to read there (not an uninitialised buffer), in either form."""
    rng = np.random.default_rng(2)
    positions, quats, weights, kp, kq, actions = _problem(rng)
    R = Rollouts(config_from_dict({}, "test"), positions, quats, weights, kp, kq, actions, Mode.ROTATION,
                 (0.03, 0.3), steps=3, dt=1.0, compiled=compiled)
    assert all(getattr(R, f).size == 0 for f in FIELDS[2:])
    assert R.value.shape == (3, 5, 5, 4) and np.all(np.isfinite(R.value))


@pytest.mark.parametrize("compiled", [False, True])
def test_a_turn_in_the_rollouts_is_charged_where_the_user_last_translated(compiled):
    """Turning, the watch model's tracker measures the charge at ``anchor`` (the user's point), in both
    forms: the default is the first start's position, and an anchor at goal 1 favours goal 1 over one at
    goal 0 in the likelihood, by the same amount for every watched step in which the predicted user turns
    (none once at its goal's orientation: no turn, no charge)."""
    cfg = config_from_dict({"planner": {"threads": 1}, "intent": {"turn_charge": 0.2}}, "test")
    positions, quats, weights, kp, kq, actions = _problem(np.random.default_rng(3))

    def loglik(anchor):
        return Rollouts(cfg, positions, quats, weights, kp, kq, actions, Mode.ROTATION, (0.03, 0.3), steps=3,
                        dt=0.5, watch_steps=2, compiled=compiled, anchor=anchor).loglik

    np.testing.assert_array_equal(loglik(None), loglik(positions[0]))
    at0, at1 = loglik(kp[0]), loglik(kp[1])
    gain = (at1[..., 1] - at1[..., 0]) - (at0[..., 1] - at0[..., 0])
    step = gain.max() / 2  # two watched steps
    assert step > 0.0 and np.mean(gain == 2 * step) > 0.5
    np.testing.assert_allclose(gain / step, np.round(gain / step), atol=1e-9)
    assert np.all(gain >= 0.0)
