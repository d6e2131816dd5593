"""A third algorithm, registered from outside the package (test/random_walk, named in SWARM_ROS_ALGORITHMS), runs
in ``simulate`` and in an experiment beside the study's model with no edit to shared code, the same for the same
seed; what it does not supply (a ROS 2 graph, ``--check``) is refused in one line, before anything is written."""

from __future__ import annotations

import csv
import os
import subprocess
import sys
from pathlib import Path

import pytest
from recordings import Recording

pytestmark = pytest.mark.process  # each case is a swarm-ros command in a process of its own (the registry is global)

HERE = Path(__file__).resolve().parent
BLOCK = "#####\n#####\n#####\n#####\n"  # 20 patches


def _swarm(cwd: Path, *args: str, plugin: bool = True) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k != "SWARM_ROS_ALGORITHMS"}
    if plugin:
        env["SWARM_ROS_ALGORITHMS"] = "random_walk"
        env["PYTHONPATH"] = os.pathsep.join([str(HERE), *filter(None, [env.get("PYTHONPATH")])])
    command = [sys.executable, "-m", "swarm_ros", *args]
    return subprocess.run(command, cwd=cwd, env=env, capture_output=True, text=True, timeout=300)


@pytest.fixture
def block(tmp_path) -> Path:
    (tmp_path / "block.txt").write_text(BLOCK)
    return tmp_path / "block.txt"


def test_simulate_runs_it_writes_its_run_directory_and_the_same_seed_gives_the_same_run(tmp_path, block):
    run = ("simulate", "--algorithm", "random-walk", "--shape", str(block), "--world-radius", "8", "--robots", "30")
    first = _swarm(tmp_path, *run, "--max-ticks", "300", "--out", "a")
    assert first.returncode == 0, first.stderr
    assert "localized" in first.stdout and "vision" not in first.stdout  # the study's parameters are not its own
    second = _swarm(tmp_path, *run, "--max-ticks", "300", "--out", "b", "--no-recording", "--quiet")
    assert second.returncode == 0, second.stderr
    for name in ("metrics.csv", "final_state.csv"):
        assert (tmp_path / "a" / name).read_text() == (tmp_path / "b" / name).read_text()
    history = list(csv.DictReader((tmp_path / "a" / "metrics.csv").open()))
    assert len(history) == 301 and int(history[-1]["localized"]) > 4  # robots joined the seeds
    recording = Recording(tmp_path / "a" / "recording.rrd")
    assert len(recording.robots) == 301 and recording.events[-1][0] == 300  # every tick, and the outcome


def test_what_it_does_not_supply_is_refused_in_one_line_and_nothing_is_written(tmp_path, block):
    shape = ("--algorithm", "random-walk", "--shape", str(block), "--world-radius", "8", "--out", "x")
    for args, said in (
        (("simulate", *shape, "--check"), "the random-walk algorithm has no --check"),
        (("run", *shape), "the random-walk algorithm has no ROS 2 graph yet"),
    ):
        done = _swarm(tmp_path, *args)
        assert done.returncode == 2 and said in done.stderr and done.stderr.count("\n") == 1, done.stderr
    unknown = _swarm(tmp_path, "simulate", *shape, plugin=False)  # not named: not known
    assert unknown.returncode == 2 and "random-walk" in unknown.stderr and "darr-niazi" in unknown.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["block.txt"]


def test_an_experiment_runs_it_beside_the_studys_model_and_a_second_run_gives_the_same_rows(tmp_path, block):
    (tmp_path / "walk.yaml").write_text(
        "name: walk\nseed: 5\nrepetitions: 2\nvision_radius: 1\nrules: paper\nalgorithm: [darr-niazi, random-walk]\n"
        "max_ticks: 400\n"
        f"shapes:\n  {block.name}: [12]\nworld_radius: 8\n"
    )
    rows = []
    for out in ("e1", "e2"):
        done = _swarm(tmp_path, "experiment", "walk.yaml", "--out", out, "--jobs", "1", "--quiet")
        assert done.returncode == 0, done.stderr
        with (tmp_path / out / "results.csv").open() as f:
            rows.append([{k: v for k, v in r.items() if k != "wall_seconds"} for r in csv.DictReader(f)])
    assert rows[0] == rows[1]
    assert sorted(r["algorithm"] for r in rows[0]) == ["darr-niazi"] * 2 + ["random-walk"] * 2
    walk = [r for r in rows[0] if r["algorithm"] == "random-walk"]
    assert walk[0]["seed"] != walk[1]["seed"] and all(int(r["localized"]) >= 4 for r in walk)
    refused = _swarm(tmp_path, "experiment", "walk.yaml", "--out", "e3", "--engine", "ros2")
    assert refused.returncode == 2 and "has no ROS 2 graph yet" in refused.stderr and not (tmp_path / "e3").exists()
