"""Run settings from YAML parameter files in the ROS 2 form, plus command-line overrides.

A parameter file maps node names to ``ros__parameters``, so the same file serves
``ros2 run swarm_ros <node> --ros-args --params-file FILE`` and
``swarm-ros simulate --params-file FILE``::

    /**:
      ros__parameters:
        shape: star
        robots: 0          # 0 = the shape's patch count
        vision_radius: 1.0

Sections are read in file order; a later section overrides an earlier one. A section
named after a node (``/world``, ``/robot_batch``, ``/monitor``) holds only that node's
own parameters (``swarm_ros.core.params.NODE_PARAMETERS``), checked like the run's: a run parameter there
is refused, since nodes that read different values would not run the same swarm. The command line
applies them where they mean something: ``/monitor`` (recording and output directory)
in ``simulate`` and ``run``, ``/world`` in ``run``; flags override them. ``run`` refuses
``/robot_batch`` values other than the defaults, since it assigns each of its processes
its strip itself, but takes ``region_cuts`` (where the strips start); ``simulate`` has no
graph, and checks and ignores ``/world`` and ``/robot_batch``.
"""

from __future__ import annotations

from collections.abc import Hashable
from pathlib import Path

import yaml

from swarm_ros.core.errors import ConfigError, InputError, ParameterError
from swarm_ros.core.inputs import YAML_LIMIT, read_bounded
from swarm_ros.core.params import NODE_PARAMETERS, RUN_PARAMETER, Settings


class _UniqueKeyLoader(yaml.SafeLoader):
    """YAML's safe loader, refusing a key given twice in one mapping (plain YAML keeps the last, silently)."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict:
        seen: set = set()
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=True)
            if not isinstance(key, Hashable):
                continue  # the base loader refuses it, with its own message
            if key in seen:
                raise yaml.constructor.ConstructorError(
                    None, None, f"the key {key!r} is given twice (line {key_node.start_mark.line + 1})"
                )
            seen.add(key)
        return super().construct_mapping(node, deep)


def read_yaml(path: Path, what: str, error: type[InputError]) -> object:
    """The YAML document in ``path`` (at most :data:`~swarm_ros.core.inputs.YAML_LIMIT` bytes), or ``error`` with
    one line naming the file (unreadable, too large, bad YAML, a key given twice)."""
    data = read_bounded(path, YAML_LIMIT, what, error)
    try:
        return yaml.load(data.decode("utf-8"), Loader=_UniqueKeyLoader)
    except (yaml.YAMLError, UnicodeDecodeError) as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        if isinstance(exc, yaml.constructor.ConstructorError) and "given twice" in str(exc.problem):
            first = exc.problem
        raise error(f"{path}: not valid YAML ({first})") from None


def load_params_file(path: str | Path, base: Settings | None = None) -> Settings:
    """The run settings of a ROS 2 style parameter file over ``base`` (defaults if None).

    Raises:
        ConfigError: unreadable file, bad YAML, wrong layout, unknown key or wrong type.
    """
    return read_params_file(path, base)[0]


def read_params_file(path: str | Path, base: Settings | None = None) -> tuple[Settings, dict[str, dict[str, object]]]:
    """The run settings of a parameter file over ``base``, and the node parameters its node sections set.

    The second item maps each node kind (``world``, ``robot_batch``, ``monitor``) to the
    parameters of its own that the file sets. Every value is checked by its declaration.

    Raises:
        ConfigError: unreadable file, bad YAML, wrong layout, unknown key, or a value its
            declaration (``swarm_ros.core.params``) refuses.
    """
    path = Path(path)
    data = read_yaml(path, "parameter file", ConfigError)
    if not isinstance(data, dict) or not data:
        raise ConfigError(f"{path}: expected '/node_name: ros__parameters: {{...}}' sections")
    values: dict[str, object] = {}
    nodes: dict[str, dict[str, object]] = {kind: {} for kind in NODE_PARAMETERS}
    for node, section in data.items():
        if (
            not isinstance(section, dict)
            or set(section) != {"ros__parameters"}
            or not isinstance(section["ros__parameters"], dict)
        ):
            raise ConfigError(f"{path}: section '{node}' must hold exactly one 'ros__parameters' mapping")
        kind = str(node).lstrip("/")
        own = {p.name: p for p in NODE_PARAMETERS.get(kind, ())}
        for key, value in section["ros__parameters"].items():
            param = RUN_PARAMETER.get(key) or own.get(key)
            if param is None:
                known = sorted({*RUN_PARAMETER, *own})
                raise ConfigError(f"{path}: unknown parameter '{key}' in '{node}' (known: {', '.join(known)})")
            if key in RUN_PARAMETER and own:
                raise ConfigError(
                    f"{path}: '{node}' sets the run parameter '{key}'; run parameters go in '/**', "
                    f"which every node reads, so that all nodes run the same swarm"
                )
            try:
                checked = param.check(value)
            except ParameterError as exc:
                raise ConfigError(f"{path}: {node}: {exc}" if own else f"{path}: {exc}") from None
            if key in RUN_PARAMETER:
                values[key] = checked
            else:
                nodes[kind][key] = checked
    return (base or Settings()).updated(**values), nodes


def record_every(nodes: dict[str, dict[str, object]]) -> int:
    """``record_every`` of a parameter file's node sections (:func:`read_params_file`): the /monitor section's, else
    the /world section's, else 0. ``swarm-ros run`` and the launch file give the world and the monitor this one."""
    monitor, world = nodes.get("monitor", {}), nodes.get("world", {})
    return int(monitor.get("record_every", world.get("record_every", 0)))  # type: ignore[call-overload]
