"""Node parameters: one schema, read from rclpy's overrides (``--params-file`` and ``-p``), checked strictly.

Every node takes the run's parameters (:class:`swarm_ros.app.param_file.Settings`: shape,
robots, vision_radius, seed, max_ticks, wiggle_deg, world_radius) plus a few of its own.
A parameter the node does not know, or of the wrong type, is an error (rclpy would
silently ignore the first), reported in one line that names it.
"""

from __future__ import annotations

from dataclasses import fields
from typing import Any

from rclpy.node import Node
from rclpy.parameter import Parameter

from swarm_ros.app.param_file import NODE_PARAMETERS, ConfigError, Settings, check_node_values

_TYPE_NAMES = {bool: "a boolean", int: "an integer", float: "a number", str: "a string"}
_ROS_TYPES = {Parameter.Type.BOOL: bool, Parameter.Type.INTEGER: int, Parameter.Type.DOUBLE: float,
              Parameter.Type.STRING: str}
# Declared by rclpy itself on every node.
_RCLPY_OWN = {"use_sim_time", "start_type_description_service"}

RUN_PARAMETERS: dict[str, Any] = {f.name: getattr(Settings(), f.name) for f in fields(Settings)}


def make_node(kind: str) -> Node:
    """A node that takes every override as given, so :func:`read_parameters` can check them all."""
    return Node(kind, allow_undeclared_parameters=True,
                automatically_declare_parameters_from_overrides=True)


def read_parameters(node: Node, kind: str) -> tuple[Settings, dict[str, Any]]:
    """The run settings and the node's own parameters, defaults filled in.

    Raises:
        ConfigError: an unknown parameter, or one of the wrong type.
    """
    schema = {**RUN_PARAMETERS, **NODE_PARAMETERS[kind]}
    given = {}
    for pname in node.list_parameters([], 0).names:
        if pname in _RCLPY_OWN:
            continue
        if pname not in schema:
            raise ConfigError(f"node '{node.get_name()}': unknown parameter '{pname}' "
                              f"(known: {', '.join(sorted(schema))})")
        param = node.get_parameter(pname)
        given[pname] = _typed(node.get_name(), pname, param, type(schema[pname]))
    values = {**schema, **given}
    check_node_values(kind, {k: values[k] for k in NODE_PARAMETERS[kind]})
    run = Settings(**{k: values[k] for k in RUN_PARAMETERS})
    return run, {k: values[k] for k in NODE_PARAMETERS[kind]}


def _typed(node: str, pname: str, param: Parameter, want: type) -> Any:
    got = _ROS_TYPES.get(param.type_)
    value = param.value
    if got is want or (want is float and got is int):
        return want(value)
    shown = f"{value!r}" if got is not None else f"a value of type {param.type_.name.lower()}"
    raise ConfigError(f"node '{node}': parameter '{pname}' must be {_TYPE_NAMES[want]}, got {shown}")


def params_yaml(run: Settings, per_node: dict[str, dict[str, Any]]) -> str:
    """A parameter file in the ROS 2 form: the run under ``/**``, each node's own under ``/<node>``."""
    import yaml

    doc = {"/**": {"ros__parameters": {k: getattr(run, k) for k in RUN_PARAMETERS}}}
    for node, values in per_node.items():
        if values:
            doc[f"/{node}"] = {"ros__parameters": dict(values)}
    return yaml.safe_dump(doc, sort_keys=False)
