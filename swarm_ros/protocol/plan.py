"""The graph's processes and topics: which nodes a run starts, in which order, what each is told beyond the
run, and the topics they talk on (their types and QoS: ``swarm_ros.ros.graph``; docs/protocol.md).

``swarm-ros run`` (``swarm_ros.app.launcher``) and ``launch/swarm.launch.py`` both start
exactly this graph: a monitor first (so that it reads from tick 0), ``processes`` robot
batches, then the world, which starts tick 0 once the batches cover every robot.
"""

from __future__ import annotations

from swarm_ros.core.params import Param

MONITOR, ROBOT_BATCH, WORLD = "monitor", "robot_batch", "world"  #: the node executables (and kinds)
#: How many robot-batch processes a run starts (``swarm-ros run --processes``, the launch file's ``processes``).
PROCESSES = Param("processes", 2, "robot-batch processes K", low=1)


def batch_name(k: int) -> str:
    """The node name of robot batch ``k``."""
    return f"{ROBOT_BATCH}_{k}"


def graph_plan(processes: int, region_cuts: str = "") -> list[tuple[str, str, dict[str, int | str]]]:
    """The node processes, in start order: (node name, executable, its own parameters beyond the file's):
    batch k of ``processes`` hosts strip k, cut at ``region_cuts`` if given (``swarm_ros.core.regions``)."""
    cuts: dict[str, int | str] = {"region_cuts": region_cuts} if region_cuts else {}
    return [
        (MONITOR, MONITOR, {}),
        *[(batch_name(k), ROBOT_BATCH, {"batch": k, "batches": processes, **cuts}) for k in range(processes)],
        (WORLD, WORLD, {}),
    ]


# -- topics -----------------------------------------------------------------------
ROBOTS = "/swarm/robots"  # world -> all: rows of the robots that changed in the tick (PointCloud2)
#: world -> all: the decisions it applied in the tick (PointCloud2); under it, /swarm/decisions/<batch>:
#: one batch -> world: its robots' decisions (decisions_topic)
DECISIONS = "/swarm/decisions"
BATCHES = "/swarm/batches"  # robot batches -> world: the columns (strip) each batch hosts (Int64MultiArray)
#: /swarm/region/<batch>: world -> one batch, after each tick: the rows its strip and halo need (PointCloud2,
#: compact rows)
REGION = "/swarm/region"
SHAPE = "/swarm/shape"  # world: the shape mask (OccupancyGrid, latched)
OCCUPANCY = "/swarm/occupancy"  # world: localized robots on the shape (OccupancyGrid, latched)
STATUS = "/swarm/status"  # world: running / outcome (DiagnosticArray, latched)
METRICS = "/swarm/metrics"  # monitor: the tick's metrics (Int64MultiArray, labelled)
CLOCK = "/clock"  # world: simulation time, one tick = one second (rosgraph_msgs/Clock)
SNAPSHOT = "/swarm/snapshot"  # /swarm/snapshot/<batch>: world -> one batch: its region's rows at a tick (PointCloud2)
ALIVE = "/swarm/alive"  # /swarm/alive/<node>: each batch's and the monitor's liveliness (std_msgs/Empty, silent)
#: What the monitor reads, bag or no bag: its bag records these, its own METRICS, and SHAPE, OCCUPANCY and
#: CLOCK as it derives them from the rows (these types carry no tag: swarm_ros.ros.auth). The world starts
#: tick 0 once it has discovered the monitor's reader of each (so the bag misses none of their messages).
MONITOR_READS = (ROBOTS, DECISIONS, STATUS)


def alive_topic(node_name: str) -> str:
    return f"{ALIVE}/{node_name}"


def region_topic(node_name: str) -> str:
    return f"{REGION}/{node_name}"


def snapshot_topic(node_name: str) -> str:
    return f"{SNAPSHOT}/{node_name}"


def decisions_topic(node_name: str) -> str:
    """A batch's own decisions topic: the world takes a robot's decisions only from its batch's topic."""
    return f"{DECISIONS}/{node_name}"
