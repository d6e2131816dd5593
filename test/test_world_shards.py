"""World shards over the ROS 2 graph (``swarm-ros run --world-shards S``): the run is simulate's, byte for byte,
its bag holds every tick's S parts, and a world shard SIGKILLed in the middle of the run is restarted from its
save and changes nothing the run writes but ``restarts``."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from helpers import finish_restarted_run, node_pid, run_env, wait_ticks_recorded

from swarm_ros.app import cli

pytestmark = pytest.mark.process


#: the star under the local join rule with 700 robots: about 800 ticks, a few seconds over the graph
MID = ["--shape", "star", "--robots", "700", "--seed", "5", "--rules", "local"]


@pytest.fixture(scope="module")
def reference(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("shards-ref") / "ref"
    assert cli.main(["simulate", *MID, "--out", str(out), "--quiet", "--no-recording"]) == 0
    return out


def _launch(out: Path, shards: int, *extra: str) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "swarm_ros", "run", *MID, "--processes", "4", "--world-shards", str(shards)]
        + ["--out", str(out), "--quiet", *extra],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=run_env(),
    )


SMALL = ["--robots", "300", "--seed", "3"]


@pytest.fixture(scope="module")
def small_reference(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("shards-small") / "ref"
    assert cli.main(["simulate", *SMALL, "--out", str(out), "--quiet", "--no-recording"]) == 0
    return out


def _launch_small(out: Path) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "swarm_ros", "run", *SMALL, "--processes", "4", "--world-shards", "3"]
        + ["--out", str(out), "--quiet", "--no-recording"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=run_env(),
    )


def test_a_run_over_three_world_shards_is_simulates(small_reference, tmp_path):
    out = tmp_path / "run"
    summary = finish_restarted_run(_launch_small(out), small_reference, out, [])
    assert summary["engine"] == "ros2"
    logs = sorted(p.name for p in (out / "logs").glob("world_shard_*.log"))
    assert logs == ["world_shard_0.log", "world_shard_1.log", "world_shard_2.log"]
    assert not (out / "logs" / "world.log").exists()


def test_a_world_shard_killed_mid_run_goes_on_from_its_save(reference, tmp_path):
    out = tmp_path / "run"
    launcher = _launch(out, 2)
    wait_ticks_recorded(out, 150_000)
    os.kill(node_pid(out, "world_shard_1"), signal.SIGKILL)
    summary = finish_restarted_run(launcher, reference, out, ["world_shard_1"])
    [restart] = summary["restarts"]
    assert 0 < restart["tick"] < summary["convergence_tick"]
    log = (out / "logs" / "world_shard_1.log").read_text()
    assert "world_shard_1 restarted: going on from tick" in log


def test_a_world_shard_killed_while_starting_is_restarted_and_the_run_is_identical(small_reference, tmp_path):
    out = tmp_path / "run"
    launcher = _launch_small(out)
    os.kill(node_pid(out, "world_shard_0"), signal.SIGKILL)  # seen as soon as it exists: long before tick 0
    summary = finish_restarted_run(launcher, small_reference, out, ["world_shard_0"])
    assert summary["restarts"] == [{"tick": 0, "node": "world_shard_0"}]
