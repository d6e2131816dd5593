"""What several test modules share: small shapes, checked runs, recordings read back, network namespaces,
the package's import graph, runs of the graph and their processes, killed nodes and their restarts,
experiment files, the lockstep driven with a fake port and clock. (Fixtures are in conftest.py; modules
import these by name; a test module imports nothing from another test module.)"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from bagcheck import assert_bag_holds_run

from swarm_ros.core import RunParams, Shape, Simulation, World, decide
from swarm_ros.core.invariants import check_state, check_tick
from swarm_ros.core.regions import batch_strip, columns
from swarm_ros.core.rules import Decider, Decisions
from swarm_ros.protocol.checkpoint import MAGIC
from swarm_ros.protocol.checks import Rejections
from swarm_ros.protocol.lockstep import Lockstep
from swarm_ros.protocol.plan import batch_name
from swarm_ros.protocol.rows import decision_rows
from swarm_ros.protocol.world_port import Policy

_DONE = 7  # the checkpoint header's int64 holding the last tick saved (swarm_ros.protocol.checkpoint)

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
        return (
            self.series == other.series
            and self.events == other.events
            and self.static == other.static
            and self.robots.keys() == other.robots.keys()
            and all(np.array_equal(a, b) for t in self.robots for a, b in zip(self.robots[t], other.robots[t]))
            and self.occupancy.keys() == other.occupancy.keys()
            and all(np.array_equal(self.occupancy[t], other.occupancy[t]) for t in self.occupancy)
        )


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
        states = {
            dev: json.loads(ip_in("-n", ns, "-j", "link", "show", "dev", dev).stdout or "[{}]")[0].get("operstate")
            for ns, dev in links
        }
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
    return {
        name: {m for m in _imports_of(path, name, package) if m in modules and m != name}
        for name, (path, package) in modules.items()
    }


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


# -- from test_ros_graph.py --------------------------------------------------------------------------------------


def run_env() -> dict[str, str]:
    env = dict(os.environ)
    env.pop("ROS_DOMAIN_ID", None)  # every run picks a free domain of its own
    env.setdefault("HOME", "/tmp")
    return env


def shape_file(path: Path, outer: float, hole: float = 0.0, cross: bool = False, half: int = 16) -> Path:
    c = np.arange(-half, half + 1)
    x, y = np.meshgrid(c, c)
    d = np.hypot(x, y)
    mask = (d <= outer) & (d >= hole)
    if cross:
        mask = ((np.abs(x) <= 2) & (np.abs(y) <= outer)) | ((np.abs(y) <= 2) & (np.abs(x) <= outer))
    rows = ["".join("#" if v else "." for v in row) for row in mask[::-1]]
    path.write_text("\n".join(rows) + "\n")
    return path


def _processes_where(read: str, holds) -> list[int]:
    """Pids of the live processes whose /proc/<pid>/``read`` file's text ``holds`` (one that ended meanwhile: no)."""
    found = []
    for proc in Path("/proc").iterdir():
        if proc.name.isdigit():
            try:
                text = (proc / read).read_bytes().decode(errors="replace")
            except OSError:
                continue
            if holds(text):
                found.append(int(proc.name))
    return found


def processes_mentioning(text: str) -> list[int]:
    """Pids of the processes whose command line holds ``text``."""
    return _processes_where("cmdline", lambda cmdline: text in cmdline)


def run_processes(out: Path) -> list[int]:
    """Pids of the node processes of the run writing ``out`` (their parameter files are in its hidden logs
    folder), and of no other run on the machine, a test running beside this one included."""
    return processes_mentioning(f"{out.absolute().parent}/.{out.name}.logs-")


