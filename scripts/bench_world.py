#!/usr/bin/env python3
"""The world's own work per tick, without ROS: a world process's ``Lockstep`` taking two batches' decisions of a
tick and applying, saving and routing it (to a port that drops what it is given), in milliseconds per tick.

What it leaves out is the same for every version measured: the batches' rule (run here, untimed, on an in-process
``Simulation`` that the world is checked against at the end), the messages and rclpy. So it is the A/B of a
change to the world's tick (issue 46: the world as the world shard with no peers), run back to back in two
trees: this commit's and an older one extracted with ``git archive``. It also runs the ``Lockstep`` of before
that change (a ``Simulation`` inside, a ``Checkpoint`` for its save), so one script measures both::

    git archive <commit> | tar -x -C /tmp/base
    PYTHONPATH=/tmp/base .venv/bin/python scripts/bench_world.py        # before
    .venv/bin/python scripts/bench_world.py                             # this tree

Cases: the star (1,036 robots, its 405 ticks) and a disc of 50,000 robots at the star's density (world radius
226, ``--ticks`` ticks), seed 1, K = 2 batches; median (min-max) over ``--repeats``.

``--central`` adds the study's model on a central world, the one design the rubenstein algorithm's graph runs on
(issue 62: the study's graph is to move onto it): its world's work a tick (every batch's area out as a PointCloud2,
the decisions checked, the tick settled), each batch's (its rows checked, its view rebuilt, its decisions), and the
bytes each batch is sent a tick, once over the star (K = 2) and the disc (K = 4) from tick 0 and from tick 1,000.
A central world sends each batch its whole view (its area, and every stationary robot) at first and then, as the
study's graph does, only the rows that changed.

    .venv/bin/python scripts/bench_world.py [--repeats 5] [--ticks 60] [--robots 50000] [--central] [--smoke]
"""

from __future__ import annotations

import argparse
import inspect
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_scale import disc_file

from swarm_ros.core import RunParams, Shape, Simulation, World
from swarm_ros.core.metrics import METRIC_COLUMNS
from swarm_ros.core.regions import batch_cuts, columns, strip
from swarm_ros.core.rules import Decider
from swarm_ros.protocol.checks import Rejections
from swarm_ros.protocol.lockstep import Lockstep
from swarm_ros.protocol.plan import batch_name
from swarm_ros.protocol.rows import decision_rows
from swarm_ros.protocol.world_port import Policy

UNIFIED = "shard" in inspect.signature(Lockstep.__init__).parameters  #: the world as a shard (issue 46) or before
BATCHES = 2


class _Log:
    def info(self, text: str) -> None:
        pass

    warn = info


class _Port:
    """A world node that publishes nothing and saves each tick as the node does."""

    saver = None

    def watch_batch(self, *args) -> None:
        pass

    send_snapshot = publish_tick = publish_status = save_book = watch_batch

    def checkpoint(self, tick, rows, applied, metrics, published, tally) -> None:  # the Lockstep of before
        assert self.saver is not None
        self.saver.write(tick, rows, applied, metrics, published, tally)

    def save_tick(self, tick, rows, published, applied, metrics, sent, tally) -> None:
        assert self.saver is not None
        self.saver.write_tick(tick, rows, published, applied, metrics, sent, tally)

    def monitor_reads_all(self) -> bool:
        return True

    delivered = decisions_delivered = monitor_reads_all

    def startup_seconds(self) -> float:
        return 0.0


def _lockstep(shape: Shape, params: RunParams, folder: Path):
    port, log = _Port(), _Log()
    policy, rejections = Policy(monitor_window=0), Rejections(log)
    if UNIFIED:
        from swarm_ros.core.shards import ShardPlan, WorldShard
        from swarm_ros.protocol.shard_save import ShardSaver

        plan = ShardPlan(shape.world.radius, params.vision_radius, np.empty(0, dtype=np.int64))
        port.saver = saver = ShardSaver(folder / "save", params, plan, 0, 2, shape.dims)
        saver.create()
        return Lockstep(WorldShard(shape, params, plan, 0), "world", policy, port, log, rejections)
    from swarm_ros.protocol.checkpoint import Checkpoint

    port.saver = ck = Checkpoint(folder / "save", params.robots, params.max_ticks, len(METRIC_COLUMNS), 2, shape.dims)
    ck.create()
    return Lockstep(Simulation(shape, params), policy, port, log, rejections)  # the signature of before


def world_tick_ms(shape: Shape, params: RunParams, max_ticks: int) -> tuple[float, int]:
    """Milliseconds per tick of the world's decisions-to-tick path, and the ticks run."""
    cuts = batch_cuts(shape, params, BATCHES)
    strips = [strip(k, BATCHES, cuts, shape.world.radius) for k in range(BATCHES)]
    with tempfile.TemporaryDirectory() as folder:
        ls = _lockstep(shape, params, Path(folder))
        for k in range(BATCHES):
            ls.announce(batch_name(k), 0, strips[k])
        decider, ref = Decider(shape, params), Simulation(shape, params)
        spent, ticks = 0.0, 0
        while not ls.sim.done and ticks < max_ticks:
            s = ref.state
            decisions = decider.decide(s, s.moving_ids(), ref.tick + 1)
            rows = decision_rows(decisions)
            cols = columns(s.x[rows["id"]], shape.world.radius)
            parts = [rows[(cols >= a) & (cols <= b)] for a, b in strips]
            began = time.perf_counter()
            for k, part in enumerate(parts):
                if part.size:
                    ls.decisions(k, ref.tick + 1, part)
            spent += time.perf_counter() - began
            ref.apply(decisions)
            ticks += 1
        if [int(v) for v in ls.sim.history[-1]] != [int(v) for v in ref.history[-1]]:
            sys.exit("bench_world: the world's run is not the engine's")
    return 1000 * spent / ticks, ticks


