"""A third algorithm, registered from outside the package (test/random_walk, named in SWARM_ROS_ALGORITHMS), runs in
``simulate``, over the ROS 2 graph and in an experiment beside the study's model with no edit to shared code: the
graph's run, with K = 1 robot-batch process, with K = 3 over S = 2 world shards, and with the default K = 2 in the
experiment, is the one ``simulate`` writes, byte for byte; what it does not supply (``--check``) is refused in one
line, before anything is written."""

from __future__ import annotations

import csv
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from recordings import Recording

pytestmark = pytest.mark.process  # each case is a swarm-ros command in a process of its own (the registry is global)

HERE = Path(__file__).resolve().parent
BLOCK = "#####\n#####\n#####\n#####\n"  # 20 cells
RUN = ("--algorithm", "random-walk", "--world-radius", "6", "--robots", "30", "--seed", "4", "--max-ticks", "300")


def _swarm(cwd: Path, *args: str, plugin: bool = True) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k not in ("SWARM_ROS_ALGORITHMS", "ROS_DOMAIN_ID")}
    if plugin:
        env["SWARM_ROS_ALGORITHMS"] = "random_walk"
        env["PYTHONPATH"] = os.pathsep.join([str(HERE), *filter(None, [env.get("PYTHONPATH")])])
    command = [sys.executable, "-m", "swarm_ros", *args]
    return subprocess.run(command, cwd=cwd, env=env, capture_output=True, text=True, timeout=300)


@pytest.fixture(scope="module")
def block(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("walk") / "block.txt"
    path.write_text(BLOCK)
    return path


@pytest.fixture(scope="module")
def reference(block) -> Path:
    """``simulate``'s run, twice: the same seed gives the same run."""
    first = _swarm(block.parent, "simulate", "--shape", str(block), *RUN, "--out", "a")
    assert first.returncode == 0, first.stderr
    assert "localized" in first.stdout and "vision" not in first.stdout  # the study's parameters are not its own
    second = _swarm(block.parent, "simulate", "--shape", str(block), *RUN, "--out", "b", "--no-recording", "--quiet")
    assert second.returncode == 0, second.stderr
    for name in ("metrics.csv", "final_state.csv"):
        assert (block.parent / "a" / name).read_text() == (block.parent / "b" / name).read_text()
    history = list(csv.DictReader((block.parent / "a" / "metrics.csv").open()))
    assert int(history[-1]["stopped"]) > 4 and len(history) == int(history[-1]["tick"]) + 1
    recording = Recording(block.parent / "a" / "recording.rrd")
    assert len(recording.robots) == len(history) and recording.events[-1][0] == len(history) - 1  # every tick
    return block.parent / "a"


@pytest.mark.parametrize("processes, shards", [(1, 1), (3, 2)])
def test_the_graph_with_k_batch_processes_writes_the_run_simulate_writes(block, reference, tmp_path, processes, shards):
    k, s = str(processes), str(shards)
    done = _swarm(
        tmp_path, "run", "--shape", str(block), *RUN, "--out", "g", "--processes", k, "--world-shards", s, "--quiet"
    )
    assert done.returncode == 0, done.stderr
    out = tmp_path / "g"
    for name in ("metrics.csv", "final_state.csv"):
        assert (out / name).read_bytes() == (reference / name).read_bytes(), name
    got, ref = (json.loads((d / "summary.json").read_text()) for d in (out, reference))
    assert {k for k in ref if got.get(k) != ref[k]} == {"engine", "wall_seconds"}
    assert got["processes"] == processes and (out / "recording.rrd").stat().st_size > 0
    assert (out / "bag" / "metadata.yaml").exists()
    assert all("dropped" not in p.read_text() for p in (out / "logs").glob("world*.log"))


def test_what_it_does_not_supply_is_refused_in_one_line_and_nothing_is_written(tmp_path, block):
    shape = ("--algorithm", "random-walk", "--shape", str(block), "--world-radius", "8", "--out", "x")
    for args, said in ((("simulate", *shape, "--check"), "the random-walk algorithm has no --check"),):
        done = _swarm(tmp_path, *args)
        assert done.returncode == 2 and said in done.stderr and done.stderr.count("\n") == 1, done.stderr
    unknown = _swarm(tmp_path, "simulate", *shape, plugin=False)  # not named: not known
    assert unknown.returncode == 2 and "random-walk" in unknown.stderr and "darr-niazi" in unknown.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_an_experiment_runs_it_beside_the_studys_model_and_over_the_graph_gives_the_same_rows(tmp_path, block):
    (tmp_path / "walk.yaml").write_text(
        "name: walk\nseed: 5\nrepetitions: 1\nvision_radius: 1\nrules: paper\nalgorithm: [darr-niazi, random-walk]\n"
        f"max_ticks: 400\nshapes:\n  {block}: [12]\nworld_radius: 8\n"
    )
    rows = {}
    for engine in ("inprocess", "ros2"):
        done = _swarm(
            tmp_path, "experiment", "walk.yaml", "--out", engine, "--jobs", "1", "--quiet", "--engine", engine
        )
        assert done.returncode == 0, done.stderr
        with (tmp_path / engine / "results.csv").open() as f:
            rows[engine] = [
                {k: v for k, v in r.items() if k not in ("wall_seconds", "engine")} for r in csv.DictReader(f)
            ]
    assert rows["inprocess"] == rows["ros2"]
    assert sorted(r["algorithm"] for r in rows["ros2"]) == ["darr-niazi", "random-walk"]
    [walk] = [r for r in rows["ros2"] if r["algorithm"] == "random-walk"]
    assert int(walk["localized"]) >= 1
