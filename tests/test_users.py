"""The simulated-user population (``sa_daemon/sim/users.py``, ``sa_daemon/users/*.toml``): each built-in
profile's distinguishing behaviour, on the user model in isolation (``SimulatedUser.act`` fed with poses
built here) or in short manual trials on the kinematic arm (scene1), deterministic by seed; and the
profile loader's errors."""

from __future__ import annotations

import math
from functools import cache

import numpy as np
import pytest

from sa_daemon.arm.kinematic import KinematicArm
from sa_daemon.config import Config, ConfigError, SimUserConfig
from sa_daemon.geometry import Pose
from sa_daemon.model.actions import Mode
from sa_daemon.sim.episode import TrialResult, desired_pose, run_trial
from sa_daemon.sim.success import scene_object
from sa_daemon.sim.user import Phase, SimulatedUser, UserInput
from sa_daemon.sim.users import builtin_user_names, load_user
from sa_daemon.world.goals import Goal, GraspType
from sa_daemon.world.grasps import classify_grasp
from sa_daemon.world.holding import holds
from sa_daemon.world.scene import builtin_scene_names, load_scene

SCENE = load_scene("scene1")
TASK = "cup:top"
GOAL = SCENE.goal(TASK)
DT = 1.0 / Config().eval.control_hz  # 0.025 s, the paper's joystick sampling
W = Config().intent.rotation_weight_m_per_rad
KC = GOAL.desired_pose(SCENE.start, W)  # the pose a "closest" user wants
APPROACH = KC.rotation[:, 2]
FINE = {GraspType.TOP_HORIZONTAL, GraspType.TOP_VERTICAL, GraspType.SIDE_HORIZONTAL, GraspType.SIDE_VERTICAL}
PROFILES = (
    "calibrated", "confident", "hasty", "hesitant", "imprecise", "own-pose", "own-pose-off-list", "rotate-first",
)


def _cfg(name: str) -> Config:
    """``Config()`` with the built-in profile ``name`` applied."""
    return load_user(name).apply(Config())


def _user(name: str, seed: int = 0, desired: Pose = KC, **sim_user) -> SimulatedUser:
    """The profile's user wanting ``desired``; ``sim_user`` overrides fields in a copy of its config."""
    cfg = _cfg(name)
    su = cfg.sim_user.model_copy(update=sim_user) if sim_user else cfg.sim_user
    return SimulatedUser(TASK, desired, su, cfg.input, np.random.default_rng(seed), DT)


def _hold_still(user: SimulatedUser, pose: Pose, seconds: float) -> list[UserInput]:
    """Samples of ``user`` while the arm stays at ``pose`` (it does not follow the stick)."""
    return [user.act(pose) for _ in range(round(seconds / DT))]


def _drive(user: SimulatedUser, start: Pose, steps: int, until=None) -> list[tuple[UserInput, Pose]]:
    """A perfect arm: the pose follows the user's twist. (sample, pose it was taken at) per step; stops
    after a close or when ``until(user, sample)`` is true."""
    pose, log = start, []
    for _ in range(steps):
        inp = user.act(pose)
        log.append((inp, pose))
        if inp.close or (until is not None and until(user, inp)):
            break
        pose = pose.moved(inp.twist(user.scale), DT)
    return log


def _still(inp: UserInput) -> bool:
    return not np.any(inp.axes)


def _runs(flags: list[bool]) -> list[tuple[int, int]]:
    """(start, length) of each run of true flags."""
    out, i = [], 0
    while i < len(flags):
        if flags[i]:
            j = i
            while j < len(flags) and flags[j]:
                j += 1
            out.append((i, j - i))
            i = j
        else:
            i += 1
    return out


FAR = Pose(KC.position + np.array([-0.15, -0.15, 0.25]), KC.quat_wxyz)  # far behind the pre-grasp point


class _RecordingArm(KinematicArm):
    """The kinematic arm, remembering where the gripper was closed."""

    closed_at: Pose | None = None

    def command_gripper(self, closed: bool) -> None:
        if closed:
            self.closed_at = self.read().pose
        super().command_gripper(closed)


