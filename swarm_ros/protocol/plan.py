"""The graph's processes and topics: which nodes a run starts, in which order, what each is told beyond the
run, and the topics they talk on (their types and QoS: ``swarm_ros.ros.graph``; docs/protocol.md).

``swarm-ros run`` (``swarm_ros.app.launcher``) and ``launch/swarm.launch.py`` both start
exactly this graph: a monitor first (so that it reads from tick 0), ``processes`` robot
batches, then the world, which starts tick 0 once the batches cover every robot.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from swarm_ros.core.algorithm import algorithm_of
from swarm_ros.core.params import Param

#: the node executables (and kinds), one set for every algorithm: each runs its algorithm's node (nodes/roles.py)
MONITOR, ROBOT_BATCH, WORLD = "monitor", "robot_batch", "world"
WORLD_SHARD = "world_shard"  #: the executable (and kind) of a world shard, which stands in for the world
#: How many robot-batch processes a run starts (``swarm-ros run --processes``, the launch file's ``processes``).
PROCESSES = Param("processes", 2, "robot-batch processes K", low=1)


_SHARD = re.compile(r"world_shard_(0|[1-9][0-9]{0,5})")
_SHARD_TOPIC = re.compile(r"/swarm/shards/shard_(0|[1-9][0-9]{0,5})/")


def shard_name(i: int) -> str:
    """The node name of world shard ``i``."""
    return f"{WORLD_SHARD}_{i}"


def is_world(sender: str) -> bool:
    """Whether node ``sender`` speaks for the world: the world node, or a world shard."""
    return sender == WORLD or _SHARD.fullmatch(sender) is not None


def batch_name(k: int) -> str:
    """The node name of robot batch ``k``."""
    return f"{ROBOT_BATCH}_{k}"


def graph_plan(
    processes: int, region_cuts: str = "", world_shards: int = 1
) -> list[tuple[str, str, dict[str, int | str]]]:
    """The node processes, in start order: (node name, executable, its own parameters beyond the file's):
    batch k of ``processes`` hosts strip k, cut at ``region_cuts`` if given (``swarm_ros.core.strips``); then
    the world, or ``world_shards`` > 1 world shards, shard i owning the strips of a run of consecutive batches
    (:func:`swarm_ros.core.strips.shard_batches`)."""
    cuts: dict[str, int | str] = {"region_cuts": region_cuts} if region_cuts else {}
    monitor: dict[str, int | str] = {"world_shards": world_shards} if world_shards > 1 else {}
    world: list[tuple[str, str, dict[str, int | str]]] = (
        [(WORLD, WORLD, {})]
        if world_shards == 1
        else [
            (shard_name(i), WORLD_SHARD, {"shard": i, "shards": world_shards, "batches": processes, **cuts})
            for i in range(world_shards)
        ]
    )
    return [
        (MONITOR, MONITOR, monitor),
        *[(batch_name(k), ROBOT_BATCH, {"batch": k, "batches": processes, **cuts}) for k in range(processes)],
        *world,
    ]


def plan_for(
    algorithm: str, processes: int, region_cuts: str = "", world_shards: int = 1
) -> list[tuple[str, str, dict[str, int | str]]]:
    """The node processes of a run of ``algorithm`` (``swarm-ros run`` and the launch file start the same): its
    plan (core.algorithm)."""
    return algorithm_of(algorithm).hook("plan")(processes, region_cuts, world_shards)


# -- topics -----------------------------------------------------------------------
BATCHES = "/swarm/batches"  # robot batches -> world: the columns (strip) each batch hosts (Int64MultiArray)
SHAPE = "/swarm/shape"  # world: the shape mask (OccupancyGrid, latched)
OCCUPANCY = "/swarm/occupancy"  # world: localized robots on the shape (OccupancyGrid, latched)
STATUS = "/swarm/status"  # world: running / outcome (DiagnosticArray, latched)
#: monitor -> every world process, every algorithm's run: ``[tick, ended]`` (Int64MultiArray, latched), the last
#: tick whose record its bag holds durably, and 1 once it holds the run's outcome too. A world runs at most
#: ``monitor_window`` ticks (or records) past it: the run's one backpressure.
HELD = "/swarm/held"
CLOCK = "/clock"  # world: simulation time, one tick = one second (rosgraph_msgs/Clock)
ALIVE = "/swarm/alive"  # /swarm/alive/<node>: each batch's and the monitor's liveliness (std_msgs/Empty, silent)


#: A central world's run talks under /swarm/<algorithm> (the name's hyphens as underscores; PointCloud2, the
#: algorithm's rows: swarm_ros.protocol.central_world): ``robots``: world -> monitor and viewers, every robot's row at
#: tick 0, every ``record_every``-th tick and the last; ``metrics``: world -> monitor, the metrics rows of the ticks
#: since the last message, as often; ``area/<batch>``: world -> one batch, after each tick, its area's rows;
#: ``decisions/<batch>``: one batch -> world, its strip's decisions. (The monitor's report back is ``HELD``.)
#: The robots and metrics messages the world keeps for a late reader (a restarted monitor): one each per record,
#: so the world runs at most ``CENTRAL_KEPT - 2`` records past the monitor's last held one
#: (swarm_ros.protocol.central_world.monitor_reach).
CENTRAL_KEPT = 32
_CENTRAL = re.compile(r"/swarm/([a-z][a-z0-9_]*)/decisions/(.+)")


@dataclass(frozen=True)
class CentralTopics:
    """The topics of a central world's run of one algorithm (above)."""

    root: str

    @staticmethod
    def of(algorithm: str) -> CentralTopics:
        return CentralTopics(f"/swarm/{algorithm.replace('-', '_')}")

    @property
    def robots(self) -> str:
        return f"{self.root}/robots"

    @property
    def metrics(self) -> str:
        return f"{self.root}/metrics"

    def area(self, node_name: str) -> str:
        return f"{self.root}/area/{node_name}"

    def changes(self, node_name: str) -> str:
        return f"{self.root}/changes/{node_name}"

    def decisions(self, node_name: str) -> str:
        return f"{self.root}/decisions/{node_name}"


def central_sender(topic: str) -> str | None:
    """Who alone sends on ``topic`` if it is a central world's run's batch's (``decisions/<batch>``: that batch), else
    None."""
    got = _CENTRAL.fullmatch(topic)
    return None if got is None else got.group(2)


#: /swarm/shards/shard_<i>/...: world shard i -> its peers, each tick: ``claims_to_<j>`` and ``part_to_<j>``
#: (PointCloud2, to shard j), ``counts`` (Int64MultiArray, to every peer) and ``again`` (Int64MultiArray: a peer,
#: asked to send its kept messages again); only shard i publishes under /swarm/shards/shard_<i>
SHARDS = "/swarm/shards"


def counts_topic(i: int) -> str:
    return f"{SHARDS}/shard_{i}/counts"


def shard_topic(i: int, what: str) -> str:
    """A central world's shard i's topic ``what``: ``border_to_<j>`` (its decisions in shard j's halo), ``shared``
    (the rows every shard shares; its counts on :func:`counts_topic`), ``rows_to_<j>`` (its robots in j's reach)."""
    return f"{SHARDS}/shard_{i}/{what}"


def shard_of_topic(topic: str) -> int | None:
    """The shard that publishes on ``topic`` (one under /swarm/shards/<i>), or None."""
    m = _SHARD_TOPIC.match(topic)
    return int(m[1]) if m else None


def alive_topic(node_name: str) -> str:
    return f"{ALIVE}/{node_name}"
