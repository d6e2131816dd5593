#!/usr/bin/env python3
"""The floor under the ROS graph: a bare lockstep over rclpy with the star's message sizes, and nothing else.

A world process and K batch processes, on a domain of their own, exchange per tick exactly the
rows the product's graph exchanges for the star (read from the in-process engine's run of the
same seed): the world publishes the tick's changed rows on one topic (40 bytes per row, as
``/swarm/robots``), each batch answers with its share of the moving robots' decisions (48
bytes per row, as ``/swarm/decisions/<batch>``), and the world starts the next tick once every
batch has answered. Messages are PointCloud2 bytes built once (:func:`encode_cloud`), published
serialized and taken raw, through the product's QoS and DDS profile and an EventsExecutor, the
executor the nodes use. No checks, no tags, no state: the transport alone. ``bench_ros.py``
runs it in the same session as the graph and reports the graph's ticks/s as a share of it.

    .venv/bin/python scripts/bench_bare.py --processes 2 [--seed 1] [--repeats 3]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import struct
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

_TICK = struct.Struct("<i")


def star_rows(seed: int, rules: str = "paper") -> tuple[np.ndarray, np.ndarray]:
    """(rows the world sends, moving robots) per tick of the star's run with ``seed``, ticks 1..end."""
    from swarm_ros.core import RunParams, Shape, Simulation

    shape = Shape.load("star")
    sim = Simulation(shape, RunParams(robots=shape.patches, seed=seed, rules=rules))
    sent, moving = [], []
    while not sim.done:
        moving.append(sim.metrics.moving)
        sim.step()
        sent.append(np.union1d(sim.last_joins()[0], sim.last_removed).size)
    return np.array(sent), np.array(moving)


def _node(role: str, domain: int):
    import rclpy
    from rclpy.context import Context
    from rclpy.experimental import EventsExecutor
    from rclpy.node import Node

    from swarm_ros.ros.dds import apply_dds_defaults

    apply_dds_defaults()
    context = Context()
    rclpy.init(args=[], context=context, domain_id=domain)
    node = Node(role, context=context, start_parameter_services=False)
    executor = EventsExecutor(context=context)
    executor.add_node(node)
    return node, executor


def _spin(node, executor) -> bool:
    """Handle the next event, or what waits in the readers after 50 ms without one (as the product's nodes do:
    rclpy's EventsExecutor sometimes loses a new-message event, swarm_ros.ros.runtime.handle_missed)."""
    from swarm_ros.ros.runtime import handle_missed

    began = time.monotonic()
    executor.spin_once(timeout_sec=0.05)
    return time.monotonic() - began < 0.05 or handle_missed(node) > 0


def _cloud(dtype, n: int, tick: int) -> bytes:
    from swarm_ros.protocol.cdr import encode_cloud

    return encode_cloud(np.zeros(n, dtype=dtype), tick)


def world(domain: int, k: int, sizes: Path, out: Path) -> None:
    from sensor_msgs.msg import PointCloud2

    from swarm_ros.protocol.darr_niazi.rows import ROBOT_ROW
    from swarm_ros.ros import graph as msgs

    sent, _ = np.load(sizes)
    node, executor = _node("bare_world", domain)
    pub = node.create_publisher(PointCloud2, "/bare/robots", msgs.ROBOTS_QOS)
    answered: dict[int, int] = {}

    def on_reply(data: bytes) -> None:
        tick = _TICK.unpack_from(data, 4)[0]
        answered[tick] = answered.get(tick, 0) + 1

    for b in range(k):
        node.create_subscription(
            PointCloud2, f"/bare/decisions/batch_{b}", on_reply, msgs.reader_qos(msgs.DECISIONS_QOS), raw=True
        )
    while pub.get_subscription_count() < k or any(
        node.count_publishers(f"/bare/decisions/batch_{b}") < 1 for b in range(k)
    ):
        executor.spin_once(timeout_sec=0.01)
    messages = [_cloud(ROBOT_ROW, int(n), t) for t, n in enumerate(sent)]
    start = time.perf_counter()
    for t, data in enumerate(messages):
        pub.publish(data)
        while answered.get(t, 0) < k:
            _spin(node, executor)
    seconds = time.perf_counter() - start
    pub.publish(_cloud(ROBOT_ROW, 0, -1))  # the end
    pub.wait_for_all_acked(__import__("rclpy").duration.Duration(seconds=2))
    out.write_text(json.dumps({"ticks": len(messages), "seconds": seconds}))


