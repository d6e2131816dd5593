"""The graph over several hosts: Linux network namespaces on one switch (a bridge), talking UDP only.
Two hosts (the world and monitor on one, the robot batches on the other), and four hosts, each running
robot batches of its own (regions), the first also the world and the monitor. The result equals the
in-process engine's.

Needs root and iproute2 (``ip netns``); skipped, with the reason, where namespaces cannot
be made. Only this test's own namespaces are touched (named after its process id).

``SWARM_ROS_LAN_ROBOTS=100000`` runs the four-host tests with a disc of that many robots (50 ticks)
instead of its small ring: how docs/benchmarks.md's figures over four hosts were taken (minutes, not CI).
"""

from __future__ import annotations

import csv
import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest
from graph_runs import assert_same_run
from netns import SUBNET, host_env, ip_in
from runs import shape_file
from waiting import wait_for

from swarm_ros.app import cli
from swarm_ros.app.param_file import params_yaml
from swarm_ros.core.params import Settings
from swarm_ros.protocol.darr_niazi.rows import DECISION_ROW, ROBOT_ROW
from swarm_ros.protocol.runkey import KEY_ENV, new_key

pytestmark = pytest.mark.process

PY = sys.executable
LAN_ROBOTS = int(os.environ.get("SWARM_ROS_LAN_ROBOTS", "0"))  #: 0: the small ring


def _logs(tmp_path, procs, hosts: list[str], links: list[str]) -> str:
    """Each node's exit status (None: still running) and the end of its log, and the links' counters,
    for a failure's message."""
    logs = [
        f"--- {name} (exit {proc.poll()}):\n{(tmp_path / f'{name}.log').read_text()[-1500:]}"
        for name, (proc, _) in procs.items()
    ]
    return "\n".join(
        [
            *logs,
            *(
                f"--- {dev} in {ns}:\n{ip_in('-n', ns, '-s', 'link', 'show', 'dev', dev).stdout}"
                for ns, dev in zip(hosts, links)
            ),
        ]
    )


def _link_bytes(ns: str, dev: str) -> dict:
    return json.loads(ip_in("-n", ns, "-j", "-s", "link", "show", "dev", dev).stdout)[0]["stats64"]


def _run_on_hosts(tmp_path: Path, hosts: list[str], links: list[str], settings: Settings, plan, timeout: float):
    """Start ``plan``'s nodes ((host index, node name, module, extra arguments)) on their hosts with one
    parameter file of ``settings``, wait for the monitor to write the run and every node to exit 0; the run
    directory."""
    run = tmp_path / "run"
    params = tmp_path / "params.yaml"
    params.write_text(params_yaml(settings, {"world": {}, "monitor": {"out_dir": str(run)}}))
    # The environment each host gets, whole: nothing ROS or DDS that an earlier test set in this process
    # (a Fast DDS profile, a discovery range) leaks in. Discovery as docs/guides/several_hosts.md says for several
    # hosts: the subnet, plus each host's address as a static peer (unicast, should multicast be lost).
    env = host_env()
    net = int(links[0].removeprefix("swra")) % 250
    env.update(
        {
            "ROS_DOMAIN_ID": str(100 + os.getpid() % 100),
            "ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET",
            "ROS_STATIC_PEERS": ";".join(SUBNET.format(net, i + 1) for i in range(len(hosts))),
            "FASTDDS_BUILTIN_TRANSPORTS": "UDPv4",  # shared memory would bypass the namespaces
            "HOME": str(tmp_path),
            "ROS_LOG_DIR": str(tmp_path / "ros"),
            "PYTHONUNBUFFERED": "1",
            KEY_ENV: new_key(),
        }
    )  # one run key on every host (docs/guides/several_hosts.md)
    procs = {}
    try:
        for host, name, module, extra in plan:
            log = open(tmp_path / f"{name}.log", "w")
            procs[name] = (
                subprocess.Popen(
                    [
                        "ip",
                        "netns",
                        "exec",
                        hosts[host],
                        PY,
                        "-m",
                        f"swarm_ros.nodes.{module}",
                        "--ros-args",
                        "--params-file",
                        str(params),
                        "-r",
                        f"__node:={name}",
                        *extra,
                    ],
                    env=env,
                    stdout=log,
                    stderr=subprocess.STDOUT,
                ),
                log,
            )
        monitor = procs["monitor"][0]

        def ended() -> bool:  # the monitor's end, or a node that failed
            return monitor.poll() is not None or any(p.poll() not in (None, 0) for p, _ in procs.values())

        try:
            wait_for(ended, timeout, "the monitor's end", poll=0.1)
        except AssertionError as late:
            raise AssertionError(f"{late}\n{_logs(tmp_path, procs, hosts, links)}") from None
        assert monitor.poll() == 0, _logs(tmp_path, procs, hosts, links)
        wait_for(lambda: all(p.poll() is not None for p, _ in procs.values()), 30, "every node's exit", poll=0.1)
    finally:
        for proc, log in procs.values():
            if proc.poll() is None:
                proc.kill()
            proc.wait()
            log.close()
    codes = {name: p.returncode for name, (p, _) in procs.items()}
    assert codes == dict.fromkeys(procs, 0), _logs(tmp_path, procs, hosts, links)
    assert not any("public key" in (tmp_path / f"{name}.log").read_text() for name in procs)  # the run's key
    return run


