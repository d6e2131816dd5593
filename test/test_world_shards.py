"""World shards over the ROS 2 graph (``swarm-ros run --world-shards S``): the run is simulate's, byte for byte,
its bag holds every tick's S parts, and a world shard SIGKILLed while starting or right as it writes its save, in
the middle of the run, is restarted from that save and changes nothing the run writes but ``restarts``. A batch
lost for good under ``--on-batch-loss remove`` has its robots removed by the shards that held them (the only
process test of ``remove``). A node lost more often than ``--max-restarts`` is test_node_restarts' (the world)
and test_rubenstein_graph's (a batch): the launcher's bound is the same for every node."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from graph_runs import (
    assert_identical_run,
    finish_restarted_run,
    kill_node,
    kill_starting,
    processes_mentioning,
    run_env,
    staged_logs,
    wait_saved,
)

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


def test_world_shards_keep_to_the_worlds_tick_rate_and_the_run_is_simulates(tmp_path):
    """``tick_rate`` in the parameter file's /world section reaches every shard: 60 ticks at 40 a second take
    at least 59/40 s (unpaced, about 0.6 s here), and the run is simulate's."""
    flags = [*SMALL, "--max-ticks", "60", "--no-recording"]
    ref, out, paced = tmp_path / "ref", tmp_path / "run", tmp_path / "paced.yaml"
    assert cli.main(["simulate", *flags, "--out", str(ref), "--quiet"]) == 0
    paced.write_text("/world:\n  ros__parameters:\n    tick_rate: 40.0\n")
    done = subprocess.run(
        [sys.executable, "-m", "swarm_ros", "run", *flags, "--processes", "4", "--world-shards", "2"]
        + ["--params-file", str(paced), "--out", str(out), "--quiet"],
        capture_output=True,
        text=True,
        env=run_env(),
        timeout=300,
    )
    assert done.returncode == 0, done.stderr
    summary = assert_identical_run(ref, out)
    assert summary["wall_seconds"] >= 0.95 * 59 / 40, summary["wall_seconds"]  # the monitor's receive times


def test_a_run_over_three_world_shards_one_killed_while_starting_is_simulates(small_reference, tmp_path):
    out = tmp_path / "run"
    launcher = _launch_small(out)
    kill_starting(out, "world_shard_0")  # long before tick 0
    summary = finish_restarted_run(launcher, small_reference, out, ["world_shard_0"])
    assert summary["restarts"] == [{"tick": 0, "node": "world_shard_0"}]
    assert summary["engine"] == "ros2"
    assert (summary["processes"], summary["world_shards"]) == (4, 3), "the run directory says how it ran"
    logs = sorted(p.name for p in (out / "logs").glob("world_shard_*.log"))
    assert logs == ["world_shard_0.log", "world_shard_1.log", "world_shard_2.log"]
    assert not (out / "logs" / "world.log").exists()


def test_a_world_shard_killed_as_it_writes_its_save_goes_on_from_it(reference, tmp_path):
    """Killed the moment its save's header moves on (polled every 0.5 ms), twice: the process is then writing
    the next tick's kept messages or ring slot, or publishing what it just saved. The shards send the robots
    every 4th tick (``--record-every 4``), their tallies in between: the new process sends again what the
    monitor may lack of each kind, and the bag holds every 4th tick whole."""
    out = tmp_path / "run"
    launcher = _launch(out, 2, "--no-recording", "--record-every", "4")
    logs, pid = staged_logs(out), None
    for tick in (100, 300):
        wait_saved(logs, tick, name="world.checkpoint.0")
        pid = kill_node(out, "world_shard_0", not_pid=pid)
    summary = finish_restarted_run(launcher, reference, out, ["world_shard_0", "world_shard_0"])
    assert all(0 < r["tick"] < summary["convergence_tick"] for r in summary["restarts"]), summary["restarts"]


def test_a_batch_lost_for_good_in_a_sharded_run_has_its_robots_removed(tmp_path):
    """``--on-batch-loss remove``: robot_batch_1 (world shard 0's second batch) is SIGKILLed mid-run; the shards
    remove the robots it hosted that were still moving, and the run goes on to its end with the rest; the robots'
    final rows agree with the counts the monitor made of the shards' parts."""
    out = tmp_path / "run"
    launcher = _launch(out, 2, "--no-recording", "--on-batch-loss", "remove")
    wait_saved(staged_logs(out), 100, name="world.checkpoint.0")
    kill_node(out, "robot_batch_1")
    _, err = launcher.communicate(timeout=240)
    assert launcher.returncode == 0, err
    assert "the world removes its robots" in err and "restarted" not in err, err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["lost_robots"] > 0 and summary["restarts"] == [], summary
    final = (out / "final_state.csv").read_text().splitlines()  # the robots' rows, against the counted metrics
    states = [row.rsplit(",", 1)[1] for row in final[1:]]
    assert len(states) == summary["robots"] and states.count("removed") == summary["lost_robots"], summary
    assert states.count("localized") + states.count("seed") == summary["localized"], summary
    assert not processes_mentioning(str(out)), "a process outlived the run"
