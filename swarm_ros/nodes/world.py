"""The ``world`` executable: the world node of the run's algorithm (:mod:`swarm_ros.nodes.roles`).

ros2 run swarm_ros world --ros-args --params-file config/swarm_ros.yaml
"""

from __future__ import annotations

from swarm_ros.nodes.roles import start
from swarm_ros.protocol.plan import WORLD


def main(argv: list[str] | None = None) -> int:
    return start(WORLD, argv)


if __name__ == "__main__":
    raise SystemExit(main())
