"""Node parameters: one schema, read from rclpy's overrides (``--params-file`` and ``-p``), checked strictly.

Every node takes the run's parameters (``swarm_ros.core.params.RUN_PARAMETERS``) plus its own
(``NODE_PARAMETERS``). A parameter the node does not know, or a value its declaration refuses,
is an error (rclpy would silently ignore the first), reported in one line that names it.
"""

from __future__ import annotations

from typing import Any

from rclpy.node import Node

from swarm_ros.core.errors import ConfigError, ParameterError
from swarm_ros.core.params import NODE_PARAMETERS, RUN_PARAMETERS, Settings

# Declared by rclpy itself on every node.
_RCLPY_OWN = {"use_sim_time", "start_type_description_service"}

def make_node(kind: str) -> Node:
    """A node that takes every override as given, so :func:`read_parameters` can check them all."""
    return Node(kind, allow_undeclared_parameters=True,
                automatically_declare_parameters_from_overrides=True)


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
            raise ConfigError(f"node '{node.get_name()}': unknown parameter '{pname}' "
                              f"(known: {', '.join(sorted(schema))})")
        value = node.get_parameter(pname).value  # None, a list, ...: the check names what it got
        try:
            values[pname] = schema[pname].check(value)
        except ParameterError as exc:
            raise ConfigError(f"node '{node.get_name()}': {exc}") from None
    run = Settings(**{p.name: values[p.name] for p in RUN_PARAMETERS})
    return run, {p.name: values[p.name] for p in NODE_PARAMETERS[kind]}


def params_yaml(run: Settings, per_node: dict[str, dict[str, Any]]) -> str:
    """A parameter file in the ROS 2 form: the run under ``/**``, each node's own under ``/<node>``."""
    import yaml

    doc = {"/**": {"ros__parameters": {p.name: getattr(run, p.name) for p in RUN_PARAMETERS}}}
    for node, values in per_node.items():
        if values:
            doc[f"/{node}"] = {"ros__parameters": dict(values)}
    return yaml.safe_dump(doc, sort_keys=False)
