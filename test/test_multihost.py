"""The graph over two hosts: the world and monitor in one Linux network namespace, the robot batches
in another, joined by a veth pair, talking UDP only. The result equals the in-process engine's.

Needs root and iproute2 (``ip netns``); skipped, with the reason, where namespaces cannot
be made. Only this test's own namespaces are touched (named after its process id).
"""

from __future__ import annotations

import csv
import json
import os
import subprocess
import sys
import time

import pytest
from helpers import SUBNET, host_env, ip_in
from test_ros_graph import _assert_same_run, _shape_file

from swarm_ros.app import cli
from swarm_ros.core.params import Settings
from swarm_ros.protocol.rows import DECISION_ROW, ROBOT_ROW
from swarm_ros.protocol.runkey import KEY_ENV, new_key
from swarm_ros.ros.node_params import params_yaml

pytestmark = pytest.mark.process

PY = sys.executable


def _logs(tmp_path, procs, link: str) -> str:
    """Each node's exit status (None: still running) and the end of its log, and the link's counters,
    for a failure's message."""
    logs = [f"--- {name} (exit {proc.poll()}):\n{(tmp_path / f'{name}.log').read_text()[-1500:]}"
            for name, (proc, _) in procs.items()]
    ns = "swarm_ros_a" + link.removeprefix("swra")
    return "\n".join([*logs, f"--- {link} in {ns}:\n{ip_in('-n', ns, '-s', 'link', 'show', 'dev', link).stdout}"])


def test_world_and_batches_on_two_hosts_over_udp_equal_the_in_process_engine(two_hosts, tmp_path):
    a, b, link = two_hosts
    shape = _shape_file(tmp_path / "ring.txt", outer=12.5, hole=5)
    # rules 'local': a run of a few hundred ticks, so that most of a megabyte crosses the link
    flags = ["--shape", str(shape), "--world-radius", "16", "--seed", "7", "--robots", "440", "--rules", "local"]
    ref = tmp_path / "ref"
    assert cli.main(["simulate", *flags, "--out", str(ref), "--quiet"]) == 0
    run = tmp_path / "run"
    params = tmp_path / "params.yaml"
    params.write_text(params_yaml(Settings(shape=str(shape), robots=440, seed=7, world_radius=16, rules="local"),
                                  {"world": {}, "monitor": {"out_dir": str(run)}}))
    # The environment each host gets, whole: nothing ROS or DDS that an earlier test set in this process
    # (a Fast DDS profile, a discovery range) leaks in. Discovery as docs/ros_graph.md says for several
    # hosts: the subnet, plus each host's address as a static peer (unicast, should multicast be lost).
    env = host_env()
    net = int(link.removeprefix("swra")) % 250
    env.update({"ROS_DOMAIN_ID": str(100 + os.getpid() % 100), "ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET",
                "ROS_STATIC_PEERS": f"{SUBNET.format(net, 1)};{SUBNET.format(net, 2)}",
                "FASTDDS_BUILTIN_TRANSPORTS": "UDPv4",  # shared memory would bypass the namespaces
                "HOME": str(tmp_path), "ROS_LOG_DIR": str(tmp_path / "ros"), "PYTHONUNBUFFERED": "1",
                KEY_ENV: new_key()})  # one run key on both hosts (docs/ros_graph.md, Several hosts)
    plan = [(a, "world", "world", []), (a, "monitor", "monitor", []),
            (b, "robot_batch_0", "robot_batch", ["-p", "batch:=0", "-p", "batches:=2"]),
            (b, "robot_batch_1", "robot_batch", ["-p", "batch:=1", "-p", "batches:=2"])]
    procs = {}
    try:
        for ns, name, module, extra in plan:
            log = open(tmp_path / f"{name}.log", "w")  # noqa: SIM115 - closed with the process
            procs[name] = (subprocess.Popen(["ip", "netns", "exec", ns, PY, "-m", f"swarm_ros.nodes.{module}",
                                             "--ros-args", "--params-file", str(params), "-r", f"__node:={name}",
                                             *extra], env=env, stdout=log, stderr=subprocess.STDOUT), log)
        monitor = procs["monitor"][0]
        deadline = time.monotonic() + 120  # the run takes a few seconds; a node that failed ends the wait
        while monitor.poll() is None and time.monotonic() < deadline and \
                not any(p.poll() not in (None, 0) for p, _ in procs.values()):
            time.sleep(0.1)
        assert monitor.poll() == 0, _logs(tmp_path, procs, link)
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline and any(p.poll() is None for p, _ in procs.values()):
            time.sleep(0.1)
    finally:
        for proc, log in procs.values():
            if proc.poll() is None:
                proc.kill()
            proc.wait()
            log.close()
    codes = {name: p.returncode for name, (p, _) in procs.items()}
    assert codes == dict.fromkeys(procs, 0), _logs(tmp_path, procs, link)
    world_log = (tmp_path / "world.log").read_text()
    assert "robot_batch_0 hosts" in world_log and "robot_batch_1 hosts" in world_log
    assert not any("public key" in (tmp_path / f"{name}.log").read_text() for name in procs)  # the run's key
    _assert_same_run(ref, run, launched=False)
    # and the traffic really crossed the link between the hosts. Lower bounds that must hold:
    # host A received every decision row (one per moving robot per tick) from host B, and sent
    # each batch its start snapshot of every robot.
    with open(ref / "metrics.csv", newline="") as f:
        moving = [int(row["moving"]) for row in csv.DictReader(f)]
    stats = json.loads(ip_in("-n", a, "-j", "-s", "link", "show", "dev", link).stdout)[0]["stats64"]
    assert stats["rx"]["bytes"] >= DECISION_ROW.itemsize * sum(moving[:-1]), stats
    assert stats["tx"]["bytes"] >= 2 * ROBOT_ROW.itemsize * 440, stats