def batch(domain: int, b: int, k: int, sizes: Path) -> None:
    from sensor_msgs.msg import PointCloud2

    from swarm_ros.protocol.darr_niazi.rows import DECISION_ROW
    from swarm_ros.ros import graph as msgs

    _, moving = np.load(sizes)
    node, executor = _node(f"bare_batch_{b}", domain)
    pub = node.create_publisher(PointCloud2, f"/bare/decisions/batch_{b}", msgs.DECISIONS_QOS)
    share = [max(1, int(m) // k) for m in moving]
    done = []

    def on_robots(data: bytes) -> None:
        tick = _TICK.unpack_from(data, 4)[0]
        if tick < 0:
            done.append(1)
            return
        pub.publish(_cloud(DECISION_ROW, share[tick], tick))

    node.create_subscription(PointCloud2, "/bare/robots", on_robots, msgs.reader_qos(msgs.ROBOTS_QOS), raw=True)
    last = time.monotonic()
    while not done and time.monotonic() - last < 30:  # the world gone without its last message: stop too
        if _spin(node, executor):
            last = time.monotonic()


def bare(seed: int, k: int, domain: int) -> tuple[int, float]:
    """(ticks, seconds) of one bare lockstep with ``k`` batches, the star's message sizes."""
    return _lockstep(np.stack(star_rows(seed)), k, domain)


def bare_fixed(k: int, rows: int, decisions: int, ticks: int, domain: int) -> float:
    """Seconds per tick of a bare lockstep with ``k`` batches where every tick the world sends ``rows`` robot
    rows (one message every batch takes) and each batch answers with ``decisions`` decision rows: the
    transport's part of a tick at a given size (scripts/bench_scale.py's projection)."""
    sizes = np.stack([np.full(ticks, rows), np.full(ticks, decisions * k)])
    done, seconds = _lockstep(sizes, k, domain)
    return seconds / done


def _lockstep(sizes_per_tick: np.ndarray, k: int, domain: int) -> tuple[int, float]:
    """(ticks, seconds) of one bare lockstep with ``k`` batches: row (rows sent, moving robots) per tick."""
    with tempfile.TemporaryDirectory() as tmp:
        sizes, out = Path(tmp) / "sizes.npy", Path(tmp) / "out.json"
        with open(sizes, "wb") as f:
            np.save(f, sizes_per_tick)
        me = [sys.executable, __file__, "--domain-id", str(domain), "--sizes", str(sizes)]
        procs = [subprocess.Popen([*me, "--role", f"batch:{b}:{k}"]) for b in range(k)]
        world = subprocess.Popen([*me, "--role", f"world:{k}", "--out", str(out)])
        world.wait(timeout=300)
        for p in procs:  # a batch that missed the world's last message would wait for it: the world is done
            try:
                p.wait(timeout=10)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
        got = json.loads(out.read_text())
        return got["ticks"], got["seconds"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--processes", type=int, nargs="+", default=[1, 2, 4])
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--domain-id", type=int, default=90 + os.getpid() % 10)
    parser.add_argument("--role")
    parser.add_argument("--sizes", type=Path)
    parser.add_argument("--out", type=Path)
    args = parser.parse_args()
    if args.role:
        kind, *nums = args.role.split(":")
        if kind == "world":
            world(args.domain_id, int(nums[0]), args.sizes, args.out)
        else:
            batch(args.domain_id, int(nums[0]), int(nums[1]), args.sizes)
        return
    for k in args.processes:
        rates = []
        for _ in range(args.repeats):
            ticks, seconds = bare(args.seed, k, args.domain_id)
            rates.append(ticks / seconds)
        print(
            f"bare lockstep, star sizes, K = {k}: {ticks} ticks, ticks/s min {min(rates):,.0f} "
            f"median {statistics.median(rates):,.0f} max {max(rates):,.0f}"
        )


if __name__ == "__main__":
    main()
