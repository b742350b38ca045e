"""Configuration: the paper's defaults, and errors that name the offending key (and file)."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from pydantic import ValidationError

from sa_daemon.config import METHODS, Config, ConfigError, config_from_dict, load_config

REPO = Path(__file__).resolve().parents[1]


def test_defaults_are_the_papers():
    c = Config()
    assert c.method == "policy"
    assert c.reward.beta == 8.0
    assert c.reward.rotation_threshold_m == 0.1  # delta
    assert c.reward.gamma == 0.95
    assert c.reward.scale == 100.0
    assert c.reward.question == -5.0 and c.reward.repeated_question == -100.0
    assert c.reward.opposition_penalty == -5.0 and c.reward.opposition_threshold == 0.01
    assert c.reward.goal == 100.0
    assert c.blend.alpha == 0.5
    assert c.blend.predict_margin == 0.4
    assert c.planner.top_goals == 10  # G_m
    assert c.planner.budget_s == 0.1
    assert c.intent.cap == 0.99
    assert c.intent.answer_p_correct == 0.999
    assert c.intent.action_apply_time_s == 0.1


def test_huber_defaults_are_javdanis():
    t, r = Config().intent.translation, Config().intent.rotation
    assert (t.c, t.delta, t.a, t.weight) == (2.25, 0.07, 0.2, 1.0)
    assert (r.c, r.delta, r.a, r.weight) == (0.20, math.pi / 32, 0.01, 0.07)


def test_ho_and_goal_region_defaults():
    c = Config()
    assert c.ho.translation_cost_multiplier == 40.0
    assert c.ho.rotation_cost_multiplier == 0.05
    assert c.ho.translation_shrink_m == 0.02
    assert c.ho.rotation_shrink_rad == math.pi / 12
    assert c.reward.goal_translation_m == 0.01
    assert c.reward.goal_rotation_rad == math.pi / 48
    assert (c.input.linear_scale_mps, c.input.angular_scale_radps) == (0.2, 0.4)


def test_partial_override_keeps_other_defaults():
    c = config_from_dict({"reward": {"beta": 4.0}, "planner": {"top_goals": 3}})
    assert c.reward.beta == 4.0 and c.planner.top_goals == 3
    assert c.reward.gamma == 0.95 and c.intent == Config().intent


def test_config_is_frozen():
    with pytest.raises(ValidationError):
        Config().reward.beta = 3.0  # type: ignore[misc]


def test_unknown_key_refused_and_named():
    with pytest.raises(ConfigError, match=r"reward\.betta"):
        config_from_dict({"reward": {"betta": 8.0}})


def test_a_moved_key_is_refused_with_its_new_place_named():
    with pytest.raises(ConfigError, match=r"planner\.user_standoff_m: unknown key \(moved to intent\.user_standoff_m\)"):
        config_from_dict({"planner": {"user_standoff_m": 0.05}})
    assert config_from_dict({"intent": {"user_standoff_m": 0.05}}).intent.user_standoff_m == 0.05


def test_unknown_top_level_section_named():
    with pytest.raises(ConfigError, match=r"rewards"):
        config_from_dict({"rewards": {"beta": 8.0}})


def test_wrong_type_names_the_key():
    with pytest.raises(ConfigError, match=r"planner\.top_goals"):
        config_from_dict({"planner": {"top_goals": "ten"}})


def test_out_of_range_names_the_key():
    with pytest.raises(ConfigError, match=r"reward\.gamma"):
        config_from_dict({"reward": {"gamma": 1.5}})


@pytest.mark.parametrize("bad", [math.nan, math.inf])
def test_non_finite_refused(bad):
    with pytest.raises(ConfigError, match=r"intent\.translation\.c"):
        config_from_dict({"intent": {"translation": {"c": bad, "delta": 0.07, "a": 0.2}}})
    with pytest.raises(ConfigError, match=r"blend\.alpha"):
        config_from_dict({"blend": {"alpha": bad}})


@pytest.mark.parametrize(("section", "key", "value"), [
    ("reward", "question_time_s", 2.5), ("reward", "question_time_s", 0.0), ("planner", "horizon_s", 4.5),
    ("planner", "watch_s", 0.3)])
def test_watch_model_times_off_its_rollout_grid_are_refused_and_named(section, key, value):
    """The watch model counts these times in rollout steps (1 s by default): a time between two steps is
    refused, not rounded (before session 19 a question's 2.5 s silently ran as 2 steps)."""
    with pytest.raises(ConfigError, match=rf"{section}\.{key}: {value:g} s is not a whole number"):
        config_from_dict({section: {key: value}})
    ok = config_from_dict({section: {key: value}, "planner": {"model": "commit"}} if section == "reward" else
                          {"planner": {key: value, "model": "commit"}})
    assert getattr(getattr(ok, section), key) == value  # the commit model has no grid


def test_the_watch_search_charges_the_configured_question_time():
    from sa_daemon.model.model import SharedAutonomyModel
    from sa_daemon.planner.snapshot import Snapshot
    from sa_daemon.planner.watch import WatchSearch
    from sa_daemon.world.scene import load_scene

    scene = load_scene("scene1")
    for q_s, dt in ((2.0, 1.0), (1.5, 0.5), (3.0, 1.0)):
        cfg = config_from_dict({"reward": {"question_time_s": q_s}, "planner": {"rollout_step_s": dt}})
        model = SharedAutonomyModel(cfg)
        goals = model.initial_belief(scene.goals).goals
        search = WatchSearch(model, Snapshot(goals, [0.25] * 4, scene.start, [0.0] * 6, budget_s=None))
        assert search.n_q * search.dt == pytest.approx(q_s)


def test_bad_method_refused():
    with pytest.raises(ConfigError, match="method"):
        config_from_dict({"method": "telepathy"})


@pytest.mark.parametrize("method", METHODS)
def test_every_method_accepted(method):
    assert config_from_dict({"method": method}).method == method


def test_toml_file_with_bad_key_names_file_and_key(tmp_path):
    f = tmp_path / "bad.toml"
    f.write_text('method = "policy"\n\n[planner]\ntop_goals = 5\ntop_goalz = 6\n')
    with pytest.raises(ConfigError) as e:
        load_config(f)
    assert str(f) in str(e.value)
    assert "planner.top_goalz" in str(e.value)


def test_toml_file_loads_over_defaults(tmp_path):
    f = tmp_path / "ok.toml"
    f.write_text('method = "ho"\n[reward]\nlookahead_steps = 1\n')
    c = load_config(f)
    assert c.method == "ho" and c.reward.lookahead_steps == 1 and c.reward.beta == 8.0


def test_invalid_toml_is_a_config_error(tmp_path):
    f = tmp_path / "broken.toml"
    f.write_text("[reward\nbeta = 8\n")
    with pytest.raises(ConfigError, match="broken.toml"):
        load_config(f)


def test_missing_file_is_a_config_error(tmp_path):
    with pytest.raises(ConfigError, match="not found"):
        load_config(tmp_path / "nope.toml")


def test_no_path_gives_defaults():
    assert load_config(None) == Config()


def test_repository_config_toml_equals_defaults():
    path = REPO / "config.toml"
    if not path.exists():
        pytest.skip("no config.toml at the repository root")
    assert load_config(path) == Config()


@pytest.mark.parametrize("kind", ["directory", "binary"])
def test_unreadable_config_path_is_a_config_error(tmp_path, kind):
    if kind == "directory":
        path = tmp_path
    else:
        path = tmp_path / "binary.toml"
        path.write_bytes(b"\xff\xfe\x00 not text")
    with pytest.raises(ConfigError, match=str(path.name)):
        load_config(path)