def _trial_with_arm(name: str, seed: int) -> tuple[TrialResult, _RecordingArm]:
    arms: list[_RecordingArm] = []

    def factory(scene, cfg):
        arms.append(_RecordingArm(scene.start, cfg.limits))
        return arms[-1]

    result = run_trial(SCENE, TASK, "manual", seed, _cfg(name), arm_factory=factory, user_name=name)
    return result, arms[0]


@cache
def _trial(name: str, seed: int = 0) -> TrialResult:
    """A recorded manual trial of ``name`` on scene1's cup:top (cached: several tests compare them)."""
    return run_trial(SCENE, TASK, "manual", seed, _cfg(name), record=True, user_name=name)


# -- 1. rotate-first -----------------------------------------------------------------------------------


@pytest.mark.parametrize("seed", [0, 1])
def test_rotate_first_aligns_before_any_translation_input(seed):
    user = _user("rotate-first", seed)
    log = _drive(user, SCENE.start, 1600, until=lambda u, inp: inp.mode is Mode.TRANSLATION and not _still(inp))
    moving = [(inp, pose) for inp, pose in log if not _still(inp)]
    assert moving[0][0].mode is Mode.ROTATION
    first_t = next(i for i, (inp, _) in enumerate(moving) if inp.mode is Mode.TRANSLATION)
    assert first_t > 0 and all(inp.mode is Mode.ROTATION for inp, _ in moving[:first_t])
    # It translates only once aligned: the rotation error is at rotation_done_rad by then.
    _, rot0 = SCENE.start.distance(KC)
    _, rot = moving[first_t][1].distance(KC)
    assert rot0 > 0.5 and rot <= user.cfg.rotation_done_rad + 1e-9


@pytest.mark.parametrize("seed", [0, 1])
def test_the_calibrated_user_translates_first(seed):
    user = _user("calibrated", seed)
    log = _drive(user, SCENE.start, 40)
    first = next(inp for inp, _ in log if not _still(inp))
    assert first.mode is Mode.TRANSLATION
    assert user.mode_changes == 0


@pytest.mark.parametrize("name, first_mode", [("rotate-first", "rotation"), ("calibrated", "translation")])
def test_first_input_of_a_manual_trial(name, first_mode):
    tl = _trial(name).timeline
    twists = np.asarray(tl.user_twist)
    moving = np.flatnonzero(np.any(twists != 0.0, axis=1))
    assert tl.mode[moving[0]] == first_mode
    first_translation = next(i for i in moving if np.any(twists[i, :3]))
    first_rotation = next(i for i in moving if np.any(twists[i, 3:]))
    assert bool(first_rotation < first_translation) == (name == "rotate-first")


# -- 2. hasty ------------------------------------------------------------------------------------------


def test_hasty_draws_its_closing_tolerance_per_trial():
    su = _cfg("hasty").sim_user
    assert su.close_translation_max_m is not None
    tols = [_user("hasty", seed).close_translation_m for seed in range(30)]
    assert all(su.close_translation_m <= t <= su.close_translation_max_m for t in tols)
    assert len(set(tols)) == len(tols)  # varies across seeds
    assert min(tols) < 0.02 and max(tols) > 0.03  # spread over the range
    assert tols == [_user("hasty", seed).close_translation_m for seed in range(30)]  # seeded
    assert {_user("calibrated", seed).close_translation_m for seed in range(5)} == {0.01}


def test_a_hasty_close_far_from_the_grasp_fails_on_geometry():
    for seed in range(10):
        result, arm = _trial_with_arm("hasty", seed)
        assert arm.closed_at is not None  # it closed (no timeout)
        d_t, _ = arm.closed_at.distance(KC)
        assert d_t <= _cfg("hasty").sim_user.close_translation_max_m + 1e-9
        if d_t > 0.025:
            break
    else:
        pytest.fail("no hasty trial closed beyond 2.5 cm in seeds 0-9")
    assert result.success is False
    assert result.failure not in ("", "timeout")
    assert result.user == "hasty"


