"""Simulated users as data: a profile is a TOML file that overrides ``[sim_user]`` (``docs/simulated-user.md``).

    name = "hasty"
    summary = "closes the gripper before it is at the grasp"
    [sim_user]                # any key of [sim_user]; the rest stay the configuration's (the calibrated user)
    close_translation_max_m = 0.035
    [sources]                 # one entry per key of [sim_user]: the reason for its value, with its source
    close_translation_max_m = "section VI-D: 17 of 47 failures ..."

Unknown keys are refused with the file and key named, and a ``[sim_user]`` key without a ``[sources]``
entry is refused too: every value says what it stands on. Built-in profiles live in ``sa_daemon/users/``;
``eval --user NAME|FILE`` and ``run --input sim --user NAME|FILE`` take either.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from ..config import Config, ConfigError, SimUserConfig

CALIBRATED = "calibrated"
_TOP_KEYS = {"name", "summary", "sim_user", "sources"}


@dataclass(frozen=True)
class UserProfile:
    """A named simulated user: ``overrides`` of ``[sim_user]`` and the reason for each (``sources``)."""

    name: str
    summary: str
    overrides: dict[str, Any] = field(default_factory=dict)
    sources: dict[str, str] = field(default_factory=dict)
    path: str = ""

    def apply(self, cfg: Config) -> Config:
        """``cfg`` with this user's ``[sim_user]`` (validated again: an override that clashes with the
        configuration, e.g. a closing tolerance below ``close_translation_m``, is a ConfigError)."""
        if not self.overrides:
            return cfg
        merged = {**cfg.sim_user.model_dump(), **self.overrides}
        try:
            sim_user = SimUserConfig.model_validate(merged)
        except ValidationError as e:
            raise ConfigError(_errors(e, self.path or self.name)) from None
        return cfg.model_copy(update={"sim_user": sim_user})


def _errors(err: ValidationError, source: str) -> str:
    out = []
    for e in err.errors():
        key = ".".join(["sim_user", *(str(p) for p in e["loc"])])
        msg = "unknown key" if e["type"] == "extra_forbidden" else e["msg"].removeprefix("Value error, ")
        out.append(f"{source}: {key}: {msg}")
    return "\n".join(out)


def _builtin_dir() -> Any:
    return resources.files("sa_daemon").joinpath("users")


def builtin_user_names() -> list[str]:
    """Names of the profiles shipped in ``sa_daemon/users`` (``calibrated`` first)."""
    names = sorted(p.name.removesuffix(".toml") for p in _builtin_dir().iterdir() if p.name.endswith(".toml"))
    return sorted(names, key=lambda n: (n != CALIBRATED, n))


def user_from_dict(data: Any, source: str) -> UserProfile:
    """A profile from parsed TOML; :class:`ConfigError` naming ``source`` and the key on any problem."""
    if not isinstance(data, dict):
        raise ConfigError(f"{source}: a user profile is a TOML table")
    for k in data:
        if k not in _TOP_KEYS:
            raise ConfigError(f"{source}: {k}: unknown key (a profile has {', '.join(sorted(_TOP_KEYS))})")
    name, summary = data.get("name"), data.get("summary", "")
    if not isinstance(name, str) or not name.strip():
        raise ConfigError(f"{source}: name: a profile needs a name")
    if not isinstance(summary, str):
        raise ConfigError(f"{source}: summary: must be a string")
    overrides, sources = data.get("sim_user", {}), data.get("sources", {})
    for key, table in (("sim_user", overrides), ("sources", sources)):
        if not isinstance(table, dict):
            raise ConfigError(f"{source}: {key}: must be a table")
    try:
        SimUserConfig.model_validate({**SimUserConfig().model_dump(), **overrides})
    except ValidationError as e:
        raise ConfigError(_errors(e, source)) from None
    for k in overrides:
        if not isinstance(sources.get(k), str) or not sources[k].strip():
            raise ConfigError(f"{source}: sources.{k}: every [sim_user] value needs its reason in [sources]")
    for k in sources:
        if k not in overrides:
            raise ConfigError(f"{source}: sources.{k}: no such key in this profile's [sim_user]")
    return UserProfile(name.strip(), summary.strip(), dict(overrides), dict(sources), source)


def load_user(name_or_path: str | Path) -> UserProfile:
    """A built-in profile by name (``confident``) or a profile file; :class:`ConfigError` if neither."""
    text = str(name_or_path)
    path = Path(text)
    if text in builtin_user_names():
        res = _builtin_dir().joinpath(f"{text}.toml")
        raw, source = res.read_text(), f"sa_daemon/users/{text}.toml"
    elif path.suffix == ".toml" or path.exists():
        try:
            raw, source = path.read_text(), str(path)
        except OSError as e:
            raise ConfigError(f"--user {text}: cannot read: {e.strerror or e}") from None
    else:
        raise ConfigError(f"--user {text}: no such profile (built-in: {', '.join(builtin_user_names())}) or file")
    try:
        data = tomllib.loads(raw)
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(f"{source}: not valid TOML: {e}") from None
    return user_from_dict(data, source)
