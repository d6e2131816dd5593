"""Runs to test with: small shapes and shape files, checked in-process runs, runs split into batches,
experiment files."""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import yaml

from swarm_ros.core import RunParams, Shape, Simulation, World, decide
from swarm_ros.core.darr_niazi.invariants import check_state, check_tick
from swarm_ros.core.darr_niazi.rules import Decisions
from swarm_ros.core.darr_niazi.state import FRONTIER_BLOCK

# Robot counts that complete each built-in shape in the original study (docs/model.md, "Shapes").
STUDY_PATCHES = {"star": 1036, "wrench": 566, "k-letter": 1352, "rectangle": 438, "tyre": 1282, "spinner": 1040}


def disc_shape(world: World, radius: float, name: str = "disc", hole: float = 0.0) -> Shape:
    """A disc (or ring, with ``hole`` > 0) centred on the origin."""
    r = world.radius
    c = np.arange(-r, r + 1)
    x, y = np.meshgrid(c, c)
    d = np.hypot(x, y)
    return Shape(name=name, mask=(d <= radius) & (d >= hole), world=world, source=f"test {name}")


def run_digest(sim: Simulation, *arrays: np.ndarray) -> str:
    """A short hash of ``arrays``, then of the frontier's counts as the code before the super-blocks kept them
    (per block, then the total: the hashes of test_2d_unchanged and test_3d_unchanged were made so; the
    super-blocks' counts are derived from those and checked by the invariants), then of every tick's metrics."""
    blocks = sim.state.frontier_blocks
    fine = (-(-sim.shape.world.size // FRONTIER_BLOCK)) ** sim.shape.world.dims
    digest = hashlib.sha256()
    for a in (*arrays, np.append(blocks[:fine], blocks[-1]), sim.history):
        digest.update(np.ascontiguousarray(a).tobytes())
    return digest.hexdigest()[:16]


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


def cloud_rows(msg, dtype: np.dtype) -> np.ndarray:
    """The rows of a PointCloud2 of ``dtype`` rows, none or more, as a node reads them (``checks.cloud``; Rejected if
    its layout is not ``dtype``'s)."""
    import sys

    from swarm_ros.protocol.checks import cloud

    return cloud(msg, dtype, max_rows=sys.maxsize, min_rows=0)


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
