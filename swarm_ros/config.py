"""Run settings from YAML parameter files in the ROS 2 form, plus command-line overrides.

A parameter file maps node names to ``ros__parameters``, so the same file serves
``ros2 run swarm_ros <node> --ros-args --params-file FILE`` and
``swarm-ros simulate --params-file FILE``::

    /**:
      ros__parameters:
        shape: star
        robots: 0          # 0 = the shape's patch count
        vision_radius: 1.0

Sections are read in file order; a later section overrides an earlier one.
"""

from __future__ import annotations

import numbers
from dataclasses import dataclass, fields, replace
from pathlib import Path

import yaml

from .core.errors import SwarmError
from .core.params import DEFAULT_MAX_TICKS, DEFAULT_SEED, DEFAULT_VISION, DEFAULT_WIGGLE_DEG
from .core.world import DEFAULT_RADIUS


class ConfigError(SwarmError):
    """A parameter file is unreadable or holds an unknown or ill-typed key; the message names both."""


@dataclass(frozen=True)
class Settings:
    """What a run needs before the shape is loaded. ``robots = 0`` means the shape's patch count."""

    shape: str = "star"
    robots: int = 0
    vision_radius: float = DEFAULT_VISION
    seed: int = DEFAULT_SEED
    max_ticks: int = DEFAULT_MAX_TICKS
    wiggle_deg: float = DEFAULT_WIGGLE_DEG
    world_radius: int = DEFAULT_RADIUS

    def updated(self, **values: object) -> Settings:
        """A copy with the given non-None values."""
        return replace(self, **{k: v for k, v in values.items() if v is not None})


_TYPES = {f.name: f.type for f in fields(Settings)}


def _check_type(path: Path, key: str, value: object) -> object:
    want = _TYPES[key]
    if want == "str":
        ok = isinstance(value, str)
    elif want == "int":
        ok = isinstance(value, numbers.Integral) and not isinstance(value, bool)
    else:
        ok = isinstance(value, numbers.Real) and not isinstance(value, bool)
        value = float(value) if ok else value
    if not ok:
        raise ConfigError(f"{path}: parameter '{key}' must be {'a' if want != 'int' else 'an'} "
                          f"{ {'str': 'string', 'int': 'integer', 'float': 'number'}[want]}, got {value!r}")
    return value


def load_params_file(path: str | Path, base: Settings | None = None) -> Settings:
    """Read a ROS 2 style parameter file over ``base`` (defaults if None).

    Raises:
        ConfigError: unreadable file, bad YAML, wrong layout, unknown key or wrong type.
    """
    path = Path(path)
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read parameter file ({exc.strerror or exc})") from None
    except (yaml.YAMLError, UnicodeDecodeError) as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise ConfigError(f"{path}: not valid YAML ({first})") from None
    if not isinstance(data, dict) or not data:
        raise ConfigError(f"{path}: expected '/node_name: ros__parameters: {{...}}' sections")
    values: dict[str, object] = {}
    for node, section in data.items():
        if not isinstance(section, dict) or set(section) != {"ros__parameters"} \
                or not isinstance(section["ros__parameters"], dict):
            raise ConfigError(f"{path}: section '{node}' must hold exactly one 'ros__parameters' mapping")
        for key, value in section["ros__parameters"].items():
            if key not in _TYPES:
                raise ConfigError(f"{path}: unknown parameter '{key}' in '{node}' "
                                  f"(known: {', '.join(sorted(_TYPES))})")
            values[key] = _check_type(path, key, value)
    return (base or Settings()).updated(**values)
