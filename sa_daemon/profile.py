"""Per-person profiles: one TOML file a person, applied over the configuration (``docs/profiles.md``).

    name = "alex"
    summary = "one hand, left; a mild tremor"
    [joystick]   # axes (mapping), signs (inversion), deadzone, gains, centre/low/high (calibrate), button_*
    [input]      # filter_hz: the tremor filter
    [blend]      # alpha: the assistance level, 0.2-0.8 in a profile
    [planner]    # switch_margin: a steadier arm (fewer changes of the assistance's mind on near ties)
    [move]       # approach_standoff_m: the approach corridor, for a person who closes at the grasp
    [speech]     # voice, rate_wpm, volume of the questions
    [asking]     # max_per_task, answer_sources, third_answer, withdraw_yes_s, withdraw_no_s, learn_answer_time
    [reward]     # question_time_s: how long this person's questions stop the arm (s), what the planner charges

Only these keys may appear; everything is validated as configuration is (an error names the file and
the key), and a profile never changes what is not listed. ``run --profile NAME|FILE`` applies one at
start; ``sa-daemon calibrate`` writes the ``[joystick]`` calibration of one.
"""

from __future__ import annotations

import json
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .config import Config, ConfigError, config_from_dict

#: The keys a profile may set, by section.
PROFILE_KEYS: dict[str, frozenset[str]] = {
    "joystick": frozenset({"axes", "signs", "deadzone", "gains", "centre", "low", "high", "button_mode",
                           "button_gripper", "button_yes", "button_no", "button_assist", "button_stop",
                           "button_other"}),
    "input": frozenset({"filter_hz"}),
    "blend": frozenset({"alpha", "yield_near_m", "yield_near_belief", "opposition_window_s", "opposition_share",
                        "churn_window_s", "churn_switches", "churn_counts"}),
    "planner": frozenset({"switch_margin"}),
    # The approach corridor suits a person who closes at the grasp, not one who closes early
    # (docs/results.md, "Session 48"): it is theirs to switch on.
    "move": frozenset({"approach_standoff_m"}),
    "speech": frozenset({"voice", "rate_wpm", "volume"}),
    "asking": frozenset({"max_per_task", "answer_sources", "third_answer", "withdraw_yes_s",
                          "withdraw_no_s", "learn_answer_time"}),
    # A question stops the arm until the person answers: a slow answerer's questions cost more, and the
    # planner should charge what they cost this person (the ``answer`` events' ``after_s``).
    "reward": frozenset({"question_time_s"}),
}
#: The assistance level a profile may choose (the paper's 0.5 in the middle): enough of the person's own
#: input always passes, and enough assistance to matter.
ALPHA_RANGE = (0.2, 0.8)


@dataclass(frozen=True)
class Profile:
    """A person's settings: ``overrides`` by section, from ``path``."""

    name: str
    summary: str = ""
    overrides: dict[str, dict[str, Any]] = field(default_factory=dict)
    path: str = ""

    def apply(self, cfg: Config) -> Config:
        """``cfg`` with this profile's keys (validated as configuration; ``ConfigError`` naming the key)."""
        data = cfg.model_dump(mode="json")
        for section, keys in self.overrides.items():
            data[section] = {**data[section], **keys}
        return config_from_dict(data, f"profile {self.path or self.name}")

    def keys(self) -> list[str]:
        """The dotted keys this profile sets, for the log and the ``profile`` event."""
        return sorted(f"{s}.{k}" for s, ks in self.overrides.items() for k in ks)


def resolve(name_or_file: str, directory: str) -> Path:
    """A profile file: ``name_or_file`` if it is a path to a file, else ``directory/NAME.toml``."""
    p = Path(name_or_file)
    if p.suffix == ".toml" or p.is_file():
        return p
    return Path(directory) / f"{name_or_file}.toml"


def parse_profile(data: dict[str, Any], source: str) -> Profile:
    """A profile from its TOML ``data``; ``ConfigError`` naming ``source`` and the key otherwise."""
    unknown = sorted(set(data) - {"name", "summary", *PROFILE_KEYS})
    if unknown:
        raise ConfigError(f"{source}: {unknown[0]}: unknown key (allowed: name, summary, {', '.join(PROFILE_KEYS)})")
    name = data.get("name")
    if not isinstance(name, str) or not name.strip():
        raise ConfigError(f"{source}: name: a profile needs a name")
    overrides: dict[str, dict[str, Any]] = {}
    for section, allowed in PROFILE_KEYS.items():
        table = data.get(section, {})
        if not isinstance(table, dict):
            raise ConfigError(f"{source}: {section}: must be a table")
        bad = sorted(set(table) - allowed)
        if bad:
            raise ConfigError(f"{source}: {section}.{bad[0]}: not a profile key (allowed: {', '.join(sorted(allowed))})")
        if table:
            overrides[section] = dict(table)
    alpha = overrides.get("blend", {}).get("alpha")
    lo, hi = ALPHA_RANGE
    if alpha is not None and (not isinstance(alpha, (int, float)) or not lo <= alpha <= hi):
        raise ConfigError(f"{source}: blend.alpha: must be between {lo} and {hi} in a profile, got {alpha!r}")
    profile = Profile(name.strip(), str(data.get("summary", "")), overrides, source)
    profile.apply(Config())  # every value checked now, against the defaults
    return profile


def load_profile(name_or_file: str, directory: str) -> Profile:
    """Read and check a profile (``ConfigError`` naming the file and the key on any problem)."""
    path = resolve(name_or_file, directory)
    try:
        data = tomllib.loads(path.read_text())
    except OSError as e:
        raise ConfigError(f"profile {name_or_file}: cannot read {path}: {e.strerror or e}") from None
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(f"{path}: not valid TOML: {e}") from None
    return parse_profile(data, str(path))


def profile_toml(profile: Profile) -> str:
    """A profile as TOML text (what ``calibrate`` writes), readable by :func:`load_profile`."""
    def value(v: Any) -> str:
        if isinstance(v, (list, tuple)):
            return "[" + ", ".join(value(x) for x in v) + "]"
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, str):
            return json.dumps(v)  # a JSON string is a TOML basic string
        return repr(float(v)) if isinstance(v, float) else str(v)

    lines = [f"name = {value(profile.name)}"]
    if profile.summary:
        lines.append(f"summary = {value(profile.summary)}")
    for section, keys in profile.overrides.items():
        lines += ["", f"[{section}]"] + [f"{k} = {value(v)}" for k, v in keys.items()]
    return "\n".join(lines) + "\n"