def assert_same_run(ref: Path, got: Path, launched: bool = True) -> None:
    """``got`` (a ROS run; ``launched``: by ``swarm-ros run``) equals ``ref`` (``simulate``) but for timings."""
    assert (ref / "metrics.csv").read_bytes() == (got / "metrics.csv").read_bytes()
    assert (ref / "final_state.csv").read_bytes() == (got / "final_state.csv").read_bytes()
    a = json.loads((ref / "summary.json").read_text())
    b = json.loads((got / "summary.json").read_text())
    assert (a.pop("engine"), b.pop("engine")) == ("inprocess", "ros2")
    a.pop("wall_seconds"), b.pop("wall_seconds")
    # a ROS run's overheads: from the command's start to tick 0, and from the outcome to the last process gone
    # (only the launcher knows the latter, from the world's status: its progress listener heard the graph)
    startup, shutdown = b.pop("startup_seconds"), b.pop("shutdown_seconds")
    assert isinstance(startup, float) and 0 < startup < 120
    assert (isinstance(shutdown, float) and 0 < shutdown < 60) if launched else shutdown is None
    assert b.pop("rejected_messages") == {"world": 0, "monitor": 0}  # an honest run: nothing dropped
    processes, shards = b.pop("processes"), b.pop("world_shards")  # how it ran
    assert isinstance(shards, int) and shards >= 1
    assert (isinstance(processes, int) and processes >= shards) if launched else processes is None
    b.pop("bag_robots_every", None)  # checked against the bag (bagcheck)
    assert a == b
    assert (got / "final.png").stat().st_size > 0 and (got / "convergence.png").stat().st_size > 0
    assert_bag_holds_run(got)  # the rosbag2 of the run, read with another library than the one that wrote it
    # the monitor records with the same module: the same data (ids, timestamps and chunking may differ)
    assert Recording(got / "recording.rrd").same_data(Recording(ref / "recording.rrd"))


# -- from test_restarts.py ---------------------------------------------------------------------------------------


# The star under the local join rule: ~3600 ticks, several seconds over the graph, long enough to kill in
STAR_LOCAL = ["--shape", "star", "--seed", "5", "--rules", "local"]
#: STAR_LOCAL cut at 1,000 ticks (outcome timeout): the fault tests' run, about 3 s over the graph once started;
#: their kills are timed on what the run writes, all before tick 600
STAR_SHORT = [*STAR_LOCAL, "--max-ticks", "1000"]


def node_pid(out: Path, node: str, timeout: float = 60, not_pid: int | None = None) -> int:
    """The pid of the process running ``node`` for the run into ``out`` (a new one if ``not_pid`` is given)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        for pid in run_processes(out):
            try:
                cmdline = Path(f"/proc/{pid}/cmdline").read_bytes().decode(errors="replace")
            except OSError:
                continue
            if f"__node:={node}\0" in cmdline + "\0" and str(out.parent) in cmdline and pid != not_pid:
                return pid
        time.sleep(0.02)
    raise AssertionError(f"no process for {node}")


def wait_ticks_recorded(out: Path, size: int, timeout: float = 120) -> None:
    """Wait until the run's partial recording holds ``size`` bytes: ticks are flowing."""
    partial = out.parent / f"{out.name}.partial.rrd"
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if partial.exists() and partial.stat().st_size > size:
            return
        time.sleep(0.02)
    raise AssertionError("the run never got going")


def assert_identical_run(reference: Path, out: Path) -> dict:
    for name in ("metrics.csv", "final_state.csv"):
        assert (out / name).read_bytes() == (reference / name).read_bytes(), name
    got, ref = (json.loads((d / "summary.json").read_text()) for d in (out, reference))
    assert got["outcome"] == ref["outcome"] and got["lost_robots"] == 0 and got["losses"] == []
    return got


# -- from test_node_restarts.py ----------------------------------------------------------------------------------


def staged_logs(out: Path, timeout: float = 60) -> Path:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        found = list(out.parent.glob(f".{out.name}.logs-*"))
        if found:
            return found[0]
        time.sleep(0.01)
    raise AssertionError("no logs")


def saved_tick(logs: Path, name: str = "world.checkpoint") -> int:
    """The last tick the world saved (``name``: world.checkpoint.<i> for world shard i); -1 before its first."""
    try:
        head = np.fromfile(logs / name, dtype=np.int64, count=8)
    except (OSError, ValueError):
        return -1
    return int(head[_DONE]) if head.size == 8 and head[0] == MAGIC else -1


