"""The ROS-free core of swarm_ros: world, shapes, parameters, metrics, and each
algorithm's package (the study's model: :mod:`swarm_ros.core.darr_niazi`; :mod:`swarm_ros.core.rubenstein`).

Nothing here imports rclpy, ROS message packages or rerun; the ROS 2 nodes and the
recorder convert to and from these types at their edges.

The names below load their module on first use (PEP 562), so a program that needs only
shapes and parameters (the ``swarm-ros run`` launcher) does not pay for numba.
"""

from __future__ import annotations

import importlib

_HOME = {
    "JoinOutcome": "darr_niazi.arbitration",
    "Simulation": "darr_niazi.engine",
    "ParameterError": "errors",
    "ShapeError": "errors",
    "SwarmError": "errors",
    "InputError": "errors",
    "ContractError": "errors",
    "METRIC_COLUMNS": "darr_niazi.metrics",
    "Outcome": "metrics",
    "TickMetrics": "darr_niazi.metrics",
    "RunParams": "params",
    "Decisions": "darr_niazi.rules",
    "decide": "darr_niazi.rules",
    "Shape": "shapes",
    "builtin_shapes": "shapes",
    "RobotState": "darr_niazi.state",
    "SwarmState": "darr_niazi.state",
    "World": "grid",
}
__all__ = sorted(_HOME)


def __getattr__(name: str) -> object:
    if name not in _HOME:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{_HOME[name]}", __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_HOME))
