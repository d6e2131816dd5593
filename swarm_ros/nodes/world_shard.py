"""A world shard node (``swarm-ros run --world-shards S``): the world node (:mod:`swarm_ros.nodes.world`) for the
robot batches in its strips, with its peers' topics under /swarm/shards.

    ros2 run swarm_ros world_shard --ros-args -r __node:=world_shard_0 -p shard:=0 -p shards:=2 -p batches:=4 \\
        --params-file config/swarm_ros.yaml
"""

from __future__ import annotations

import functools

from swarm_ros.nodes.world import WorldNode
from swarm_ros.protocol.plan import WORLD_SHARD
from swarm_ros.ros.runtime import run_node


def main(argv: list[str] | None = None) -> int:
    return run_node(WORLD_SHARD, functools.partial(WorldNode, WORLD_SHARD), argv)


if __name__ == "__main__":
    raise SystemExit(main())
