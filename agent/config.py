"""Typed agent configuration: defaults in the dataclasses, a TOML file on top,
command-line flags on top of that. Unknown keys are refused by name."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any

from agent.controller import Gains, RobotLimits
from agent.patrol import PatrolConfig

SECTIONS: dict[str, type] = {"gains": Gains, "patrol": PatrolConfig, "limits": RobotLimits}


class ConfigError(ValueError):
    pass


def _build(cls: type, values: dict[str, Any], where: str) -> Any:
    names = {f.name: f for f in dataclasses.fields(cls)}
    unknown = set(values) - set(names)
    if unknown:
        raise ConfigError(f"{where}: unknown key(s) {', '.join(sorted(unknown))}; "
                          f"known: {', '.join(sorted(names))}")
    typed = {}
    for key, value in values.items():
        kind = type(names[key].default)
        if kind is float and isinstance(value, int) and not isinstance(value, bool):
            value = float(value)
        if not isinstance(value, kind) or isinstance(value, bool) != (kind is bool):
            raise ConfigError(f"{where}.{key}: expected {kind.__name__}, got {value!r}")
        if isinstance(value, float) and not math.isfinite(value):
            raise ConfigError(f"{where}.{key}: expected a finite number, got {value!r}")
        typed[key] = value
    try:
        return cls(**typed)
    except ValueError as exc:
        raise ConfigError(f"{where}: {exc}") from None


def load(path: str | Path | None, overrides: dict[str, dict[str, Any]] | None = None
         ) -> tuple[Gains, PatrolConfig, RobotLimits]:
    """Read ``[gains]``, ``[patrol]`` and ``[limits]`` from a TOML file (optional) and
    apply ``overrides`` (section -> key -> value) from the command line."""
    data: dict[str, Any] = {}
    if path is not None:
        import tomllib  # only with a file: an agent started without one never needs it

        try:
            data = tomllib.loads(Path(path).read_text())
        except FileNotFoundError:
            raise ConfigError(f"{path}: no such file") from None
        except tomllib.TOMLDecodeError as exc:
            raise ConfigError(f"{path}: {exc}") from None
    unknown = set(data) - set(SECTIONS)
    if unknown:
        raise ConfigError(f"{path}: unknown section(s) {', '.join(sorted(unknown))}")
    built = []
    for name, cls in SECTIONS.items():
        values = dict(data.get(name, {}))
        values.update({k: v for k, v in (overrides or {}).get(name, {}).items() if v is not None})
        built.append(_build(cls, values, f"{path or 'config'}[{name}]"))
    return built[0], built[1], built[2]
