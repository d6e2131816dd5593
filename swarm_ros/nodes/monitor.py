"""The ``monitor`` executable: the monitor node of the run's algorithm (:mod:`swarm_ros.nodes.roles`).

ros2 run swarm_ros monitor --ros-args --params-file config/swarm_ros.yaml
"""

from __future__ import annotations

from swarm_ros.nodes.roles import start
from swarm_ros.protocol.plan import MONITOR


def main(argv: list[str] | None = None) -> int:
    return start(MONITOR, argv)


if __name__ == "__main__":
    raise SystemExit(main())
