"""What several test modules share: small shapes, checked runs, recordings read back, network namespaces,
and the package's import graph. (Fixtures are in conftest.py; modules import these by name.)"""

from __future__ import annotations

import json
import os
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest

from swarm_ros.core import RunParams, Shape, Simulation, World
from swarm_ros.core.invariants import check_state, check_tick

# Robot counts that complete each built-in shape in the original study (docs/model.md, "Shapes").
STUDY_PATCHES = {"star": 1036, "wrench": 566, "k-letter": 1352, "rectangle": 438, "tyre": 1282, "spinner": 1040}


def disc_shape(world: World, radius: float, name: str = "disc", hole: float = 0.0) -> Shape:
    """A disc (or ring, with ``hole`` > 0) centred on the origin."""
    r = world.radius
    c = np.arange(-r, r + 1)
    x, y = np.meshgrid(c, c)
    d = np.hypot(x, y)
    return Shape(name=name, mask=(d <= radius) & (d >= hole), world=world, source=f"test {name}")


def run_checked(sim: Simulation) -> Simulation:
    """Run ``sim`` to its end, checking every Z-spec invariant after every tick."""
    check_state(sim)
    while not sim.done:
        prev = sim.state.copy()
        sim.step()
        check_tick(prev, sim)
    return sim


def params(robots: int, **kw) -> RunParams:
    return RunParams(robots=robots, **kw)


class Recording:
    """What an .rrd file holds, read back with rerun's own reader (not with swarm_ros code).

    Attributes:
        series: metric name -> {tick: value} (entities ``metrics/<name>``).
        robots: tick -> (positions (n, 2) float32, class ids (n,)) of ``world/robots`` ((n, 3) in 3D).
        occupancy: tick -> flat uint8 class image of ``world/occupancy`` (3D: the filled voxels' centres, flat).
        events: (tick, text) of ``events``, in tick order.
        static: entity paths that hold static data.
        blueprints: how many blueprints the file holds.
    """

    def __init__(self, path) -> None:
        import warnings

        from rerun.chunk import RrdReader

        self.series: dict[str, dict[int, float]] = {}
        self.robots: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self.occupancy: dict[int, np.ndarray] = {}
        self.events: list[tuple[int, str]] = []
        self.static: set[str] = set()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # a file without footer (killed writer) warns, and reads
            reader = RrdReader(str(path))
            self.blueprints = len(reader.blueprints())
            chunks = reader.stream().to_chunks()
        for chunk in chunks:
            entity, batch = chunk.entity_path, chunk.to_record_batch()
            if chunk.is_static:
                self.static.add(entity)
                continue
            names = batch.schema.names
            ticks = batch.column("tick").to_numpy().tolist()
            if "Scalars:scalars" in names:
                values = batch.column("Scalars:scalars").flatten().to_numpy()
                self.series.setdefault(entity.rsplit("/", 1)[1], {}).update(zip(ticks, values.tolist()))
            for kind, dims in (("Points2D", 2), ("Points3D", 3)):  # a 3D run's robots are Points3D
                if f"{kind}:positions" in names:
                    pos, cls = batch.column(f"{kind}:positions"), batch.column(f"{kind}:class_ids")
                    for k, tick in enumerate(ticks):
                        p = pos[k].values.flatten().to_numpy(zero_copy_only=False).reshape(-1, dims)
                        self.robots[tick] = (p, cls[k].values.to_numpy(zero_copy_only=False))
            if "SegmentationImage:buffer" in names:
                buf = batch.column("SegmentationImage:buffer")
                for k, tick in enumerate(ticks):
                    self.occupancy[tick] = buf[k].values[0].values.to_numpy(zero_copy_only=False)
            if "Boxes3D:centers" in names:  # a 3D run's filled voxels: their centres, (n, 3) flattened
                centres = batch.column("Boxes3D:centers")
                for k, tick in enumerate(ticks):
                    self.occupancy[tick] = centres[k].values.flatten().to_numpy(zero_copy_only=False)
            if "TextLog:text" in names:
                texts = batch.column("TextLog:text").flatten().to_pylist()
                self.events += list(zip(ticks, texts))
        self.events.sort()

    def same_data(self, other: Recording) -> bool:
        """Whether two recordings hold the same logged data (not the same bytes: ids and times differ)."""
        return (self.series == other.series and self.events == other.events and self.static == other.static
                and self.robots.keys() == other.robots.keys()
                and all(np.array_equal(a, b) for t in self.robots for a, b in zip(self.robots[t], other.robots[t]))
                and self.occupancy.keys() == other.occupancy.keys()
                and all(np.array_equal(self.occupancy[t], other.occupancy[t]) for t in self.occupancy))