def central_tick(shape: Shape, params: RunParams, batches: int, ticks: int, skip: int = 0) -> tuple[float, list, list]:
    """The study's model on a central world (``Simulation`` as a ``CentralRun``, its wire and strip batches, every
    message through a PointCloud2's bytes): milliseconds per tick of the world (the areas out, the decisions checked,
    the tick settled), of each batch (its area's rows checked, its decisions), and each batch's bytes of rows a tick,
    over at most ``ticks`` ticks from tick ``skip`` (to the run's end)."""
    from swarm_ros.core.strips import AreaStore, strips_for
    from swarm_ros.protocol.cdr import decode_cloud, encode_cloud
    from swarm_ros.protocol.central_lockstep import CentralLockstep
    from swarm_ros.protocol.checks import cloud
    from swarm_ros.protocol.darr_niazi.wire import StudyWire

    run, start, wire = Simulation(shape, params), Simulation(shape, params), StudyWire(shape.dims)
    if skip:
        run.run(skip)
    ls = CentralLockstep(run, wire)
    strips = strips_for(start, batches)
    for k in range(batches):
        ls.announce(batch_name(k), strips.strip(k))
    hosts = [wire.batch(start, strips, k) for k in range(batches)]
    stores = [AreaStore(start, strips, k) for k in range(batches)]
    world, spent, sent, ran = 0.0, np.zeros(batches), np.zeros(batches), 0
    while run.outcome is None and ran < ticks:
        tick, ran = run.tick, ran + 1
        began = time.process_time()
        messages = {
            k: (encode_cloud(rows, tick), whole) for k, (rows, whole) in ls.areas(list(range(batches)), set()).items()
        }
        world += time.process_time() - began
        for k, (message, whole) in messages.items():
            between = time.process_time()
            rows = cloud(decode_cloud(message), wire.row, params.robots, min_rows=0)
            wire.check_rows(start, rows, tick)
            changed = stores[k].take(tick, *wire.robots_of(rows), whole)
            decided = hosts[k].decide(tick + 1, stores[k].seen, changed, stores[k].robots)
            answer = encode_cloud(wire.decision_rows(*decided), tick + 1)
            after = time.process_time()
            ls.decisions(k, tick + 1, cloud(decode_cloud(answer), wire.decision_row, params.robots, min_rows=0))
            world += time.process_time() - after
            spent[k] += after - between
            sent[k] += len(message)
    return 1000 * world / ran, list(1000 * spent / ran), list(sent / ran)


def central(args: argparse.Namespace, disc: Path, radius: int) -> None:
    """The study's model on a central world (``--central``): what its world and its batches would do a tick."""
    print("the study's model on a central world: the world's ms a tick | each batch's ms | each batch's bytes a tick")
    late = 10 if args.smoke else 1000
    cases = [
        ("star, K = 2", Shape.load("star"), 1036, 2, 10_000, 0),
        (f"disc {args.robots:,}, K = 4", Shape.load(disc, World(radius=radius)), args.robots, 4, args.ticks, 0),
        (f"from tick {late:,}", Shape.load(disc, World(radius=radius)), args.robots, 4, args.ticks // 3 or 1, late),
    ]
    for name, shape, robots, batches, ticks, skip in cases:
        params = RunParams(robots=robots, seed=1)
        world, spent, sent = central_tick(shape, params, batches, ticks, skip)
        each = " ".join(f"{m:.2f}" for m in spent)
        print(f"  {name:>22}: {world:7.2f} | {each} | {' '.join(f'{b / 1000:.0f} kB' for b in sent)}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--ticks", type=int, default=60, help="ticks of the large disc (the star runs to its end)")
    ap.add_argument("--robots", type=int, default=50_000, help="the large disc's robots")
    ap.add_argument("--smoke", action="store_true", help="small and quick: checks the script runs (test_scripts)")
    ap.add_argument("--central", action="store_true", help="the study's model on a central world too (this tree only)")
    args = ap.parse_args()
    if args.smoke:
        args.repeats, args.ticks, args.robots, args.central = 1, 3, 2000, True
    print(f"the world's tick, {'as a shard with no peers' if UNIFIED else 'a Simulation inside (before issue 46)'}")
    with tempfile.TemporaryDirectory() as tmp:
        disc, radius = disc_file(args.robots, Path(tmp))
        cases = [
            ("star", Shape.load("star"), 1036, 10_000),
            (f"disc {args.robots:,}", Shape.load(disc, World(radius=radius)), args.robots, args.ticks),
        ]
        for name, shape, robots, ticks in cases:
            params = RunParams(robots=robots, seed=1)
            world_tick_ms(shape, params, 5)  # the kernels' first calls
            runs = [world_tick_ms(shape, params, ticks) for _ in range(args.repeats)]
            ms = [m for m, _ in runs]
            print(
                f"  {name:>14}: {statistics.median(ms):7.3f} ms a tick ({min(ms):.3f}-{max(ms):.3f}), "
                f"{runs[0][1]} ticks, median of {args.repeats}"
            )
        if args.central:
            central(args, disc, radius)


if __name__ == "__main__":
    main()