def test_hasty_closes_three_cm_short_along_the_approach_when_its_tolerance_allows():
    short = Pose(KC.position - 0.03 * APPROACH, KC.quat_wxyz)  # 3 cm back along the approach axis
    seeds = range(40)
    wide = next(s for s in seeds if _user("hasty", s).close_translation_m > 0.03)
    narrow = next(s for s in seeds if _user("hasty", s).close_translation_m < 0.03)
    assert _user("hasty", wide).act(short).close is True
    assert _user("hasty", narrow).act(short).close is False
    assert _user("calibrated", wide).act(short).close is False
    assert _user("calibrated", wide).act(KC).close is True


# -- 3. own-pose ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("task", SCENE.targets)
def test_own_pose_wants_another_listed_pose_than_kc(task):
    cfg = _cfg("own-pose")
    goal = SCENE.goal(task)
    kc = goal.desired_pose(SCENE.start, cfg.intent.rotation_weight_m_per_rad)
    assert len(goal.poses) > 1
    chosen = []
    for seed in range(8):
        pose = desired_pose(goal, SCENE.start, cfg, np.random.default_rng(seed))
        assert pose is not kc
        assert sum(pose.distance(kc)) > 1e-6
        assert any(pose is p for p in goal.poses)
        chosen.append(next(i for i, p in enumerate(goal.poses) if p is pose))
    assert len(set(chosen)) > 1  # seeded, not always the same one


def test_own_pose_of_a_single_pose_goal_is_kc_and_calibrated_wants_kc():
    one = Goal("cup", GraspType.TOP, (KC,))
    assert desired_pose(one, SCENE.start, _cfg("own-pose"), np.random.default_rng(0)) is KC
    assert desired_pose(GOAL, SCENE.start, _cfg("calibrated"), np.random.default_rng(0)) is KC


# -- 4. own-pose-off-list ------------------------------------------------------------------------------


@pytest.mark.parametrize("scene_name", builtin_scene_names())
def test_own_pose_off_list_wants_a_holding_pose_in_no_list_near_kc(scene_name):
    cfg = _cfg("own-pose-off-list")
    su = cfg.sim_user
    scene = load_scene(scene_name)
    for goal in scene.goals:
        obj = scene_object(scene, goal.object)
        kc = goal.desired_pose(scene.start, cfg.intent.rotation_weight_m_per_rad)
        fine = goal.grasp_type in FINE
        for seed in range(5):
            pose = desired_pose(goal, scene.start, cfg, np.random.default_rng(seed), obj=obj)
            where = f"{scene_name} {goal.target} seed {seed}"
            # In no list: more than 1 mm from every listed pose by the planner's metric (d_t + w d_r; the
            # shift alone may be drawn below 1 mm while the turn is not).
            assert goal.pose_distances(pose, cfg.intent.rotation_weight_m_per_rad).min() > 1e-3, where
            assert not any(pose is p for p in goal.poses)
            d_t, d_r = pose.distance(kc)
            assert d_t <= su.off_list_m + 1e-12 and d_r <= su.off_list_rad + 1e-9, where
            assert classify_grasp(pose, fine=fine) is goal.grasp_type, where
            assert holds(obj, pose, goal.grasp_type).held, where


# -- 5. confident --------------------------------------------------------------------------------------


def _burst_phase(i: int, su: SimUserConfig) -> str:
    """``push``/``release``/``edge`` of sample ``i`` in the burst cycle (edges: float rounding may go
    either way)."""
    phase = (i * DT) % (su.burst_s + su.burst_pause_s)
    if min(abs(phase - su.burst_s), phase, su.burst_s + su.burst_pause_s - phase) < DT / 2:
        return "edge"
    return "push" if phase < su.burst_s else "release"