def _batches(hosts: list[int], k: int) -> list[tuple]:
    """Batch b of ``k`` on host ``hosts[b]``."""
    return [
        (host, f"robot_batch_{b}", "robot_batch", ["-p", f"batch:={b}", "-p", f"batches:={k}"])
        for b, host in enumerate(hosts)
    ]


def _moving(ref: Path) -> list[int]:
    with open(ref / "metrics.csv", newline="") as f:
        return [int(row["moving"]) for row in csv.DictReader(f)]


def test_world_and_batches_on_two_hosts_over_udp_equal_the_in_process_engine(two_hosts, tmp_path):
    a, b, link = two_hosts
    shape = shape_file(tmp_path / "ring.txt", outer=12.5, hole=5)
    # rules 'local': a run of a few hundred ticks, so that most of a megabyte crosses the link
    flags = ["--shape", str(shape), "--world-radius", "16", "--seed", "7", "--robots", "440", "--rules", "local"]
    ref = tmp_path / "ref"
    assert cli.main(["simulate", *flags, "--out", str(ref), "--quiet"]) == 0
    settings = Settings(shape=str(shape), robots=440, seed=7, world_radius=16, rules="local")
    plan = [(0, "world", "world", []), (0, "monitor", "monitor", []), *_batches([1, 1], 2)]
    run = _run_on_hosts(tmp_path, [a, b], [link, "swrb" + link.removeprefix("swra")], settings, plan, 120)
    world_log = (tmp_path / "world.log").read_text()
    assert "robot_batch_0: columns" in world_log and "robot_batch_1: columns" in world_log
    assert_same_run(ref, run, launched=False)
    # and the traffic really crossed the link between the hosts. Lower bounds that must hold:
    # host A received every decision row (one per moving robot per tick) from host B, and sent
    # each batch its start snapshot of every robot.
    stats = _link_bytes(a, link)
    assert stats["rx"]["bytes"] >= DECISION_ROW.itemsize * sum(_moving(ref)[:-1]), stats
    assert stats["tx"]["bytes"] >= 2 * ROBOT_ROW.itemsize * 440, stats


