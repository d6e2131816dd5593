"""The ``world_shard`` executable: the world node of the run's algorithm for the robot batches in its strips
(``swarm-ros run --world-shards S``), with its peers' topics under /swarm/shards (:mod:`swarm_ros.nodes.roles`).

    ros2 run swarm_ros world_shard --ros-args -r __node:=world_shard_0 -p shard:=0 -p shards:=2 -p batches:=4 \\
        --params-file config/swarm_ros.yaml
"""

from __future__ import annotations

from swarm_ros.nodes.roles import start
from swarm_ros.protocol.plan import WORLD_SHARD


def main(argv: list[str] | None = None) -> int:
    return start(WORLD_SHARD, argv)


if __name__ == "__main__":
    raise SystemExit(main())
