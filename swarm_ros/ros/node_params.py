"""Node parameters: one schema, read from rclpy's overrides (``--params-file`` and ``-p``), checked strictly.

Every node takes the run's parameters (``swarm_ros.core.params.RUN_PARAMETERS``) plus its own
(``NODE_PARAMETERS``). A parameter the node does not know, or a value its declaration refuses,
is an error (rclpy would silently ignore the first), reported in one line that names it.
"""

from __future__ import annotations

import sys
from typing import Any

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, ParameterType
from rclpy.node import Node

from swarm_ros.core.errors import ConfigError, ParameterError
from swarm_ros.core.params import INT64_MAX, NODE_PARAMETERS, RUN_PARAMETERS, Param, Settings

# Declared by rclpy itself on every node.
_RCLPY_OWN = {"use_sim_time", "start_type_description_service"}


def make_node(kind: str) -> Node:
    """A node that takes every override as given, so :func:`read_parameters` can check them all."""
    return Node(kind, allow_undeclared_parameters=True, automatically_declare_parameters_from_overrides=True)


def read_parameters(node: Node, kind: str) -> tuple[Settings, dict[str, Any]]:
    """The run settings and the node's own parameters, defaults filled in.

    Raises:
        ConfigError: an unknown parameter, or a value its declaration refuses.
    """
    schema = {p.name: p for p in (*RUN_PARAMETERS, *NODE_PARAMETERS[kind])}
    values = {name: p.default for name, p in schema.items()}
    for pname in node.list_parameters([], 0).names:
        if pname in _RCLPY_OWN:
            continue
        if pname not in schema:
            raise ConfigError(
                f"node '{node.get_name()}': unknown parameter '{pname}' (known: {', '.join(sorted(schema))})"
            )
        value = node.get_parameter(pname).value  # None, a list, ...: the check names what it got
        try:
            values[pname] = schema[pname].check(value)
        except ParameterError as exc:
            raise ConfigError(f"node '{node.get_name()}': {exc}") from None
    run = Settings(**{p.name: values[p.name] for p in RUN_PARAMETERS})
    own = {p.name: values[p.name] for p in NODE_PARAMETERS[kind]}
    for name, p in schema.items():  # now each with its descriptor: what `ros2 param describe` shows
        if node.has_parameter(name):
            node.undeclare_parameter(name)
        node.declare_parameter(name, values[name], descriptor(p), ignore_override=True)
    return run, own


_TYPES = {
    bool: ParameterType.PARAMETER_BOOL,
    int: ParameterType.PARAMETER_INTEGER,
    float: ParameterType.PARAMETER_DOUBLE,
    str: ParameterType.PARAMETER_STRING,
}


def descriptor(p: Param) -> ParameterDescriptor:
    """``p``'s declaration as ROS 2 describes a parameter: its meaning, type, the values it takes in words
    (``additional_constraints``) and, for a number with bounds, its range. Read-only: a run's parameters are
    fixed when its nodes start, so ``ros2 param set`` is refused rather than ignored.

    ROS ranges are closed, so a bound a value may not equal (``> 0``) is in the words only; a number whose
    blank value (0) means something of its own (``robots``: the shape's patch count) has no range.
    """
    d = ParameterDescriptor(
        name=p.name, type=_TYPES[p.kind], description=p.help, additional_constraints=p.describe(), read_only=True
    )
    if p.kind in (int, float) and not p.blank and (p.low is not None or p.high is not None):
        if p.kind is int:
            d.integer_range = [
                IntegerRange(
                    from_value=int(p.low) if p.low is not None else -INT64_MAX - 1,
                    to_value=int(p.high) if p.high is not None else INT64_MAX,
                    step=0,
                )
            ]
        else:
            top = sys.float_info.max
            d.floating_point_range = [
                FloatingPointRange(
                    from_value=float(p.low) if p.low is not None else -top,
                    to_value=float(p.high) if p.high is not None else top,
                    step=0.0,
                )
            ]
    return d