def rrd_verify(path) -> subprocess.CompletedProcess:
    """``rerun rrd verify PATH`` with the rerun CLI installed beside this Python."""
    import sys

    exe = Path(sys.executable).with_name("rerun")
    return subprocess.run([str(exe), "rrd", "verify", str(path)], capture_output=True, text=True, timeout=120)


# -- two hosts on one machine: Linux network namespaces joined by a veth pair --------------

SUBNET = "10.231.{}.{}"


def host_env() -> dict[str, str]:
    """This process's environment without any ROS or DDS setting (an earlier test may have left some):
    what a process on another host starts from."""
    return {k: v for k, v in os.environ.items() if not k.startswith(("ROS_", "FASTDDS_", "FASTRTPS_", "RMW_"))}


def ip_in(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(["ip", *args], capture_output=True, text=True, timeout=30)


def _wait_until_up(*links: tuple[str, str], limit: float = 10.0) -> None:
    """Wait until each (namespace, device) reports operstate UP, with its carrier.

    The kernel reports a veth's carrier (operstate UP) asynchronously, after both ends are set
    up; it usually takes milliseconds. Fast DDS lists a host's interfaces once, when a
    participant starts, so a node must not start before its interface is really up.
    """
    deadline = time.monotonic() + limit
    while True:
        states = {dev: json.loads(ip_in("-n", ns, "-j", "link", "show", "dev", dev).stdout
                                  or "[{}]")[0].get("operstate")
                  for ns, dev in links}
        if all(state == "UP" for state in states.values()):
            return
        if time.monotonic() > deadline:
            pytest.fail(f"the veth pair did not come up within {limit:g} s: {states}")
        time.sleep(0.05)


def _imports_of(path, module: str, package: str) -> set[str]:
    """The swarm_ros modules that ``module`` (file ``path``) imports, lazy and TYPE_CHECKING imports included."""
    import ast

    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = package.split(".")
            if node.level:
                base = base[: len(base) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module
            found.add(target)
            found |= {f"{target}.{a.name}" for a in node.names}  # `from . import messages`
    return found


def module_graph() -> dict[str, set[str]]:
    from pathlib import Path

    root = Path(__file__).resolve().parents[1] / "swarm_ros"
    modules = {}
    for path in root.rglob("*.py"):
        parts = list(path.relative_to(root.parent).with_suffix("").parts)
        package = ".".join(parts if parts[-1] == "__init__" else parts[:-1]).removesuffix(".__init__")
        name = ".".join(parts).removesuffix(".__init__")
        modules[name] = (path, package)
    return {name: {m for m in _imports_of(path, name, package) if m in modules and m != name}
            for name, (path, package) in modules.items()}


def make_cloud(rows: np.ndarray, tick: int):
    """A PointCloud2 message object holding ``rows``, built field by field as an outside ROS tool builds one:
    the reference the graph's own CDR writer is compared with, and what tests reshape into bad messages."""
    import array

    from sensor_msgs.msg import PointCloud2, PointField
    from std_msgs.msg import Header

    from swarm_ros.protocol.rows import FRAME_ID, point_fields
    from swarm_ros.ros.graph import stamp

    msg = PointCloud2()
    msg.header = Header(stamp=stamp(tick), frame_id=FRAME_ID)
    msg.height, msg.width = 1, int(rows.size)
    msg.fields = [PointField(name=n, offset=o, datatype=d, count=c) for n, o, d, c in point_fields(rows.dtype)]
    msg.is_bigendian = False
    msg.point_step = rows.dtype.itemsize
    msg.row_step = rows.dtype.itemsize * int(rows.size)
    msg.data = array.array("B", rows.tobytes())
    msg.is_dense = True
    return msg
