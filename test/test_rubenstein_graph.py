"""The rubenstein algorithm over the ROS 2 graph (`swarm-ros run --algorithm rubenstein`): K = 1, 2, 3, 4 robot-batch
processes and S = 2 world shards write the run `simulate` writes, byte for byte, and a batch, the world, a world shard
or the monitor killed mid-run is restarted and changes nothing.

The runs stop at tick 1,600 (outcome timeout), past the start-up's 200 ticks and a quarter of the robots joined: the
square's whole run is 5,311 ticks, which test_ros2_cli runs to its end under ``ros2 launch``."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from bagcheck import assert_bag_holds_run
from graph_runs import (
    kill_starting,
    node_pid,
    processes_mentioning,
    run_env,
    staged_logs,
    wait_monitor_holds,
    wait_rubenstein_saved,
)
from waiting import wait_for

from swarm_ros.app import cli
from swarm_ros.protocol.plan import CentralTopics

pytestmark = pytest.mark.process

SQUARE = "######\n" * 6  # 36 pixels: 5,311 ticks to complete
TICKS = 1600
RUN = ["--algorithm", "rubenstein", "--robots", "40", "--seed", "5", "--quiet", "--max-ticks", str(TICKS)]


@pytest.fixture(scope="module")
def square(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("rubenstein-shape") / "square6.txt"
    path.write_text(SQUARE)
    return path


@pytest.fixture(scope="module")
def reference(square, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("rubenstein-ref") / "ref"
    assert cli.main(["simulate", "--shape", str(square), *RUN, "--out", str(out), "--no-recording"]) == 0
    return out


def assert_same_run(reference: Path, out: Path, scaled: bool = False) -> dict:
    """``scaled``: the run read its shape at another scale, so its summary names another shape file."""
    for name in ("metrics.csv", "final_state.csv"):
        assert (out / name).read_bytes() == (reference / name).read_bytes(), name
    got, ref = (json.loads((d / "summary.json").read_text()) for d in (out, reference))
    differ = {k for k in ref if got.get(k) != ref[k]}
    allowed = {"engine", "wall_seconds", "recording_robots_every", "bag_robots_every", *["shape"] * scaled}
    assert differ <= allowed, differ
    assert got["engine"] == "ros2" and got["outcome"] == "timeout"
    # what every graph run's summary says beside the algorithm's own fields (docs/usage.md)
    assert isinstance(got["startup_seconds"], float) and 0 < got["startup_seconds"] < 120
    assert got["rejected_messages"] == {"world": 0, "monitor": 0} and got["world_shards"] >= 1
    return got


def _launch(square: Path, out: Path, processes: int, *flags: str) -> subprocess.Popen:
    command = [sys.executable, "-m", "swarm_ros", "run", "--shape", str(square), *RUN, "--out", str(out), *flags]
    return subprocess.Popen(
        [*command, "--processes", str(processes)], env=run_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE
    )


@pytest.mark.parametrize("processes, cuts", [(1, ""), (4, ""), (3, "-9,5")])
def test_k_batch_processes_write_the_run_simulate_writes(square, reference, tmp_path, processes, cuts):
    """K = 2 is every restart test's below, each compared with simulate's run the same way (S = 2 world shards, each
    holding its strips' robots and a halo, is the world shard's); K = 3 with the strips cut where the user says (x
    positions in d: the grid's cell columns 0-1, 2-5 and 6-9). K = 1 reads the square as a 3 x 3 one at
    ``--shape-scale 2``: every node scales it, and the run is the 6 x 6 square's."""
    out = tmp_path / "run"
    shape, scaled = square, ()
    if processes == 1:
        shape, scaled = tmp_path / "square3.txt", ("--shape-scale", "2")
        shape.write_text("###\n" * 3)
    launcher = _launch(shape, out, processes, *([f"--region-cuts={cuts}"] if cuts else []), *scaled)
    _, err = launcher.communicate(timeout=300)
    assert launcher.returncode == 0, err.decode()
    summary = assert_same_run(reference, out, scaled=bool(scaled))
    assert summary.get("shape_scale", 1) == (2 if scaled else 1)
    assert summary["processes"] == processes
    assert (out / "recording.rrd").stat().st_size > 0 and (out / "final.png").stat().st_size > 0
    assert_bag_holds_run(out)
    world = "".join(p.read_text() for p in (out / "logs").glob("world*.log"))
    assert "dropped" not in world, world  # no message of the run's own was refused
    if cuts:
        assert all(f"columns {strip}" in world for strip in ("0..1", "2..5", "6..9")), world
    assert not processes_mentioning(str(out)), "a process outlived the run"


@pytest.mark.parametrize("stop", ["ctrl-c", "a batch lost past --max-restarts"])
def test_a_run_stopped_mid_way_is_written_up_to_its_last_record_as_simulate_writes_it(square, tmp_path, stop):
    """Ctrl-C, or a batch lost more often than the restart bound (its robots cannot be removed under this algorithm:
    the run cannot go on), stops every process; the monitor writes the run up to the last record it holds, outcome
    interrupted: its metrics and final state are simulate's with --max-ticks at that tick."""
    out = tmp_path / "run"
    command = [sys.executable, "-m", "swarm_ros", "run", "--shape", str(square), *RUN, "--out", str(out)]
    launcher = subprocess.Popen(
        [*command, "--processes", "2", "--max-restarts", "0"], env=run_env(), stderr=subprocess.PIPE, text=True
    )
    wait_rubenstein_saved(out, 1000)
    if stop == "ctrl-c":
        launcher.send_signal(signal.SIGINT)
    else:
        os.kill(node_pid(out, "robot_batch_1", timeout=10), signal.SIGKILL)
    _, err = launcher.communicate(timeout=120)
    summary = json.loads((out / "summary.json").read_text())
    tick = summary["convergence_tick"]
    if stop == "ctrl-c":
        assert launcher.returncode == 130 and f"interrupted at tick {tick}; the run so far is in {out}" in err, err
    else:
        assert launcher.returncode == 1 and err.count("\n") == 1, err
        assert "robot_batch_1 was killed by SIGKILL; it was restarted 0 times already (--max-restarts)" in err
        assert f"(logs: {out}.logs)" in err
    assert summary["outcome"] == "interrupted" and tick > 0
    ref = tmp_path / "ref"
    assert cli.main(["simulate", "--shape", str(square), *RUN, "--max-ticks", str(tick), "--out", str(ref)]) == 0
    for name in ("metrics.csv", "final_state.csv"):
        assert (out / name).read_bytes() == (ref / name).read_bytes(), name
    assert_bag_holds_run(out, interrupted=True)
    assert (out / "recording.rrd").stat().st_size > 0
    beside = ["ref", "run"] + ["run.logs"] * (stop != "ctrl-c")  # a command that failed keeps its logs, and says so
    assert sorted(p.name for p in tmp_path.iterdir()) == beside, "nothing partial is left beside the run"
    assert not processes_mentioning(str(out)), "a process outlived the run"


def test_a_world_shard_killed_goes_on_from_its_checkpoint_and_the_run_is_the_same(square, reference, tmp_path):
    """World shard 1 of 2, killed mid-run (past its checkpoint of tick 300, saved every 100 ticks), goes on from its
    last checkpoint: its peer waits, the topics give it again what its peer sent it since, its batches decide those
    ticks again, the monitor takes its records' parts again as repeats: the run directory is simulate's, and its bag
    holds the run."""
    out = tmp_path / "run"
    launcher = _launch(square, out, 2, "--world-shards", "2")
    checkpoint = staged_logs(out) / "world.checkpoint.1"
    wait_for(lambda: saved_tick(checkpoint) >= 300, 120, "shard 1's checkpoint of tick 300", poll=0.01)
    # then the records up to tick 340 (each shard's part of each 20th tick): its process is ticks past a checkpoint
    # (40 or more, unless it saved again meanwhile), which its new one decides again from what its peer sent it
    wait_monitor_holds(out, CentralTopics.of("rubenstein").robots, 2 * (340 // 20 + 1))
    os.kill(node_pid(out, "world_shard_1", timeout=10), signal.SIGKILL)
    _, err = launcher.communicate(timeout=300)
    assert launcher.returncode == 0, err.decode()
    summary = assert_same_run(reference, out)
    assert [r["node"] for r in summary["restarts"]] == ["world_shard_1"]
    said = (out / "logs" / "world_shard_1.log").read_text()
    assert "restarted: on from the checkpoint of tick" in said, said
    assert "dropped" not in said, said  # its batches' decisions of settled ticks, again from their histories
    assert "dropped" not in (out / "logs" / "monitor.log").read_text()  # the parts again were repeats, not faults
    assert_bag_holds_run(out)
    assert not list((out / "logs").glob("world.checkpoint*")), "a checkpoint outlived the run"
    assert not processes_mentioning(str(out)), "a process outlived the run"


def test_the_graph_refuses_what_the_rubenstein_graph_does_not_do_in_one_line(square, tmp_path, capsys):
    for flags, message in (
        (["--processes", "500"], "cannot be cut into 500 strips, one per robot-batch process"),
        (["--on-batch-loss", "remove"], "--on-batch-loss remove is not for the rubenstein algorithm's graph"),
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
    experiment = {"name": "kb", "seed": 5, "repetitions": 1, "vision_radius": 1, "algorithm": "rubenstein"}
    config.write_text(yaml.safe_dump({**experiment, "max_ticks": TICKS, "shapes": shapes}))
    rows = {}
    for engine in ("inprocess", "ros2"):
        out = tmp_path / engine
        assert cli.main(["experiment", str(config), "--out", str(out), "--quiet", "--engine", engine]) == 0
        [rows[engine]] = read_results(out / "results.csv")
    differ = {k for k in rows["ros2"] if rows["ros2"][k] != rows["inprocess"][k]}
    assert differ == {"engine", "wall_seconds"}, differ


def saved_tick(checkpoint: Path) -> int:
    try:
        with np.load(checkpoint) as f:
            return int(f["tick"][0])
    except (OSError, KeyError, ValueError):
        return -1


def _kill_at(out: Path, node: str, moment: str) -> None:
    """SIGKILL ``node`` of the run into ``out`` at ``moment``: "starting" (graph_runs.kill_starting),
    "mid-run" (past the world's checkpoint of tick 1000), or "writing" (the monitor: the run directory's temporary
    folder is there)."""
    if moment == "mid-run":
        wait_rubenstein_saved(out, 1000)
    if moment == "writing":
        wait_for(lambda: any(out.parent.glob(".run.tmp-*")), 240, "the monitor writing the run", poll=0.002)
    if moment == "starting":
        kill_starting(out, node, timeout=30)
    else:
        os.kill(node_pid(out, node, timeout=30), signal.SIGKILL)


@pytest.mark.parametrize(
    "kills",
    [
        (("world", "starting"), ("robot_batch_0", "mid-run"), ("monitor", "writing")),
        (("monitor", "starting"), ("world", "mid-run")),
        (("monitor", "mid-run"),),
    ],
    ids=["world starting, a batch mid-run, monitor writing", "monitor starting, world mid-run", "monitor mid-run"],
)
def test_a_world_a_batch_and_a_monitor_killed_go_on_and_the_run_is_the_same(square, reference, tmp_path, kills):
    """The restarted world takes the last checkpoint (saved every 1,000 ticks, and at tick 0 before anything of it
    goes out; killed before that, it starts afresh), the batches decide the ticks after it again, the monitor
    drops the metrics it already holds. A batch keeps nothing between ticks: its restarted process is sent its
    area again and decides as the killed one would have. The restarted monitor reads back the bag its process
    before left and takes the records since from the topics' histories (the world never runs past what they keep;
    "writing": the world has ended and exited, the bag is all there is). The run directory is simulate's, its bag
    holds the run once (robots by tick), and its recording is whole. Kills at moments that do not overlap share a
    run."""
    out = tmp_path / "run"
    launcher = _launch(square, out, 2)
    for node, moment in kills:
        _kill_at(out, node, moment)
    _, err = launcher.communicate(timeout=300)
    assert launcher.returncode == 0, err.decode()
    summary = assert_same_run(reference, out)
    assert [r["node"] for r in summary["restarts"]] == [node for node, _ in kills]
    for node, moment in kills:
        said = (out / "logs" / f"{node}.log").read_text()
        if node == "world":
            assert "restarted: on from the checkpoint of tick" in said or "restarted before tick 0 went out" in said
            assert "dropped" not in said, said  # the batches' decisions of settled ticks, again from their histories
        elif node.startswith("robot_batch"):
            assert f"started {node}" in (out / "logs" / "launcher.log").read_text()
            world = (out / "logs" / "world.log").read_text()  # the world follows each peer's liveliness
            peers = ("robot_batch_0", "robot_batch_1", "monitor")
            assert all(f"{name} is alive (liveliness)" in world for name in peers)
        else:
            [resumed_at] = re.findall(r"monitor restarted \(incarnation 1\): went on from tick (-?\d+)", said)
            assert int(resumed_at) > 0 if moment == "mid-run" else int(resumed_at) >= -1, said
    assert_bag_holds_run(out)
    assert (out / "recording.rrd").stat().st_size > 0
    assert not list((out / "logs").glob("world.checkpoint*")), "the checkpoint outlived the run"
    assert not list(tmp_path.glob(".run.*")), "a folder of a killed node outlived the run"
    assert not processes_mentioning(str(out)), "a process outlived the run"
