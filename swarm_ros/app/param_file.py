"""Run settings from YAML parameter files in the ROS 2 form, plus command-line overrides.

A parameter file maps node names to ``ros__parameters``, so the same file serves
``ros2 run swarm_ros <node> --ros-args --params-file FILE`` and
``swarm-ros simulate --params-file FILE``::

    /**:
      ros__parameters:
        shape: star
        robots: 0          # 0 = the shape's patch count
        vision_radius: 1.0

Sections are read in file order; a later section overrides an earlier one. A file may hold ``/**`` (the run
parameters, which every node reads) and a section per node kind, ``/world``, ``/robot_batch`` and ``/monitor``,
each holding only that node's own parameters (``swarm_ros.core.params.NODE_PARAMETERS``), checked like the
run's. Anything else is refused in one line: a section no node reads (``/foo``, ``/robot_batch_0``) would be
ignored or, worse, taken for ``/**``, and a run parameter in a node section would let nodes run different swarms.
The command line applies node sections where they mean something: ``/monitor`` (recording and output directory)
in ``simulate`` and ``run``, ``/world`` in ``run`` (every world shard takes it under ``--world-shards``), and
``/robot_batch``'s ``region_cuts``; flags override them. What ``run`` and the launch file set for each process
themselves (:data:`LAUNCHER_SETS`: a batch's strip, a shard count, incarnations, checkpoints) may be given only
at its default. ``simulate`` has no graph, and checks and ignores ``/world`` and ``/robot_batch``.
"""

from __future__ import annotations

from collections.abc import Hashable
from pathlib import Path
from typing import Any

import yaml

from swarm_ros.core.errors import ConfigError, InputError, ParameterError
from swarm_ros.core.inputs import YAML_LIMIT, read_bounded
from swarm_ros.core.params import NODE_PARAMETERS, RUN_PARAMETER, RUN_PARAMETERS, Settings, node_defaults


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
        kind = _section_kind(path, node)
        own = {p.name: p for p in NODE_PARAMETERS.get(kind, ())}
        for key, value in section["ros__parameters"].items():
            if kind == ALL:
                param = RUN_PARAMETER.get(key)
                if param is None:
                    raise ConfigError(f"{path}: unknown parameter '{key}' in '{node}'{_whose(key)}")
            elif key in RUN_PARAMETER:
                raise ConfigError(
                    f"{path}: '{node}' sets the run parameter '{key}'; run parameters go in '/**', "
                    f"which every node reads, so that all nodes run the same swarm"
                )
            elif key not in own:
                raise ConfigError(f"{path}: unknown parameter '{key}' in '{node}' (it may hold: {', '.join(own)})")
            else:
                param = own[key]
            try:
                checked = param.check(value)
            except ParameterError as exc:
                raise ConfigError(f"{path}: {node}: {exc}" if own else f"{path}: {exc}") from None
            if kind == ALL:
                values[key] = checked
            else:
                nodes[kind][key] = checked
    return (base or Settings()).updated(**values), nodes


ALL = "**"  #: the section every node reads: the run parameters
#: The node sections a parameter file may hold besides ``/**``, one per node kind. A world shard takes the
#: ``/world`` section; the launcher sets the parameters that tell shards and batches apart.
SECTIONS = ("world", "robot_batch", "monitor")
#: Node parameters ``swarm-ros run`` and the launch file set for each process themselves: a file may give only
#: their defaults (:func:`check_launcher_sets`).
LAUNCHER_SETS = {
    "world": ("checkpoint", "incarnation"),
    "robot_batch": ("batch", "batches", "incarnation"),
    "monitor": ("incarnation", "world_shards"),
}
_FLAG_FOR = {"world_shards": "--world-shards (the launch file: world_shards:=S)", "batches": "--processes"}


def _section_kind(path: Path, node: object) -> str:
    """The kind of section ``node`` (``/**`` or ``**``, ``/world`` or ``world``, ...), or ConfigError naming the
    sections a file may hold: a section no node reads would be silently ignored, or worse, taken as ``/**``."""
    kind = str(node).lstrip("/") if isinstance(node, str) else ""
    if kind == ALL or kind in SECTIONS:
        return kind
    hint = ""
    if kind.startswith(("world_shard", "robot_batch_")):
        hint = (
            "; swarm-ros sets what tells its processes apart, and every world shard takes '/world'"
            if kind.startswith("world_shard")
            else "; swarm-ros gives every robot batch the '/robot_batch' section"
        )
    known = ", ".join(f"'/{s}'" for s in (ALL, *SECTIONS))
    raise ConfigError(f"{path}: unknown section '{node}' (a parameter file may hold {known}){hint}")


def _whose(key: str) -> str:
    """Where node parameter ``key`` goes, as the end of an 'unknown parameter' error, or the run parameters."""
    owners = [kind for kind in SECTIONS if any(p.name == key for p in NODE_PARAMETERS[kind])]
    if owners:
        return f": it is a node parameter, for {' or '.join(f'/{k}' for k in owners)}"
    return f" (run parameters: {', '.join(RUN_PARAMETER)})"


def check_launcher_sets(path: object, nodes: dict[str, dict[str, object]]) -> None:
    """Refuse a node section's value for a parameter the launcher sets for each process itself (other than its
    default), which it would otherwise silently replace.

    Raises:
        InputError: one line naming the section, the parameter and what sets it instead.
    """
    for kind, names in LAUNCHER_SETS.items():
        defaults = node_defaults(kind)
        for name in names:
            if name in nodes.get(kind, {}) and nodes[kind][name] != defaults[name]:
                instead = _FLAG_FOR.get(name, "the launcher, for each process")
                raise InputError(
                    f"{path}: /{kind} sets {name}, which swarm-ros run and the launch file set themselves "
                    f"({instead}); use ros2 run to start nodes of your own"
                )


def record_every(nodes: dict[str, dict[str, object]]) -> int:
    """``record_every`` of a parameter file's node sections (:func:`read_params_file`): the /monitor section's, else
    the /world section's, else 0. ``swarm-ros run`` and the launch file give the world and the monitor this one."""
    monitor, world = nodes.get("monitor", {}), nodes.get("world", {})
    return int(monitor.get("record_every", world.get("record_every", 0)))  # type: ignore[call-overload]


def params_yaml(run: Settings, per_node: dict[str, dict[str, Any]]) -> str:
    """A parameter file in the ROS 2 form: the run under ``/**``, each node's own under ``/<node>``."""
    doc = {"/**": {"ros__parameters": {p.name: getattr(run, p.name) for p in RUN_PARAMETERS}}}
    for node, values in per_node.items():
        if values:
            doc[f"/{node}"] = {"ros__parameters": dict(values)}
    return yaml.safe_dump(doc, sort_keys=False)


def check_given(given: dict[str, object], algorithm: str, where: str = "") -> None:
    """Refuse a run parameter of the other algorithm that was given (a flag, a launch argument), even at its default
    value: it would do nothing. (A parameter file may hold the other algorithm's at their defaults, so that one file
    holds them all; RunParams refuses another value.)

    Raises:
        ParameterError: the first such parameter, ``where`` (if any) before it.
    """
    for name, value in given.items():
        p = RUN_PARAMETER[name]
        if value is not None and p.algorithm not in ("", algorithm):
            said = f"{where}: " if where else ""
            raise ParameterError(
                f"{said}{name} is a parameter of the {p.algorithm} algorithm, not of {algorithm}, got {value!r}"
            )