def _four_host_case(tmp_path: Path) -> tuple[Settings, Path, float, float]:
    """The four-host tests' run: the small ring, or by hand (``SWARM_ROS_LAN_ROBOTS``) a disc of that many robots at
    the star's density for 50 ticks; with its reference (``simulate``'s run directory), the seconds ``simulate``
    took and the graph's timeout."""
    if LAN_ROBOTS:
        sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "scripts"))
        from bench_scale import disc_file

        shape, radius = disc_file(LAN_ROBOTS, tmp_path)
        settings = Settings(shape=str(shape), world_radius=radius, seed=1, max_ticks=50)
        flags = ["--shape", str(shape), "--world-radius", str(radius), "--seed", "1", "--max-ticks", "50"]
        timeout = 60 + LAN_ROBOTS / 500
    else:
        shape = shape_file(tmp_path / "ring.txt", outer=12.5, hole=5)
        settings = Settings(shape=str(shape), robots=440, seed=7, world_radius=16, rules="local")
        flags = ["--shape", str(shape), "--world-radius", "16", "--seed", "7", "--robots", "440", "--rules", "local"]
        timeout = 150
    ref = tmp_path / "ref"
    began = time.perf_counter()
    assert cli.main(["simulate", *flags, "--out", str(ref), "--quiet"]) == 0
    return settings, ref, time.perf_counter() - began, timeout


def _say_times(what: str, simulated: float, began: float, run: Path) -> None:
    print(
        f"{what}: simulate {simulated:.1f} s, the graph {time.perf_counter() - began:.1f} s "
        f"(run {json.loads((run / 'summary.json').read_text())['wall_seconds']:.2f} s)"
    )


def test_four_hosts_each_hosting_regions_equal_the_in_process_engine(four_hosts, tmp_path):
    """Four strips, one robot batch on each host (host 0 also runs the world and the monitor): every host
    decides for its region, and the run equals ``simulate``'s, byte for byte."""
    hosts, links = four_hosts
    settings, ref, simulated, timeout = _four_host_case(tmp_path)
    before = [_link_bytes(ns, dev) for ns, dev in zip(hosts, links)]
    began = time.perf_counter()
    run = _run_on_hosts(
        tmp_path,
        hosts,
        links,
        settings,
        [(0, "world", "world", []), (0, "monitor", "monitor", []), *_batches([0, 1, 2, 3], 4)],
        timeout,
    )
    _say_times("four hosts", simulated, began, run)
    world_log = (tmp_path / "world.log").read_text()
    assert all(f"robot_batch_{b}: columns" in world_log for b in range(4))
    assert_same_run(ref, run, launched=False)
    # every other host took rows from host 0 and sent it decisions: each sent at least its robots' decisions
    # for the ticks where a quarter of the swarm moved in its strip, and received more than its snapshot's rows
    robots = json.loads((ref / "summary.json").read_text())["robots"]
    for i in (1, 2, 3):
        after = _link_bytes(hosts[i], links[i])
        sent = after["tx"]["bytes"] - before[i]["tx"]["bytes"]
        got = after["rx"]["bytes"] - before[i]["rx"]["bytes"]
        assert sent > DECISION_ROW.itemsize * math.floor(robots / 8), (i, sent)
        assert got > ROBOT_ROW.itemsize * math.floor(robots / 8), (i, got)


def test_four_hosts_each_with_a_world_shard_and_its_batch_equal_the_in_process_engine(four_hosts, tmp_path):
    """Four strips, four world shards: host i runs robot batch i and world shard i, which owns its strip (host 0
    also the monitor). The world's checks and apply happen on every host, the shards settle the claims near
    their borders over the links, and the run equals ``simulate``'s, byte for byte."""
    hosts, links = four_hosts
    settings, ref, simulated, timeout = _four_host_case(tmp_path)
    shards = [
        (i, f"world_shard_{i}", "world_shard", ["-p", f"shard:={i}", "-p", "shards:=4", "-p", "batches:=4"])
        for i in range(4)
    ]
    monitor = (0, "monitor", "monitor", ["-p", "world_shards:=4"])
    began = time.perf_counter()
    run = _run_on_hosts(tmp_path, hosts, links, settings, [*shards, monitor, *_batches([0, 1, 2, 3], 4)], timeout)
    _say_times("four hosts, four world shards", simulated, began, run)
    for i in range(4):
        log = (tmp_path / f"world_shard_{i}.log").read_text()
        assert f"robot_batch_{i}: columns" in log and "tick 0" in log, log[-2000:]
    assert_same_run(ref, run, launched=False)
