"""A 3D run over the ROS 2 graph equals the in-process engine's, for 1 and 4 robot-batch processes (and 2, with its
world and monitor killed and restarted), with the bag and the recording in 3D; and a 3D run's command-line paths
(docs/model.md, "Three dimensions")."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from bagcheck import assert_bag_holds_run
from graph_runs import finish_restarted_run, kill_node, staged_logs, wait_saved
from recordings import Recording

pytestmark = pytest.mark.process

PY = sys.executable
# k-block (540 voxels) in a small world: complete in about 1,050 ticks, a few seconds in process
RUN = ["--shape", "k-block", "--world-radius", "14", "--seed", "4", "--max-ticks", "1500", "--quiet"]


def swarm_ros(*args: str, timeout: float = 240) -> subprocess.CompletedProcess:
    env = {**os.environ, "HOME": os.environ.get("HOME", "/tmp")}
    env.pop("ROS_DOMAIN_ID", None)
    return subprocess.run([PY, "-m", "swarm_ros", *args], capture_output=True, text=True, timeout=timeout, env=env)


@pytest.fixture(scope="module")
def reference(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("ref3d") / "run"
    done = swarm_ros("simulate", *RUN, "--out", str(out))
    assert done.returncode == 0, done.stderr
    return out


def test_a_3d_simulate_writes_3d_files(reference):
    summary = json.loads((reference / "summary.json").read_text())
    assert summary["outcome"] == "complete" and summary["shape_patches"] == 540
    header, first = (reference / "final_state.csv").read_text().splitlines()[:2]
    assert header == "id,x,y,z,heading,pitch,state" and first.endswith(",seed")
    rec = Recording(reference / "recording.rrd")
    positions, classes = rec.robots[max(rec.robots)]
    assert positions.shape == (540, 3) and (classes == 3).sum() == 536  # localized, besides the 4 seeds
    filled = rec.occupancy[max(rec.occupancy)].reshape(-1, 3)
    assert filled.shape == (540, 3)
    assert {"/world/map", "/world/map/walls", "/world/occupancy", "/world/robots"} <= rec.static


@pytest.mark.parametrize("processes", [1, 4])
def test_a_3d_ros_graph_run_equals_the_in_process_engine(reference, tmp_path, processes):
    out = tmp_path / "run"
    done = swarm_ros("run", *RUN, "--processes", str(processes), "--out", str(out))
    assert done.returncode == 0, done.stderr
    assert (reference / "metrics.csv").read_bytes() == (out / "metrics.csv").read_bytes()
    assert (reference / "final_state.csv").read_bytes() == (out / "final_state.csv").read_bytes()
    a, b = (json.loads((d / "summary.json").read_text()) for d in (reference, out))
    for key in ("engine", "wall_seconds", "startup_seconds", "shutdown_seconds"):
        a.pop(key, None), b.pop(key, None)
    assert b.pop("rejected_messages") == {"world": 0, "monitor": 0}
    assert b.pop("bag_robots_every") == 1  # checked against the bag (bagcheck)
    assert (b.pop("processes"), b.pop("world_shards")) == (processes, 1)
    assert a == b
    assert Recording(out / "recording.rrd").same_data(Recording(reference / "recording.rrd"))
    assert_bag_holds_run(out)  # read with another library: 3D rows, and voxel clouds for shape and occupancy


def test_simulate_check_runs_the_z_spec_checker_in_3d(tmp_path):
    done = swarm_ros(
        "simulate",
        "--shape",
        "torus",
        "--world-radius",
        "16",
        "--max-ticks",
        "300",
        "--check",
        "--no-recording",
        "--out",
        str(tmp_path / "run"),
    )
    assert done.returncode == 0, done.stderr
    assert json.loads((tmp_path / "run" / "summary.json").read_text())["outcome"] == "timeout"


def test_shapes_lists_the_3d_shapes_apart():
    done = swarm_ros("shapes", "--3d")
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert lines[0].split()[:4] == ["shape", "voxels", "tunnels", "cavities"]
    rows = {ln.split()[0]: ln.split()[1:4] for ln in lines[1:-1]}
    assert rows["torus"] == ["1348", "1", "0"] and rows["shell"] == ["1628", "0", "1"]
    assert lines[-1] == "world: 65 x 65 x 65 voxels, walls on the outer shell"
    assert "3D shapes: swarm-ros shapes --3d" in swarm_ros("shapes").stdout.splitlines()[-1]


def test_a_3d_runs_world_and_monitor_killed_mid_run_go_on_and_the_run_is_identical(reference, tmp_path):
    """The world from its checkpoint of 3D rows, then the monitor from its bag of them, in one run (a batch
    takes a 3D snapshot at tick 0 in every run, and again when it is restarted: the same message)."""
    out = tmp_path / "run"
    launcher = subprocess.Popen(
        [PY, "-m", "swarm_ros", "run", *RUN, "--processes", "2", "--out", str(out)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={k: v for k, v in os.environ.items() if k != "ROS_DOMAIN_ID"},
    )
    logs = staged_logs(out)
    wait_saved(logs, 300)
    kill_node(out, "world")
    wait_saved(logs, 650)  # the new world's checkpoint: it went on
    kill_node(out, "monitor")
    summary = finish_restarted_run(launcher, reference, out, ["world", "monitor"])
    # the world went on from its checkpoint (tick 0: it saves every 1,000 ticks), the monitor from its bag
    assert summary["restarts"][0]["tick"] == 0 and 300 <= summary["restarts"][1]["tick"] < 1052