def wait_saved(logs: Path, tick: int, timeout: float = 180, name: str = "world.checkpoint") -> int:
    """Wait (polling fast) until the world (the shard whose save is ``name``) has saved ``tick``; return the tick
    saved when seen."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        t = saved_tick(logs, name)
        if t >= tick:
            return t
        time.sleep(0.0005)
    raise AssertionError(f"tick {tick} never came")


def kill_node(out: Path, node: str, not_pid: int | None = None) -> int:
    pid = node_pid(out, node, not_pid=not_pid)
    os.kill(pid, signal.SIGKILL)
    return pid


def finish_restarted_run(launcher, reference: Path, out: Path, restarts: list[str]) -> dict:
    _, err = launcher.communicate(timeout=300)
    assert launcher.returncode == 0, err
    summary = assert_identical_run(reference, out)
    assert [r["node"] for r in summary["restarts"]] == restarts, summary["restarts"]
    assert_bag_holds_run(out)
    assert not list(out.parent.glob(f".{out.name}.*")), "nothing of the run left beside it"
    assert not list((out / "logs").glob("world.checkpoint*")), "the checkpoint is removed with the run"
    assert not processes_mentioning(str(out)), "a process outlived the run"
    return summary


# -- from test_experiment.py -------------------------------------------------------------------------------------


def disc_file(path: Path, radius: float = 4.5, half: int = 6) -> Path:
    c = np.arange(-half, half + 1)
    x, y = np.meshgrid(c, c)
    rows = ["".join("#" if v else "." for v in row) for row in (np.hypot(x, y) <= radius)[::-1]]
    path.write_text("\n".join(rows) + "\n")
    return path


def small_config(tmp_path: Path, **over) -> Path:
    """A small grid in a 21 x 21 world: one disc shape (69 patches), three sizes, two radii."""
    disc_file(tmp_path / "disc.txt")
    data = {
        "name": "small",
        "seed": 11,
        "repetitions": 3,
        "vision_radius": [1, 1.5],
        "max_ticks": 4000,
        "world_radius": 10,
        "shapes": {"disc.txt": [50, "patches", 80]},
        **over,
    }
    path = tmp_path / "small.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def children_of(pid: int) -> list[int]:
    """Pids of the processes whose parent is ``pid``."""
    return _processes_where("stat", lambda stat: int(stat.rsplit(")", 1)[1].split()[1]) == pid)


def shm_left(files) -> list[str]:
    """Those of the Fast DDS shared-memory ``files`` that still exist and that no live process uses: left
    behind. A port's files (``fastrtps_portN``) are shared by every participant on that port, so a run or test
    beside this one may rightly still hold them."""
    from swarm_ros.ros.shm import in_use

    def group(path: str) -> set[str]:  # a segment, its lock file and (a port's) its semaphore
        name = Path(path).name.removesuffix("_el")
        if name.startswith("sem.") and name.endswith("_mutex"):
            name = name.removeprefix("sem.").removesuffix("_mutex")
        return {f"/dev/shm/{name}", f"/dev/shm/{name}_el", f"/dev/shm/sem.{name}_mutex"}

    return sorted(f for f in files if os.path.exists(f) and not in_use(group(f)))


def descendants_of(pid: int) -> list[int]:
    """Pids of ``pid``'s children, their children, and so on."""
    found, todo = [], [pid]
    while todo:
        kids = children_of(todo.pop())
        found += kids
        todo += kids
    return found


