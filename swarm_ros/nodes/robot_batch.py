"""The ``robot_batch`` executable: the robot_batch node of the run's algorithm (:mod:`swarm_ros.nodes.roles`).

ros2 run swarm_ros robot_batch --ros-args --params-file config/swarm_ros.yaml
"""

from __future__ import annotations

from swarm_ros.nodes.roles import start
from swarm_ros.protocol.plan import ROBOT_BATCH


def main(argv: list[str] | None = None) -> int:
    return start(ROBOT_BATCH, argv)


if __name__ == "__main__":
    raise SystemExit(main())
