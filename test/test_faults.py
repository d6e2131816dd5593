"""Process faults in a running graph: a robot batch killed (SIGKILL) or stalled (SIGSTOP), the monitor killed
with no restart left.

Under ``--on-batch-loss remove`` (robots lost for good; the default restarts the process,
see test_restarts.py) the world notices through DDS liveliness (1 s lease), removes the
lost batch's robots at the end of the next tick, and the rest of the swarm repairs the shape. These runs are
timing-dependent by nature (which tick the loss lands on), so they check consistency,
not equality with the in-process engine; --fail-robots covers equality.
"""

from __future__ import annotations

import csv
import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from graph_runs import command_args, processes_mentioning, run_env
from recordings import Recording, rrd_verify
from waiting import wait_for

from swarm_ros.core import RunParams, Shape
from swarm_ros.core.darr_niazi.engine import Simulation
from swarm_ros.core.strips import strips_for
from swarm_ros.protocol.world_port import LOSS_CONFIRM_S, STALL_S

pytestmark = pytest.mark.process

PY = sys.executable
ROBOTS = 1036  # the star, ~2700 ticks: a few seconds over the graph


def _launch(out: Path, processes: int = 3, *extra: str) -> subprocess.Popen:
    """The star under ``remove``, paced at 1,000 ticks a second: unpaced it ran in 1.3 s, and once in a loaded
    run of the tests it had ended before the test saw it running (it then waited 120 s for nothing)."""
    paced = out.parent / f"{out.name}-paced.yaml"
    paced.write_text("/world:\n  ros__parameters:\n    tick_rate: 1000.0\n", encoding="utf-8")
    return subprocess.Popen(
        [
            PY,
            "-m",
            "swarm_ros",
            "run",
            "--shape",
            "star",
            "--processes",
            str(processes),
            "--out",
            str(out),
            "--quiet",
            "--on-batch-loss",
            "remove",
            "--params-file",
            str(paced),
            *extra,
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=run_env(),
    )


def _wait_until_running(out: Path, launcher: subprocess.Popen, batches: int = 3, timeout: float = 120) -> Path:
    """The run's staged log directory, once ticks flow (the monitor has recorded a few batches of ticks) and the
    world has seen every batch's liveliness: a batch killed before that is noticed by the 5 s fallback, as
    designed (a CI run once killed one 0.2 s after tick 0, before its liveliness had matched)."""
    partial = out.parent / f"{out.name}.partial.rrd"

    def running() -> Path | None:
        if launcher.poll() is not None:
            raise AssertionError(f"the run ended (exit {launcher.returncode}) before the test saw it running")
        logs = list(out.parent.glob(f".{out.name}.logs-*"))
        if (
            logs
            and partial.exists()
            and partial.stat().st_size > 300_000
            and (logs[0] / "world.log").exists()
            and (logs[0] / "world.log").read_text().count(" is alive (liveliness)") >= batches
        ):
            return logs[0]
        return None

    return wait_for(running, timeout, "the run getting going")


def _pid_of(node: str, logs: Path) -> int:
    for pid in processes_mentioning(str(logs)):
        if f"__node:={node}" in command_args(pid):
            return pid
    raise AssertionError(f"no process for {node}")


def _lost_at(world_log: str, name: str) -> float:
    """The ROS log time of the world's 'lost' warning for ``name``."""
    m = re.search(rf"\[WARN\] \[(\d+\.\d+)\] \[world\]: {name} was lost \(liveliness lapsed\)", world_log)
    assert m, world_log[-2000:]
    return float(m.group(1))


#: the world's warning that a batch's robots are removed: (time, batch, robots, tick)
_REMOVED = re.compile(
    r"\[WARN\] \[(\d+\.\d+)\] \[world\]: robot_batch_(\d+) lost for good \([^)]*\): its (\d+) robots are removed at "
    r"the end of tick (\d+)"
)


def _in_strip(x: np.ndarray, batch: int, batches: int = 3) -> np.ndarray:
    """Whether robots at ``x`` stand in the cell columns robot_batch_<batch> of ``batches`` decides in these runs
    (the default cuts), or one column past: a robot deciding there moves in the tick at whose end it leaves."""
    run = Simulation(Shape.load("star"), RunParams(robots=ROBOTS))
    first, last = strips_for(run, batches).strip(batch)
    cols = run.grid.columns(x)
    return (cols >= first - 1) & (cols <= last + 1)


def _check_consistent_run(out: Path, batch: int) -> dict:
    """The lost batch's robots, the moving robots in its strip when it was lost, were removed (where they stood
    at the end of the tick they left in, at most a column past the strip), and nothing else changed in the counts.

    No other batch was removed: a world starved of CPU past the 1 s lease may see a live batch's liveliness lapse
    (CI once did, beside the stopped batch), but the batch is back within LOSS_CONFIRM_S and keeps its robots."""
    summary = json.loads((out / "summary.json").read_text())
    assert len(summary["losses"]) == 1
    loss_tick = summary["losses"][0]["tick"]
    final = list(csv.DictReader((out / "final_state.csv").open()))
    removed = [r for r in final if r["state"] == "removed"]
    lost_ids = np.array([int(r["id"]) for r in removed])
    assert summary["lost_robots"] == lost_ids.size > 0
    declared = [(int(k), int(t), int(n)) for _, k, n, t in _REMOVED.findall((out / "logs" / "world.log").read_text())]
    assert declared == [(batch, loss_tick, lost_ids.size)], declared
    x = np.array([float(r["x"]) for r in removed])
    assert _in_strip(x, batch).all(), "a removed robot was not in the lost batch's strip"
    rows = np.array(list(csv.reader((out / "metrics.csv").open()))[1:], dtype=np.int64)
    tick, stationary, moving = rows[:, 0], rows[:, 1], rows[:, 4]
    before = tick < loss_tick
    assert np.all(stationary[before] + moving[before] == ROBOTS)
    assert np.all(stationary[~before] + moving[~before] == ROBOTS - lost_ids.size)
    # self-repair: the robots left refill the shape as far as they go
    assert summary["outcome"] == "incomplete" and summary["localized"] == ROBOTS - lost_ids.size
    assert summary["empty_patches"] == lost_ids.size
    assert rrd_verify(out / "recording.rrd").returncode == 0
    rec = Recording(out / "recording.rrd")
    assert rec.series["localized"] == dict(zip(tick.tolist(), rows[:, 2].astype(float).tolist()))
    return summary


def test_a_killed_robot_batch_is_noticed_by_its_liveliness_and_the_swarm_repairs_the_shape(tmp_path):
    """The world notices the kill by the batch's liveliness lease (1 s), before a silence of STALL_S could tell it
    (a loaded CI machine measured 3.0 s, a quiet one about 1 s)."""
    out = tmp_path / "run"
    launcher = _launch(out)
    logs = _wait_until_running(out, launcher)
    victim = _pid_of("robot_batch_1", logs)
    killed_at = time.time()
    os.kill(victim, signal.SIGKILL)
    _, err = launcher.communicate(timeout=240)
    assert launcher.returncode == 0, err
    assert "robot_batch_1 was killed by SIGKILL; the world removes its robots (--on-batch-loss remove)" in err
    assert "restarted" not in err and "[INFO]" not in err  # no restart under 'remove', and no unrelated log line
    world_log = (out / "logs" / "world.log").read_text()
    detected = _lost_at(world_log, "robot_batch_1")
    assert detected - killed_at < STALL_S, f"noticed {detected - killed_at:.2f} s after the kill"
    summary = _check_consistent_run(out, 1)
    assert summary["restarts"] == []
    assert (out / "logs" / "launcher.log").read_text().count("started robot_batch_1 ") == 1
    removed_at, _, _, removed_tick = _REMOVED.search(world_log).groups()
    waited = float(removed_at) - detected
    assert LOSS_CONFIRM_S <= waited < LOSS_CONFIRM_S + 1.0, f"removed {waited:.2f} s after the notice"
    assert summary["losses"][0]["tick"] == int(removed_tick)  # removed at the end of the tick after the notice
    assert not processes_mentioning(str(out)), "a process outlived the run"


def test_a_stalled_robot_batch_is_dropped_and_cannot_corrupt_the_world_when_it_resumes(tmp_path):
    out = tmp_path / "run"
    launcher = _launch(out)
    logs = _wait_until_running(out, launcher)
    victim = _pid_of("robot_batch_2", logs)
    os.kill(victim, signal.SIGSTOP)
    try:
        # stopped until it is removed: its liveliness back before LOSS_CONFIRM_S would make it a pause
        wait_for(lambda: _REMOVED.search((logs / "world.log").read_text()), 120, "the stopped batch's removal")
    finally:
        os.kill(victim, signal.SIGCONT)  # back, with decisions for ticks long gone and robots it no longer has
    _, err = launcher.communicate(timeout=240)
    assert launcher.returncode == 0, err
    _check_consistent_run(out, 2)
    assert not processes_mentioning(str(out)), "a process outlived the run"


def test_a_monitor_killed_past_the_restart_bound_fails_the_command_and_its_recording_stays_readable(tmp_path):
    """With no restart left (--max-restarts 0) a killed monitor fails the command at once: nothing can write the
    run directory. (Restarts: test_node_restarts.py.) What it had recorded reads back."""
    out = tmp_path / "run"
    launcher = _launch(out, 2, "--max-restarts", "0")
    logs = _wait_until_running(out, launcher, batches=2)
    partial = tmp_path / "run.partial.rrd"
    os.kill(_pid_of("monitor", logs), signal.SIGKILL)
    start = time.monotonic()
    _, err = launcher.communicate(timeout=240)
    assert launcher.returncode == 1, err  # a run failure, not bad input
    assert "monitor was killed by SIGKILL; it was restarted 0 times already (--max-restarts)" in err
    assert "Traceback" not in err and not out.exists()
    rec = Recording(partial)  # no footer (killed), but what was sent reads back
    ticks = sorted(rec.series["localized"])
    assert len(ticks) >= 64 and ticks == list(range(len(ticks))) and rec.events == []
    assert len(rec.robots) >= 64 and sorted(rec.robots) == list(range(len(rec.robots)))
    assert time.monotonic() - start < 60
    assert not processes_mentioning(str(out)), "a process outlived the run"