def test_confident_pushes_one_axis_at_full_deflection_in_bursts():
    su = _cfg("confident").sim_user
    assert su.one_axis and su.burst_s > 0 and su.burst_pause_s > 0
    user = _user("confident", noise_std=0.0)
    samples = _hold_still(user, FAR, 3.0)  # four burst cycles
    phases = [_burst_phase(i, su) for i in range(len(samples))]
    pushes = [s for s, p in zip(samples, phases) if p == "push"]
    releases = [s for s, p in zip(samples, phases) if p == "release"]
    assert len(pushes) > 60 and len(releases) > 25
    for s in pushes:
        assert s.mode is Mode.TRANSLATION
        assert np.count_nonzero(s.axes) == 1  # one axis at a time ...
        assert np.max(np.abs(s.axes)) == pytest.approx(1.0, abs=1e-12)  # ... at full deflection
    assert all(_still(s) for s in releases)
    assert user.mode_changes == 0


def test_confident_with_its_own_noise_pushes_its_largest_axis_near_full_deflection():
    su = _cfg("confident").sim_user
    assert su.noise_std > 0
    samples = _hold_still(_user("confident", seed=3), FAR, 3.0)
    pushes = np.array([s.axes for i, s in enumerate(samples) if _burst_phase(i, su) == "push"])
    largest = np.sort(np.abs(pushes), axis=1)
    assert np.all(largest[:, 2] >= 1.0 - 5 * su.noise_std)
    assert np.mean(largest[:, 2] == 1.0) > 0.3  # clipped at the stick's limit
    assert np.sqrt(np.mean(largest[:, :2] ** 2)) < 2 * su.noise_std  # the others carry noise only
    releases = [s for i, s in enumerate(samples) if _burst_phase(i, su) == "release"]
    assert releases and all(_still(s) for s in releases)


# -- 6. imprecise --------------------------------------------------------------------------------------


@pytest.mark.parametrize("tremor_hz", [None, 8.0], ids=["profile", "8Hz"])
def test_imprecise_input_spectrum_peaks_at_the_tremor_frequency(tremor_hz):
    """Noise off and no corrective switches (each a 0.5 s silence, a step in the window) in a copy: the
    tremor alone varies the input. 4 s at 40 Hz: 0.25 Hz bins."""
    extra = {"noise_std": 0.0, "corrective_switch_hz": 0.0}
    if tremor_hz is not None:
        extra["tremor_hz"] = tremor_hz
    user = _user("imprecise", seed=2, **extra)
    want = user.cfg.tremor_hz
    if tremor_hz is None:
        assert want == 5.0 and _cfg("imprecise").sim_user.tremor_std > 0
    samples = _hold_still(user, FAR, 6.0)[round(2.0 / DT):]  # after the persistence step (1 s)
    axes = np.array([s.axes for s in samples])
    assert len(axes) == 160 and np.all(np.abs(axes) < 1.0)  # not clipped
    spectrum = np.abs(np.fft.rfft(axes - axes.mean(axis=0), axis=0)).sum(axis=1)
    freqs = np.fft.rfftfreq(len(axes), DT)
    assert abs(freqs[int(np.argmax(spectrum))] - want) <= (freqs[1] - freqs[0]) + 1e-9


def test_the_calibrated_input_has_no_tremor_peak():
    user = _user("calibrated", noise_std=0.0)
    axes = np.array([s.axes for s in _hold_still(user, FAR, 6.0)[round(2.0 / DT):]])
    assert np.all(np.ptp(axes, axis=0) < 1e-12)  # constant: nothing oscillates


def test_imprecise_makes_more_mode_changes_than_the_calibrated_user():
    assert _trial("imprecise").mode_changes > _trial("calibrated").mode_changes
    # On its own: held far away, the calibrated user never switches; the imprecise one checks the other
    # mode now and then (corrective_switch_hz, two counted switches each).
    calm, shaky = _user("calibrated", seed=1), _user("imprecise", seed=1)
    _hold_still(calm, FAR, 120.0)
    _hold_still(shaky, FAR, 120.0)
    assert calm.mode_changes == 0
    assert shaky.mode_changes >= 4


