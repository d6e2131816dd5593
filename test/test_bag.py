"""The run's rosbag2: off with --no-bag, kept by an interrupted run, and published again by `swarm-ros replay`.

(Every ROS run that test_ros_graph.py makes has its bag read back and compared with the
run's files: see bagcheck.py.)
"""

from __future__ import annotations

import csv
import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from bagcheck import assert_bag_holds_run, read_bag
from graph_runs import run_env
from runs import shape_file
from waiting import wait_for

from swarm_ros.protocol.plan import CentralTopics

pytestmark = pytest.mark.process

PY = sys.executable


def _run(out: Path, *extra: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [PY, "-m", "swarm_ros", "run", "--processes", "1", "--out", str(out), "--quiet", "--no-recording", *extra],
        capture_output=True,
        text=True,
        timeout=240,
        env=run_env(),
    )


@pytest.fixture(scope="module")
def ring_run(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("bagrun")
    shape = shape_file(d / "ring.txt", outer=12.5, hole=5)
    out = d / "run"
    done = _run(out, "--shape", str(shape), "--world-radius", "16", "--seed", "2")
    assert done.returncode == 0, done.stderr
    return out


def test_no_bag_writes_none_and_leaves_nothing_beside_the_run(tmp_path):
    shape = shape_file(tmp_path / "ring.txt", outer=12.5, hole=5)
    out = tmp_path / "run"
    done = _run(out, "--shape", str(shape), "--world-radius", "16", "--no-bag")
    assert done.returncode == 0, done.stderr
    assert not (out / "bag").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ring.txt", "run"]


def test_an_interrupted_run_keeps_a_readable_bag_of_its_ticks(tmp_path):
    out = tmp_path / "run"
    # the star under the local join rule: thousands of ticks, time to interrupt
    proc = subprocess.Popen(
        [
            PY,
            "-m",
            "swarm_ros",
            "run",
            "--shape",
            "star",
            "--seed",
            "5",
            "--rules",
            "local",
            "--processes",
            "2",
            "--out",
            str(out),
            "--quiet",
            "--no-recording",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=run_env(),
    )

    def logged(node: str, text: str) -> bool:
        return any(
            text in (logs / f"{node}.log").read_text(errors="replace")
            for logs in tmp_path.glob(".run.logs-*")
            if (logs / f"{node}.log").exists()
        )

    try:  # what can be seen, not a delay: the world sent tick 0 and the monitor is ready to take it
        wait_for(
            lambda: logged("world", ": tick 0") and logged("monitor", ": ready,"), 120, "tick 0 with the monitor ready"
        )
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 130, err
    with open(out / "metrics.csv", newline="") as f:
        assert len(list(csv.reader(f))) - 1 >= 1  # tick 0 at least
    assert_bag_holds_run(out, interrupted=True)
    assert not list(tmp_path.glob(".run.bag-*")), "the hidden bag folder is gone"


def test_replay_publishes_the_bag_again_with_its_types_and_qos(ring_run, tmp_path):
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from sensor_msgs.msg import PointCloud2

    from swarm_ros.ros import graph as msgs
    from swarm_ros.ros.dds import dds_defaults

    domain = 180 + os.getpid() % 40
    env = {**run_env(), **dds_defaults()}
    saved = {k: os.environ.get(k) for k in env if k in dds_defaults()}
    os.environ.update(dds_defaults())  # this process's participant discovers as the replay's does
    # (if this process made a participant before, Fast DDS kept its first profile: announcing every 3 s; the replay
    # waits for the listener's two subscriptions to be matched before its first message)
    context = Context()
    rclpy.init(args=[], context=context, domain_id=domain)
    try:
        node = Node("replay_listener", context=context, start_parameter_services=False)
        robots, metrics = [], []
        topics = CentralTopics.of("darr-niazi")
        node.create_subscription(PointCloud2, topics.robots, robots.append, msgs.CENTRAL_QOS)
        node.create_subscription(PointCloud2, topics.metrics, metrics.append, msgs.CENTRAL_QOS)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        replay = subprocess.Popen(
            [
                PY,
                "-m",
                "swarm_ros",
                "replay",
                str(ring_run),
                "--domain-id",
                str(domain),
                "--rate",
                "0.5",
                "--wait-for-subscribers",
                "2",  # this listener's two topics: matched, however long discovery takes under load
                "--delay",
                "0",
                "--quiet",
            ],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env=env,
        )
        _, bagged = read_bag(ring_run / "bag")
        want = len(bagged[topics.metrics])

        def replayed() -> bool:
            executor.spin_once(timeout_sec=0.05)
            return replay.poll() is not None and len(metrics) >= want

        try:
            wait_for(replayed, 60, f"the replay's {want} metrics messages", poll=0)
        except AssertionError as exc:
            state = "ended" if replay.poll() is not None else "still ran"
            replay.kill()
            raise AssertionError(f"{exc}: {len(metrics)} heard, the replay {state}") from None
        _, err = replay.communicate(timeout=30)
        assert replay.returncode == 0, err
    finally:
        rclpy.shutdown(context=context)
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
    # every message again, as the bag holds it
    assert [bytes(m.data) for m in metrics] == [bytes(m.data) for m in bagged[topics.metrics]]
    assert [bytes(m.data) for m in robots] == [bytes(m.data) for m in bagged[topics.robots]]
    assert [m.header.stamp.sec for m in robots] == [m.header.stamp.sec for m in bagged[topics.robots]]


def test_replay_refuses_a_start_offset_past_the_bags_end_in_one_line(ring_run):
    done = subprocess.run(
        [PY, "-m", "swarm_ros", "replay", str(ring_run), "--start-offset", "100000", "--quiet"],
        capture_output=True,
        text=True,
        env=run_env(),
        timeout=60,
    )
    assert done.returncode == 2 and done.stderr.count("\n") == 1, done.stderr
    assert re.fullmatch(
        r"swarm-ros: error: --start-offset 100000 is past the bag's end \(it lasts [\d.]+ s\)\n", done.stderr
    ), done.stderr


@pytest.mark.parametrize("how", ["discard", "move_to"])
def test_a_bag_that_cannot_be_closed_leaves_no_hidden_folder(tmp_path, monkeypatch, how):
    """A full disk as the bag is closed: discarding it, or moving it beside the run, removes the hidden folder it
    was written in (no reader could open an unclosed bag)."""
    import errno

    from swarm_ros.ros.bag_writer import BagRecorder, central_topics

    bag = BagRecorder(tmp_path / "r", central_topics("darr-niazi"))
    assert bag.holder.is_dir() and bag.holder.name.startswith(".r.bag-")

    def full(*args) -> None:
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(bag.writer, "close", full)
    if how == "discard":
        bag.discard()
    else:
        assert bag.move_to(tmp_path / "r.partial-bag") is None
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_held_tick_reads_the_last_clock_a_monitor_made_durable(tmp_path):
    """What the tests and scripts/bench_faults.py watch a run's progress by: only what was made durable counts."""
    from swarm_ros.ros import graph as msgs
    from swarm_ros.ros.bag_writer import BagRecorder, central_topics, held_tick

    out = tmp_path / "run"
    holders = lambda: tmp_path.glob(".run.bag-*")
    bag = BagRecorder(out, recorded=central_topics("darr-niazi"))
    assert held_tick(holders()) == -1
    for tick in range(5):
        bag.write(msgs.CLOCK, msgs.clock_message(tick))
    assert held_tick(holders()) == -1  # written, not yet durable
    bag.durable()
    assert held_tick(holders()) == 4
    bag.discard()