def alive(pid: int) -> bool:
    """Whether process ``pid`` runs (not gone, not a zombie)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().split(")")[-1].split()[0] != "Z"
    except OSError:
        return False


# -- from test_engine.py -----------------------------------------------------------------------------------------


def final_of(sim):
    return (
        sim.outcome,
        sim.history.tolist(),
        sim.state.x.tobytes(),
        sim.state.y.tobytes(),
        sim.state.heading.tobytes(),
        sim.state.state.tobytes(),
    )


def run_in_batches(shape: Shape, p, batches: int, seed: int) -> Simulation:
    """The distributed data flow in one process: robots split over ``batches`` by a random
    owner map, each batch decides from the shared view, the world applies the union."""
    sim = Simulation(shape, p)
    owner = np.random.default_rng(seed).integers(0, batches, p.robots)
    while not sim.done:
        ids = sim.moving_ids()
        parts = [decide(sim.state, ids[owner[ids] == b], shape, p, sim.tick + 1) for b in range(batches)]
        sim.apply(Decisions.concatenate(parts[::-1]))
    return sim


# -- from test_lockstep.py ---------------------------------------------------------------------------------------


ROBOTS, MAX_TICKS = 60, 400


class Clock:
    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


class Log:
    def __init__(self) -> None:
        self.lines: list[str] = []

    def info(self, text: str) -> None:
        self.lines.append(text)

    warn = info


class LockstepPort:
    """Records what the lockstep publishes."""

    def __init__(self) -> None:
        self.watched: list[str] = []
        self.snapshots: list[tuple[int, int]] = []  # (batch, tick)
        self.ticks: list[int] = []
        self.statuses: list = []
        self.monitor_ready = True
        self.saver = None  # a Checkpoint, to restart from (test_world_restart.py)
        self.books: list[dict] = []
        self.regions: list[tuple[int, int, np.ndarray]] = []  # (tick, batch, rows): snapshots and region rows

    def watch_batch(self, k, name):
        self.watched.append(name)

    def send_snapshot(self, k, tick, rows):
        self.snapshots.append((k, tick))
        self.regions.append((tick, k, rows))

    def publish_tick(self, tick, rows, joined, applied, regional, tally):
        assert (applied is None) == (tick == 0) and tally is None and rows is not None  # record_every 1
        self.ticks.append(tick)
        self.regions += [(tick, k, part) for k, part in enumerate(regional or ())]

    def publish_status(self, status):
        self.statuses.append(status)

    def checkpoint(self, tick, rows, applied, metrics, published, tally):
        if self.saver is not None:
            self.saver.write(tick, rows, applied, metrics, published, tally)

    def save_book(self, book):
        self.books.append(book)
        if self.saver is not None:
            self.saver.save_book(book)

    def monitor_reads_all(self):
        return self.monitor_ready

    def delivered(self):
        return True

    def decisions_delivered(self):
        return True

    def startup_seconds(self):
        return 0.5


class LockstepRun:
    """A lockstep, its port and clock, and batches that decide as robot-batch processes do."""

    def __init__(self, batches: int = 2, cuts: list[int] | None = None, shape: str = "star", **policy) -> None:
        self.shape = Shape.load(shape)
        self.params = RunParams(robots=ROBOTS, seed=7, max_ticks=MAX_TICKS)
        text = ",".join(map(str, cuts or []))
        self.strips = [batch_strip(self.shape, self.params, k, batches, text) for k in range(batches)]
        self.clock, self.port, self.log = Clock(), LockstepPort(), Log()
        self.rejections = Rejections(self.log)
        self.ls = Lockstep(
            Simulation(self.shape, self.params),
            Policy(**{"monitor_window": 0, **policy}),
            self.port,
            self.log,
            self.rejections,
            clock=self.clock,
        )
        self.batches = batches
        self.decider = Decider(self.shape, self.params)

    def announce(self, k: int, incarnation: int = 0) -> None:
        self.ls.announce(batch_name(k), incarnation, self.strips[k])

    def start(self) -> None:
        """Every batch announces itself (tick 0 follows, unless the monitor is awaited)."""
        for k in range(self.batches):
            self.announce(k)
        assert self.ls.started or self.ls.window

    def decide(self, k: int) -> np.ndarray:
        """Batch ``k``'s decision rows for the coming tick (its strip's moving robots not decided yet)."""
        s = self.ls.sim.state
        own = self.own(k)
        own = own[~self.ls.decided[own]]
        return decision_rows(self.decider.decide(s, own, self.ls.sim.tick + 1))

    def own(self, k: int) -> np.ndarray:
        """The moving robots in batch ``k``'s strip now."""
        s = self.ls.sim.state
        moving = s.moving_ids()
        cols = columns(s.x[moving], self.shape.world.radius)
        return moving[(cols >= self.strips[k][0]) & (cols <= self.strips[k][1])]

    def tick(self, silent: tuple[int, ...] = ()) -> None:
        """One tick: every batch but ``silent`` (and those removed for good) sends its decisions."""
        for k in range(self.batches):
            if k in self.ls.removed_batches:
                continue
            rows = self.decide(k)
            if k not in silent and rows.size:
                self.ls.decisions(k, self.ls.sim.tick + 1, rows)

    def run(self, ticks: int | None = None) -> None:
        end = MAX_TICKS if ticks is None else self.ls.sim.tick + ticks
        while not self.ls.sim.done and self.ls.sim.tick < end:
            self.tick()

    def engine(self) -> Simulation:
        sim = Simulation(self.shape, self.params)
        sim.run()
        return sim
