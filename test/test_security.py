"""Hostile and malformed messages on a run's domain (docs/security.md).

The world and the monitor run as processes; this test process plays the two robot
batches, deciding honestly with the core's own rule, and before its honest decisions of
a tick sends bad messages of two sorts: malformed or illegal ones tagged with the
run's key (a buggy node of the run), and well-formed ones with no valid tag (an outsider
on the domain). Every bad message must be dropped and counted, and the run must equal
``simulate``'s, byte for byte.
"""

from __future__ import annotations

import ast
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from netns import host_env
from runs import make_cloud

from swarm_ros.app import cli
from swarm_ros.app.param_file import params_yaml
from swarm_ros.app.processes import DomainLock, node_command, node_env
from swarm_ros.core.errors import Rejected
from swarm_ros.core.params import Settings
from swarm_ros.core.regions import batch_strip, columns
from swarm_ros.core.state import RobotState
from swarm_ros.protocol.rows import DECISION_ROW, ROBOT_ROW, batch_label, compact, decision_rows
from swarm_ros.protocol.runkey import KEY_ENV

pytest.importorskip("rclpy")

pytestmark = pytest.mark.process

PY = sys.executable
ROBOTS, SEED = 200, 4
FLAGS = ["--shape", "rectangle", "--robots", str(ROBOTS), "--seed", str(SEED)]


