"""The rubenstein algorithm over the ROS 2 graph (`swarm-ros run --algorithm rubenstein`): K = 1, 2, 4 robot-batch
processes write the run `simulate` writes, byte for byte, and a batch process killed mid-run is restarted and
changes nothing."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from bagcheck import assert_kilobot_bag_holds_run
from graph_runs import node_pid, processes_mentioning, run_env, wait_ticks_recorded

from swarm_ros.app import cli

pytestmark = pytest.mark.process

SQUARE = "######\n" * 6  # 36 pixels: a run of a few thousand ticks
RUN = ["--algorithm", "rubenstein", "--robots", "40", "--seed", "5", "--quiet"]


@pytest.fixture(scope="module")
def square(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("kilobot-shape") / "square6.txt"
    path.write_text(SQUARE)
    return path


@pytest.fixture(scope="module")
def reference(square, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("kilobot-ref") / "ref"
    assert cli.main(["simulate", "--shape", str(square), *RUN, "--out", str(out), "--no-recording"]) == 0
    return out


def assert_same_run(reference: Path, out: Path) -> dict:
    for name in ("metrics.csv", "final_state.csv"):
        assert (out / name).read_bytes() == (reference / name).read_bytes(), name
    got, ref = (json.loads((d / "summary.json").read_text()) for d in (out, reference))
    differ = {k for k in ref if got.get(k) != ref[k]}
    assert differ <= {"engine", "wall_seconds", "recording_robots_every", "bag_robots_every"}, differ
    assert got["engine"] == "ros2" and got["outcome"] == "complete"
    return got


def _launch(square: Path, out: Path, processes: int) -> subprocess.Popen:
    command = [sys.executable, "-m", "swarm_ros", "run", "--shape", str(square), *RUN, "--out", str(out)]
    return subprocess.Popen(
        [*command, "--processes", str(processes)], env=run_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE
    )


@pytest.mark.parametrize("processes", [1, 2, 4])
def test_k_batch_processes_write_the_run_simulate_writes(square, reference, tmp_path, processes):
    out = tmp_path / "run"
    launcher = _launch(square, out, processes)
    _, err = launcher.communicate(timeout=300)
    assert launcher.returncode == 0, err.decode()
    summary = assert_same_run(reference, out)
    assert summary["processes"] == processes
    assert (out / "recording.rrd").stat().st_size > 0 and (out / "final.png").stat().st_size > 0
    assert_kilobot_bag_holds_run(out)
    world = (out / "logs" / "world.log").read_text()
    assert "dropped" not in world, world  # no message of the run's own was refused
    assert not processes_mentioning(str(out)), "a process outlived the run"


def test_a_batch_process_killed_mid_run_is_restarted_and_the_run_is_the_same(square, reference, tmp_path):
    """A batch keeps nothing between ticks: its restarted process is sent its area again and decides as the
    killed one would have."""
    out = tmp_path / "run"
    launcher = _launch(square, out, 2)
    wait_ticks_recorded(out, 20_000)  # ticks are flowing: the monitor has recorded some
    os.kill(node_pid(out, "robot_batch_0", timeout=10), signal.SIGKILL)
    _, err = launcher.communicate(timeout=300)
    assert launcher.returncode == 0, err.decode()
    summary = assert_same_run(reference, out)
    assert [r["node"] for r in summary["restarts"]] == ["robot_batch_0"]
    assert "started robot_batch_0" in (out / "logs" / "launcher.log").read_text()


def test_the_graph_refuses_what_the_rubenstein_graph_does_not_do_in_one_line(square, tmp_path, capsys):
    for flags, message in (
        (["--world-shards", "2", "--processes", "2"], "--world-shards is not for the rubenstein algorithm's graph"),
        (["--processes", "500"], "processes must be between 1 and the"),
    ):
        code = cli.main(["run", "--shape", str(square), *RUN, "--out", str(tmp_path / "x"), *flags])
        err = capsys.readouterr().err
        assert code == 2 and message in err and err.count("\n") == 1, err
        assert not (tmp_path / "x").exists()


def test_an_experiment_over_the_graph_gives_the_in_process_rows(square, tmp_path):
    import yaml

    from swarm_ros.app.results_file import read_results

    config = tmp_path / "kb.yaml"
    shapes = {str(square): [40]}
    config.write_text(
        yaml.safe_dump(
            {"name": "kb", "seed": 5, "repetitions": 1, "vision_radius": 1, "algorithm": "rubenstein", "shapes": shapes}
        )
    )
    rows = {}
    for engine in ("inprocess", "ros2"):
        out = tmp_path / engine
        assert cli.main(["experiment", str(config), "--out", str(out), "--quiet", "--engine", engine]) == 0
        [rows[engine]] = read_results(out / "results.csv")
    differ = {k for k in rows["ros2"] if rows["ros2"][k] != rows["inprocess"][k]}
    assert differ == {"engine", "wall_seconds"}, differ


def test_a_world_process_killed_mid_run_fails_the_run_in_one_line_and_writes_nothing(square, tmp_path):
    """The rubenstein world keeps no checkpoint yet: its restarted process refuses to start the run again from
    tick 0, so the run fails, and no run directory is written; the monitor's bag so far is left beside it."""
    out = tmp_path / "run"
    launcher = _launch(square, out, 2)
    wait_ticks_recorded(out, 20_000)
    os.kill(node_pid(out, "world", timeout=10), signal.SIGKILL)
    _, err = launcher.communicate(timeout=300)
    said = err.decode().strip().splitlines()
    assert launcher.returncode not in (0, None) and "Traceback" not in err.decode(), said
    assert "cannot resume a rubenstein run yet" in said[-1] or "cannot resume" in err.decode(), said
    assert not out.exists()
    from rosbags.highlevel import AnyReader

    with AnyReader([tmp_path / "run.partial-bag"]) as reader:  # the bag so far, closed and readable, beside it
        metrics = [c for c in reader.connections if c.topic == "/swarm/kilobot/metrics"]
        assert metrics and sum(c.msgcount for c in metrics) > 0
    assert not processes_mentioning(str(out)), "a process outlived the run"