# -- 7. hesitant ---------------------------------------------------------------------------------------


def test_hesitant_pauses_at_the_start_and_once_halfway_to_the_pregrasp_point():
    su = _cfg("hesitant").sim_user
    user = _user("hesitant", seed=0)
    log = _drive(user, SCENE.start, round(40.0 / DT), until=lambda u, _: u.phase is not Phase.APPROACH)
    assert user.phase is not Phase.APPROACH  # reached the pre-grasp point
    dist = np.array([np.linalg.norm(user.pregrasp - pose.position) for _, pose in log])
    pauses = [(i, n) for i, n in _runs([_still(inp) for inp, _ in log]) if n * DT >= 1.0]
    assert len(pauses) == 2  # the start and the one midway; nothing else that long
    (s0, n0), (s1, n1) = pauses
    # Each lasts its configured time (float accumulation of dt may add one sample).
    assert s0 == 0 and su.start_pause_s - 1e-9 <= n0 * DT <= su.start_pause_s + DT + 1e-9
    assert su.mid_pause_s - 1e-9 <= n1 * DT <= su.mid_pause_s + DT + 1e-9
    # It starts once the pose it saw (0.15 s ago) is halfway: the true pose is just past halfway.
    assert 0.4 <= dist[s1] / dist[0] <= 0.5
    assert not _still(log[n0][0])  # moves right after the start pause


def test_hesitant_answer_delays():
    su = _cfg("hesitant").sim_user
    assert (su.answer_delay_s, su.answer_delay_max_s) == (0.8, 4.0)
    user = _user("hesitant", seed=5)
    delays = [user.answer_delay(q) for q in range(12)]
    assert all(0.8 <= d <= 4.0 for d in delays)
    assert [user.answer_delay(q) for q in range(12)] == delays  # stable per question
    assert len(set(delays)) == len(delays)  # varies across questions
    calibrated = _user("calibrated", seed=5)
    assert {calibrated.answer_delay(q) for q in range(5)} == {Config().sim_user.answer_delay_s}


# -- 8. calibrated -------------------------------------------------------------------------------------


def test_the_calibrated_profile_changes_nothing():
    profile = load_user("calibrated")
    assert profile.overrides == {} and profile.sources == {}
    cfg = Config()
    applied = profile.apply(cfg)
    assert applied is cfg or applied == cfg


def test_a_calibrated_trial_has_the_metrics_of_a_trial_without_a_profile():
    plain = run_trial(SCENE, TASK, "manual", 0, Config())
    assert _trial("calibrated").metrics() == plain.metrics()


def test_behaviours_switched_off_draw_nothing_and_change_no_trial():
    """docs/simulated-user.md: the new behaviours draw no random numbers when off, so the calibrated
    user's trials do not depend on their other settings."""
    su = Config().sim_user.model_copy(update={
        "tremor_hz": 9.0, "burst_pause_s": 0.3, "off_list_m": 0.04, "off_list_rad": 0.5, "order": "translate_first",
    })
    cfg = Config().model_copy(update={"sim_user": su})
    assert run_trial(SCENE, TASK, "manual", 0, cfg).metrics() == _trial("calibrated").metrics()


# -- 9. the loader -------------------------------------------------------------------------------------


def _write(tmp_path, text: str):
    path = tmp_path / "bad-user.toml"
    path.write_text('name = "bad"\nsummary = "a broken profile"\n' + text)
    return path


