"""The graph's processes: which nodes a run starts, in which order, and what each is told beyond the run.

``swarm-ros run`` (``swarm_ros.app.launcher``) and ``launch/swarm.launch.py`` both start
exactly this graph: a monitor first (so that it reads from tick 0), ``processes`` robot
batches, then the world, which starts tick 0 once the batches cover every robot.
"""

from __future__ import annotations

MONITOR, ROBOT_BATCH, WORLD = "monitor", "robot_batch", "world"  #: the node executables (and kinds)


def batch_name(k: int) -> str:
    """The node name of robot batch ``k``."""
    return f"{ROBOT_BATCH}_{k}"


def graph_plan(processes: int) -> list[tuple[str, str, dict[str, int]]]:
    """The node processes, in start order: (node name, executable, its own parameters beyond the file's)."""
    return [(MONITOR, MONITOR, {}),
            *[(batch_name(k), ROBOT_BATCH, {"batch": k, "batches": processes}) for k in range(processes)],
            (WORLD, WORLD, {})]
