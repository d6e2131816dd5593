"""The node executables' one door: ``world``, ``world_shard``, ``robot_batch`` and ``monitor`` each start the node
of their role that the run's algorithm supplies (its registry entry's ``<role>_node``), picked by the ``algorithm``
parameter, as crazyswarm2's server picks its backend. The executable makes the rclpy node and reads its parameters
(one schema per role, whatever the algorithm); the algorithm's class builds the rest on them.
"""

from __future__ import annotations

import functools

from swarm_ros.core.algorithm import node_of
from swarm_ros.ros.node_params import make_node, read_parameters
from swarm_ros.ros.runtime import SwarmNode, run_node


def start(role: str, argv: list[str] | None = None) -> int:
    """Run the node of ``role`` for the run its parameters describe (:func:`swarm_ros.ros.runtime.run_node`)."""
    return run_node(role, functools.partial(build, role), argv)


def build(role: str) -> SwarmNode:
    """The node of ``role``: an rclpy node named for it, its parameters read, handed to the algorithm's class.

    Raises:
        ConfigError: a parameter it does not know, or a value its declaration refuses.
        ParameterError: the algorithm's graph has no node of this role.
    """
    node = make_node(role)
    run, own = read_parameters(node, role)
    return node_of(run.algorithm, role)(node, run, own)