BAD = {
    "unknown top-level key": ('colour = "red"\n', ["colour"]),
    "unknown sim_user key": ('[sim_user]\nspeed = 1.0\n[sources]\nspeed = "fast"\n', ["sim_user.speed", "unknown"]),
    "wrong type": ('[sim_user]\ntremor_hz = "fast"\n[sources]\ntremor_hz = "r"\n', ["sim_user.tremor_hz"]),
    "out of range": ("[sim_user]\ntremor_hz = 50.0\n[sources]\ntremor_hz = \"r\"\n", ["sim_user.tremor_hz"]),
    "no source": ("[sim_user]\nburst_s = 0.5\n", ["sources.burst_s"]),
    "empty source": ('[sim_user]\nburst_s = 0.5\n[sources]\nburst_s = " "\n', ["sources.burst_s"]),
    "source without key": (
        '[sim_user]\nburst_s = 0.5\n[sources]\nburst_s = "r"\nburst_pause_s = "r"\n', ["sources.burst_pause_s"],
    ),
    "max below min": (
        (
            "[sim_user]\nclose_translation_m = 0.02\nclose_translation_max_m = 0.015\n"
            '[sources]\nclose_translation_m = "r"\nclose_translation_max_m = "r"\n'
        ),
        ["close_translation_max_m"],
    ),
}


@pytest.mark.parametrize("case", BAD, ids=list(BAD))
def test_a_bad_profile_is_a_config_error_naming_the_key_and_the_file(tmp_path, case):
    text, keys = BAD[case]
    path = _write(tmp_path, text)
    with pytest.raises(ConfigError) as err:
        load_user(path)
    msg = str(err.value)
    assert str(path) in msg
    for key in keys:
        assert key in msg
    with pytest.raises(ConfigError):  # by path as a string, too
        load_user(str(path))


def test_a_good_profile_file_loads_and_applies(tmp_path):
    path = _write(tmp_path, '[sim_user]\nburst_s = 0.5\n[sources]\nburst_s = "a reason"\n')
    profile = load_user(path)
    assert profile.name == "bad" and profile.overrides == {"burst_s": 0.5}
    assert profile.apply(Config()).sim_user.burst_s == 0.5


def test_an_unknown_profile_names_the_built_in_ones():
    with pytest.raises(ConfigError) as err:
        load_user("nope")
    msg = str(err.value)
    assert "nope" in msg
    for name in builtin_user_names():
        assert name in msg


def test_a_profile_clashing_with_the_configuration_is_a_config_error():
    su = Config().sim_user.model_copy(update={"close_translation_m": 0.05})
    cfg = Config().model_copy(update={"sim_user": su})
    with pytest.raises(ConfigError) as err:
        load_user("hasty").apply(cfg)
    assert "close_translation_max_m" in str(err.value) and "hasty" in str(err.value)


def test_the_built_in_profiles_are_listed_calibrated_first():
    names = builtin_user_names()
    assert names[0] == "calibrated"
    assert set(PROFILES) <= set(names)


@pytest.mark.parametrize("name", builtin_user_names())
def test_every_built_in_profile_loads_applies_and_cites_a_source_per_override(name):
    profile = load_user(name)
    assert profile.name == name
    assert profile.summary.strip()
    assert set(profile.sources) == set(profile.overrides)
    assert all(isinstance(s, str) and s.strip() for s in profile.sources.values())
    cfg = profile.apply(Config())
    for key, value in profile.overrides.items():
        assert getattr(cfg.sim_user, key) == value, key
    if name != "calibrated":
        assert cfg.sim_user != Config().sim_user
    # Only [sim_user] changes.
    assert cfg.model_copy(update={"sim_user": Config().sim_user}) == Config()


def test_user_behaviour_is_deterministic_by_seed():
    a = [s.axes for s in _hold_still(_user("imprecise", seed=7), FAR, 1.0)]
    b = [s.axes for s in _hold_still(_user("imprecise", seed=7), FAR, 1.0)]
    c = [s.axes for s in _hold_still(_user("imprecise", seed=8), FAR, 1.0)]
    np.testing.assert_array_equal(a, b)
    assert not np.allclose(a, c)


def test_profiles_are_distinct():
    # Guard for the list above: every named profile exists and differs from the calibrated one.
    base = Config().sim_user
    for name in PROFILES[1:]:
        assert _cfg(name).sim_user != base, name
    assert math.isclose(_cfg("hasty").sim_user.close_translation_max_m, 0.035)