class _Batches:
    """Two robot batches in this process, honest but for the bad messages ``attack`` sends."""

    def __init__(self, node, shape, params, key: bytes) -> None:
        from diagnostic_msgs.msg import DiagnosticArray
        from sensor_msgs.msg import PointCloud2
        from std_msgs.msg import Empty

        from swarm_ros.core.rules import Decider
        from swarm_ros.core.swarm_view import SwarmView
        from swarm_ros.protocol.checks import Rejections
        from swarm_ros.protocol.tag import Sealer
        from swarm_ros.ros import graph as msgs
        from swarm_ros.ros.auth import Gate, SignedPublisher, Signer

        self.msgs, self.node, self.params, self.shape = msgs, node, params, shape
        self.view, self.decider = SwarmView(shape, params.robots), Decider(shape, params)
        self.radius = shape.world.radius
        self.names = ["robot_batch_0", "robot_batch_1"]
        self.strips = [batch_strip(shape, params, k, 2) for k in range(2)]
        # tagged with the run's key, as the run's own nodes do
        signers = [Signer(node, key, n) for n in self.names]
        self.pubs = [
            signers[k].publisher(PointCloud2, msgs.decisions_topic(n), msgs.DECISIONS_QOS)
            for k, n in enumerate(self.names)
        ]
        self.alive = [node.create_publisher(Empty, msgs.alive_topic(n), msgs.ALIVE_QOS) for n in self.names]
        self.announce = [signer.publisher(msgs.Int64MultiArray, msgs.BATCHES, msgs.BATCHES_QOS) for signer in signers]
        # a key holder's announcements on the last batch's writer: DDS keeps one writer's order, so the world
        # hears the genuine batches first (from two writers, the intruder's could come first and take its columns)
        self.intruder = SignedPublisher(Sealer(key, "intruder"), self.announce[-1].pub, msgs.BATCHES)
        self.robots_pub = Signer(node, key, "world").publisher(PointCloud2, msgs.ROBOTS, msgs.ROBOTS_QOS)
        self.held_pub = Signer(node, key, "monitor").publisher(msgs.Int64MultiArray, msgs.HELD, msgs.LATCHED_QOS)
        # an outsider's: well-formed messages without a valid tag
        self.forged = {
            topic: node.create_publisher(kind, topic, qos)
            for topic, kind, qos in (
                (msgs.decisions_topic(self.names[0]), PointCloud2, msgs.DECISIONS_QOS),
                (msgs.BATCHES, msgs.Int64MultiArray, msgs.BATCHES_QOS),
                (msgs.HELD, msgs.Int64MultiArray, msgs.LATCHED_QOS),
                (msgs.STATUS, DiagnosticArray, msgs.LATCHED_QOS),
                (msgs.ROBOTS, PointCloud2, msgs.ROBOTS_QOS),
            )
        }
        self.world_rows: list = []  # the world's, serialized, as an outsider records them (to replay one)
        node.create_subscription(PointCloud2, msgs.ROBOTS, self.world_rows.append, msgs.ROBOTS_QOS, raw=True)
        # these batches take only what the world's tag proves, as the run's own do
        gate = Gate(node, key, Rejections(node.get_logger()))
        gate.subscribe(PointCloud2, msgs.ROBOTS, self._on_robots, msgs.ROBOTS_QOS)
        self.gate = gate
        self.sent: dict[str, int] = {}  # kind of bad message -> how many were sent to the world / the monitor
        # before the batches' own: an outsider's announcement of batch 1's robots under another name
        forged = msgs.ids_message(np.array(self.strips[1]))
        forged.layout.dim[0].label = "impostor/0"
        self.forged[msgs.BATCHES].publish(forged)
        self.sent["world: untagged announcement"] = 1
        for k, name in enumerate(self.names):
            hello = msgs.ids_message(np.array(self.strips[k]))
            hello.layout.dim[0].label = batch_label(name, 0)
            self.announce[k].publish(hello)
        hello = msgs.ids_message(np.array([self.strips[1][0]] * 2))  # before tick 0: another batch's column
        hello.layout.dim[0].label = "intruder/0"
        self.intruder.publish(hello)
        self.sent["world: columns of another batch"] = 1
        self.localized_sent = False

    def _on_robots(self, msg) -> None:
        from swarm_ros.protocol.checks import apply_robots, checked_robots

        try:  # the whole swarm's rows from tick 0 (these batches keep a whole view, not regional ones)
            tick, rows = checked_robots(self.view, msg, self.radius)
            if tick != self.view.tick + 1:
                return
            apply_robots(self.view, tick, rows)
        except Rejected:
            return  # the garbage this test sends on /swarm/robots itself
        if tick == 5:  # an outsider's copy of the world's rows, restamped as the next tick's, before them
            copy = make_cloud(rows.copy(), tick + 1)
            self.forged[self.msgs.ROBOTS].publish(copy)
            self.sent["monitor: untagged rows"] = 1
        self._decide()

    def _cloud(self, rows: np.ndarray, tick: int):
        return make_cloud(rows, tick)

    def _send(self, kind: str, k: int, msg) -> None:
        self.pubs[k].publish(msg)
        self.sent[f"world: {kind}"] = self.sent.get(f"world: {kind}", 0) + 1

    def _decide(self) -> None:
        s = self.view.state
        moving = self.view.moving_ids()
        tick = self.view.tick + 1
        honest = []
        cols = columns(s.x[moving], self.radius)
        for k in range(2):
            own = moving[(cols >= self.strips[k][0]) & (cols <= self.strips[k][1])]
            honest.append(decision_rows(self.decider.decide(s, own, tick, moving)) if own.size else None)
        self.attack(tick, honest)
        for k in range(2):
            if honest[k] is not None:
                self.pubs[k].publish(self._cloud(honest[k], tick))
        if tick == 12 and honest[0] is not None:  # the same decisions again: once per robot and tick
            self._send("duplicate", 0, self._cloud(honest[0], tick))

    def attack(self, tick: int, honest: list) -> None:
        """One kind of bad message per tick, sent before the honest decisions of that tick."""
        from sensor_msgs.msg import PointField

        mine = honest[0]
        if tick == 2:  # another point layout
            msg = self._cloud(mine, tick)
            msg.fields = [PointField(name="a", offset=0, datatype=7, count=1)]
            msg.point_step = 13
            self._send("point layout", 0, msg)
        elif tick == 3:  # the right layout, nonsense rows
            rows = np.zeros(3, dtype=DECISION_ROW)
            rows["id"] = [10**9, 5, 6]
            rows["claim"] = [10**8, -1, -1]
            rows["x"], rows["y"] = [np.nan, 1e300, -1e300], [0.0, np.inf, 0.0]
            self._send("nonsense rows", 0, self._cloud(rows, tick))
        elif tick == 4:  # empty
            self._send("empty", 0, self._cloud(np.zeros(0, dtype=DECISION_ROW), tick))
        elif tick == 5:  # data shorter than width x point_step
            msg = self._cloud(mine, tick)
            msg.data = bytes(msg.data)[: len(msg.data) // 2]
            self._send("short data", 0, msg)
        elif tick == 6:  # a future tick, and a stale one
            self._send("future tick", 0, self._cloud(mine, tick + 3))
            self._send("stale tick", 0, self._cloud(mine, tick - 1))
        elif tick == 7:  # well-formed rows for robots 100-104 at (5, 5): not where they are
            rows = np.zeros(5, dtype=DECISION_ROW)
            rows["id"], rows["claim"], rows["x"], rows["y"], rows["heading"] = np.arange(100, 105), -1, 5.0, 5.0, 0.0
            self._send("robots 100-104 jump", 0, self._cloud(rows, tick))
        elif tick == 8:  # batch 1's robots on batch 0's topic
            self._send("wrong batch", 0, self._cloud(honest[1], tick))
        elif tick == 9:  # a move of 5 patches
            rows = mine.copy()
            rows["x"][0] += 5.0
            self._send("move of 5", 0, self._cloud(rows, tick))
        elif tick == 10:  # a claim on a shape patch off the frontier
            s = self.view.state
            off = int(np.flatnonzero(self.shape.mask.ravel() & ~s.frontier & (s.occupancy < 0))[0])
            rows = mine[:1].copy()
            rows["claim"] = off
            self._send("claim off the frontier", 0, self._cloud(rows, tick))
        elif tick == 11:  # a seed (not moving, and no batch's)
            rows = mine[:1].copy()
            rows["id"] = 0
            self._send("a seed", 0, self._cloud(rows, tick))
        elif tick == 13:  # a new batch claiming robots, after tick 0
            hello = self.msgs.ids_message(np.array(self.strips[0]))
            hello.layout.dim[0].label = "intruder/0"
            self.intruder.publish(hello)
            self.sent["world: announcement"] = 1
        elif tick == 14:  # the monitor's report of a tick the world has not reached
            self.held_pub.publish(self.msgs.held_message(10**6, False))
            self.sent["world: held"] = 1
        elif tick >= 16 and not self.localized_sent:  # a localized robot of the batch, once there is one
            s = self.view.state
            localized = np.flatnonzero(s.state == RobotState.LOCALIZED)
            if localized.size:
                rows = np.zeros(1, dtype=DECISION_ROW)
                rows["id"], rows["claim"] = localized[0], -1
                rows["x"], rows["y"] = s.x[localized[0]], s.y[localized[0]]
                self._send("localized robot", 0, self._cloud(rows, tick))
                self.localized_sent = True
        if tick == 15:  # garbage on /swarm/robots, for the monitor (and the batches)
            msg = self._cloud(np.zeros(2, dtype=ROBOT_ROW), tick)
            msg.point_step = 13
            self.robots_pub.publish(msg)
            rows = np.zeros(2, dtype=ROBOT_ROW)
            rows["id"], rows["state"] = [10**6, 3], [1, 9]
            self.robots_pub.publish(self._cloud(rows, tick))
            self.sent["monitor: robots"] = 2
        self.forge(tick, honest)

    def forge(self, tick: int, honest: list) -> None:
        """An outsider's messages: well-formed, legal, consistent, but without a valid tag."""
        if tick == 2 and honest[0] is not None:  # batch 0's decisions, turned, before its own
            rows = honest[0].copy()
            rows["heading"] = (rows["heading"] + 1.0) % (2 * np.pi)
            self.forged[self.msgs.decisions_topic(self.names[0])].publish(self._cloud(rows, tick))
            self.sent["world: untagged decisions"] = 1
        elif tick == 3:  # the monitor's report of a tick the world published
            self.forged[self.msgs.HELD].publish(self.msgs.held_message(tick - 1, False))
            self.sent["world: untagged held"] = 1
        elif tick == 4:  # the world's status, with an outcome
            self.forged[self.msgs.STATUS].publish(self.msgs.status_message(tick, "complete", "complete"))
            self.sent["monitor: untagged status"] = 1
        elif tick == 6 and self.world_rows:  # the world's rows of an earlier tick, tag and all, again
            self.forged[self.msgs.ROBOTS].publish(self.world_rows[-2])
            self.sent["monitor: replayed rows"] = 1


def test_bad_messages_are_dropped_and_counted_and_the_run_equals_simulate(tmp_path, monkeypatch):
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node

    from swarm_ros.ros.dds import dds_defaults

    ref = tmp_path / "ref"
    assert cli.main(["simulate", *FLAGS, "--out", str(ref), "--quiet", "--no-recording"]) == 0
    settings = Settings(shape="rectangle", robots=ROBOTS, seed=SEED)
    shape, params = settings.resolve()
    out = tmp_path / "run"
    params_file = tmp_path / "params.yaml"
    params_file.write_text(params_yaml(settings, {"monitor": {"out_dir": str(out), "record": False}}))
    lock = DomainLock()
    env = node_env(lock.domain_id, tmp_path)
    procs = {
        name: subprocess.Popen(
            node_command(name, params_file, name), env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
        )
        for name in ("world", "monitor")
    }
    for key, value in dds_defaults().items():
        monkeypatch.setenv(key, value)
    context = Context()
    rclpy.init(args=[], context=context, domain_id=lock.domain_id)
    try:
        node = Node("robot_batches", context=context, start_parameter_services=False)
        batches = _Batches(node, shape, params, env[KEY_ENV].encode())
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and procs["monitor"].poll() is None:
            executor.spin_once(timeout_sec=0.05)
    finally:
        rclpy.shutdown(context=context)
        for proc in procs.values():
            if proc.poll() is None:
                proc.kill()
        logs = {name: proc.communicate()[0] for name, proc in procs.items()}
        lock.close()
    assert {n: p.returncode for n, p in procs.items()} == {"world": 0, "monitor": 0}, "\n".join(
        f"--- {n}:\n{text[-3000:]}" for n, text in logs.items()
    )
    assert batches.view.tick > 15, "the run ended before every kind of bad message was sent"
    for name in ("metrics.csv", "final_state.csv"):
        assert (ref / name).read_bytes() == (out / name).read_bytes(), name
    summary = json.loads((out / "summary.json").read_text())
    to_world = sum(n for kind, n in batches.sent.items() if kind.startswith("world: "))
    to_monitor = sum(n for kind, n in batches.sent.items() if kind.startswith("monitor: "))
    assert to_world == 19 and to_monitor == 5, batches.sent
    assert summary["rejected_messages"] == {"world": to_world, "monitor": to_monitor}, (batches.sent, logs["world"])
    assert "dropped a message on /swarm/decisions/robot_batch_0 (point layout" in logs["world"]
    assert "dropped a message on /swarm/robots" in logs["monitor"]
    assert "dropped a message on /swarm/decisions/robot_batch_0 (unauthenticated" in logs["world"]
    assert "dropped a message on /swarm/status (unauthenticated" in logs["monitor"]
    assert "dropped a message on /swarm/robots (replayed" in logs["monitor"]


def test_sros2_enclaves_reach_every_node_and_the_run_is_unchanged(tmp_path):
    """swarm-ros run --enclaves: every node process starts with its enclave, and with DDS security off
    (this ROS 2 build has none) rcl accepts the argument and the run is the same. What SROS2 does with
    the enclaves cannot be tried here (docs/security.md)."""
    from swarm_ros.app.launcher import Launch

    ref = tmp_path / "ref"
    assert cli.main(["simulate", *FLAGS, "--out", str(ref), "--quiet", "--no-recording"]) == 0
    settings = Settings(shape="rectangle", robots=ROBOTS, seed=SEED)
    shape, params = settings.resolve()
    launch = Launch(
        settings=settings,
        shape=shape,
        params=params,
        processes=2,
        out=tmp_path / "run",
        quiet=True,
        bag=False,
        enclaves="/swarm_ros",
    )
    out = launch.run()
    for name in ("metrics.csv", "final_state.csv"):
        assert (ref / name).read_bytes() == (out / name).read_bytes(), name
    assert {c.name: c.command[c.command.index("--enclave") + 1] for c in launch.children} == {
        name: f"/swarm_ros/{name}" for name in ("monitor", "robot_batch_0", "robot_batch_1", "world")
    }


_INTRUDER = """
import sys, time
import rclpy
from rclpy.node import Node
rclpy.init(domain_id=int(sys.argv[1]))
node = Node("intruder")
print("ready", flush=True)
seen, end = set(), time.monotonic() + float(sys.argv[2])
while time.monotonic() < end:
    rclpy.spin_once(node, timeout_sec=0.1)
    seen |= {name for name, _ in node.get_topic_names_and_types() if name.startswith("/swarm")}
print(sorted(seen))
"""


@pytest.mark.parametrize("discovery,seen", [("LOCALHOST", False), ("SUBNET", True)])
def test_a_one_host_run_is_not_discovered_from_another_network_namespace(two_hosts, tmp_path, discovery, seen):
    """A run on host A, with swarm-ros run's default discovery (LOCALHOST), and an intruder on host B,
    joined by a veth pair, on the run's domain with discovery open to the subnet: the intruder sees
    none of the run's topics. The control, the same run with SUBNET discovery, shows that it would."""
    a, b, _ = two_hosts
    domain = str(120 + os.getpid() % 80)
    common = {**host_env(), "ROS_DOMAIN_ID": domain, "FASTDDS_BUILTIN_TRANSPORTS": "UDPv4", "HOME": str(tmp_path)}
    # the intruder announces itself every 50 ms for its first 5 s (the run's own Fast DDS profile)
    intruder_env = {
        **common,
        "ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET",
        "FASTRTPS_DEFAULT_PROFILES_FILE": str(Path(__file__).parent.parent / "config" / "fastdds.xml"),
    }
    run_env = {**common, **({"ROS_AUTOMATIC_DISCOVERY_RANGE": discovery} if discovery != "LOCALHOST" else {})}
    intruder = subprocess.Popen(
        ["ip", "netns", "exec", b, PY, "-c", _INTRUDER, domain, "10"],
        env=intruder_env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    assert intruder.stdout is not None and intruder.stdout.readline().strip() == "ready"  # its participant is up
    run = subprocess.Popen(
        [
            "ip",
            "netns",
            "exec",
            a,
            PY,
            "-m",
            "swarm_ros",
            "run",
            *FLAGS,
            "--out",
            str(tmp_path / "run"),
            "--quiet",
            "--no-recording",
            "--no-bag",
        ],
        env=run_env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        _, err = run.communicate(timeout=120)
        out, intruder_err = intruder.communicate(timeout=60)
    finally:
        for proc in (run, intruder):
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    assert run.returncode == 0, err
    assert intruder.returncode == 0, intruder_err
    topics = ast.literal_eval(out.strip().splitlines()[-1])  # the list the script printed
    assert ("/swarm/robots" in topics) == seen, (topics, intruder_err[-2000:], domain)
    if not seen:
        assert topics == []


def test_a_stranger_without_the_key_is_kept_out_by_real_batches_and_the_monitor(tmp_path, monkeypatch):
    """swarm-ros run as a user starts it (a new key for the run), and a stranger on its domain that
    reads the run's messages and sends, without a valid tag: malformed rows; every tick's rows again,
    restamped as the next tick's (consistent, and before the world's); a batch's snapshot restamped
    later; a status with an outcome. Each would change the run if taken. Every node drops them, and
    the run equals simulate's."""
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from sensor_msgs.msg import PointCloud2

    from swarm_ros.ros import graph as msgs
    from swarm_ros.ros.dds import dds_defaults

    flags = ["--shape", "star", "--seed", "2"]
    ref, out = tmp_path / "ref", tmp_path / "run"
    assert cli.main(["simulate", *flags, "--out", str(ref), "--quiet", "--no-recording"]) == 0
    # paced (results unchanged): the run's 400 ticks last 5 s or more, so the stranger, which discovers the run's
    # processes as they start, is matched with them long before the end even on a loaded machine (unpaced, the
    # run took 1.5 s, and CI saw the stranger matched with none of its writers, or the monitor only after the end)
    paced = tmp_path / "paced.yaml"
    paced.write_text("/world:\n  ros__parameters:\n    tick_rate: 80.0\n")
    lock = DomainLock()
    run = subprocess.Popen(
        [
            PY,
            "-m",
            "swarm_ros",
            "run",
            *flags,
            "--params-file",
            str(paced),
            "--domain-id",
            str(lock.domain_id),
            "--out",
            str(out),
            "--quiet",
            "--no-recording",
            "--no-bag",
            "--processes",
            "2",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    for key, value in dds_defaults().items():
        monkeypatch.setenv(key, value)
    context = Context()
    rclpy.init(args=[], context=context, domain_id=lock.domain_id)
    sent: dict[str, int] = {}
    try:
        node = Node("stranger", context=context, start_parameter_services=False)
        pub = node.create_publisher(PointCloud2, msgs.ROBOTS, msgs.ROBOTS_QOS)
        # the batches take rows only from their region topics: the same forgeries go there
        region_pubs = [
            node.create_publisher(PointCloud2, msgs.region_topic(f"robot_batch_{k}"), msgs.ROBOTS_QOS) for k in range(2)
        ]
        snapshot_pub = node.create_publisher(PointCloud2, msgs.snapshot_topic("robot_batch_0"), msgs.LATCHED_QOS)
        status_pub = node.create_publisher(DiagnosticArray, msgs.STATUS, msgs.LATCHED_QOS)

        def count(kind: str) -> None:
            sent[kind] = sent.get(kind, 0) + 1

        def on_robots(msg) -> None:  # the world's rows of tick t, sent again as tick t + 1's
            try:
                rows = msgs.cloud_rows(msg, ROBOT_ROW)
            except Rejected:
                return  # this stranger's own garbage, back
            if rows.size and rows["z"][0] == 0.0 and rows["id"][0] != 7:  # not ours (they come back here)
                copy = rows.copy()
                copy["z"] = 0.5
                pub.publish(make_cloud(copy, msgs.tick_of(msg.header) + 1))
                for region in region_pubs:
                    region.publish(make_cloud(compact(rows), msgs.tick_of(msg.header) + 1))
                count("rows of the next tick")

        def on_snapshot(msg) -> None:  # the world's snapshot for robot_batch_0, as a later tick's
            if msgs.tick_of(msg.header) < 50:
                msg.header.stamp = msgs.stamp(msgs.tick_of(msg.header) + 50)
                snapshot_pub.publish(msg)
                count("snapshot")

        node.create_subscription(PointCloud2, msgs.ROBOTS, on_robots, msgs.ROBOTS_QOS)
        node.create_subscription(PointCloud2, msgs.snapshot_topic("robot_batch_0"), on_snapshot, msgs.LATCHED_QOS)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        while run.poll() is None:
            bad = make_cloud(np.zeros(3, dtype=ROBOT_ROW), 10**6)
            bad.point_step = 13  # another layout
            pub.publish(bad)
            rows = np.zeros(2, dtype=ROBOT_ROW)
            rows["id"], rows["x"] = [7, 7], [np.nan, 1e300]  # a repeated robot, off the world
            pub.publish(make_cloud(rows, 1))
            for region in region_pubs:
                region.publish(bad)
                region.publish(make_cloud(compact(rows), 1))
            status_pub.publish(msgs.status_message(1, "complete", "complete at tick 1"))
            count("garbage and status")
            end = time.monotonic() + 0.05
            while time.monotonic() < end:
                executor.spin_once(timeout_sec=0.01)
        _, err = run.communicate(timeout=120)
    finally:
        rclpy.shutdown(context=context)
        if run.poll() is None:
            run.kill()
            run.wait()
        lock.close()
    assert run.returncode == 0, err
    assert sent.get("garbage and status", 0) >= 10 and sent.get("rows of the next tick", 0) >= 100, sent
    assert sent.get("snapshot") == 1, sent  # robot_batch_0's tick-0 snapshot (the forgery comes back as tick 50)
    for name in ("metrics.csv", "final_state.csv"):
        assert (ref / name).read_bytes() == (out / name).read_bytes(), name
    assert json.loads((out / "summary.json").read_text())["rejected_messages"]["monitor"] >= 20
    for node_name in ("robot_batch_0", "robot_batch_1", "monitor"):
        log = (out / "logs" / f"{node_name}.log").read_text()
        rows = msgs.ROBOTS if node_name == "monitor" else msgs.region_topic(node_name)
        for topic in (rows, msgs.STATUS):
            assert f"dropped a message on {topic} (unauthenticated" in log, (node_name, topic)
    assert (
        "dropped a message on /swarm/snapshot/robot_batch_0 (unauthenticated"
        in (out / "logs" / "robot_batch_0.log").read_text()
    )
