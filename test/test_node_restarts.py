"""The world and the monitor SIGKILLed at the moments only processes have come back, and the run directory is
byte-identical to the unfaulted run's: metrics.csv, final_state.csv and the outcome; the bag holds every tick
(bagcheck) and the recording every tick's metrics and robots. The moments: the world while it starts (before tick 0),
each in the middle, the monitor while it writes the run directory, and each during its restart (killed again). Past
the restart bound the command fails (the run so far is written, as interrupted). The kills in the middle run with the
robots every 6th tick (``--record-every 6``, as large swarms run by default); the others with the robots every tick.
Kills at moments that do not overlap share a run: the world's, then the monitor's.

A world's checkpoint of tick 0 or one mid-run, restored, goes on as the unbroken run on plain code
(test_study_central); the rubenstein algorithm's world and monitor are killed at their own moments, the monitor's
start-up among them, in test_rubenstein_graph.

A kill is timed on what the run writes: the world's checkpoint (its header holds the last tick saved, read
here as the restarted world reads it), the monitor's recording, the temporary run directory.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from graph_runs import (
    STAR_SHORT,
    finish_restarted_run,
    kill_node,
    kill_starting,
    node_pid,
    processes_mentioning,
    run_env,
    staged_logs,
    wait_saved,
)
from recordings import Recording
from waiting import wait_for

from swarm_ros.app import cli

pytestmark = pytest.mark.process

SHORT = STAR_SHORT


def _launch(out: Path, *extra: str) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "swarm_ros", "run", *SHORT, "--processes", "2", "--out", str(out), "--quiet", *extra],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=run_env(),
    )


@pytest.fixture(scope="module")
def reference(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("node-restart-ref") / "ref"
    assert cli.main(["simulate", *SHORT, "--out", str(out), "--quiet", "--no-recording"]) == 0
    return out


def _recording_whole(out: Path, every: int = 1) -> Recording:
    """The recording has every tick's metrics, and the robots every ``every``-th tick and at the last
    (metrics.csv: a header, then a line per tick)."""
    rec = Recording(out / "recording.rrd")
    ticks = list(range((out / "metrics.csv").read_text().count("\n") - 1))
    assert sorted(rec.series["localized"]) == ticks and sorted(rec.robots) == sorted({*ticks[::every], ticks[-1]})
    return rec


def _final_tick(reference: Path) -> int:
    return (reference / "metrics.csv").read_text().count("\n") - 2  # a header, then one line per tick from 0


# -- the world and the monitor ----------------------------------------------------------------------------
def test_a_world_killed_before_tick_0_and_a_monitor_killed_while_it_writes_the_run_directory_come_back(
    reference, tmp_path
):
    """The world killed as it starts (graph_runs.kill_starting) starts again; the monitor killed once the writing
    of the run directory has begun (write_run's temporary directory) writes it again, whole."""
    out = tmp_path / "run"
    launcher = _launch(out)
    kill_starting(out, "world")
    wait_for(lambda: list(tmp_path.glob(".run.tmp-*")), 180, "the run directory's writing", poll=0.001)
    kill_node(out, "monitor")
    summary = finish_restarted_run(launcher, reference, out, ["world", "monitor"])
    assert summary["restarts"][0]["tick"] == 0
    _recording_whole(out)
    assert not list(tmp_path.glob(".run.*")), "nothing of the run left beside it"


def test_a_world_then_a_monitor_killed_mid_run_go_on_and_the_run_is_identical_and_whole(reference, tmp_path):
    """The world from its checkpoint, then the monitor from its bag; the recording shows each restart at its tick.
    With ``--record-every 6`` the world sends its tally every tick and every robot's row every 6th: a new world
    sends again, from its checkpoint, the tallies and rows the monitor has not confirmed; a new monitor counts
    the ticks of its bag from their tallies and its view from their rows. (Every other kill here runs with
    the robots every tick.)"""
    out = tmp_path / "run"
    launcher = _launch(out, "--record-every", "6")
    logs = staged_logs(out)
    wait_saved(logs, 300)
    kill_node(out, "world")
    wait_saved(logs, 600)  # the new world went on past what the monitor held when the world was killed
    kill_node(out, "monitor")
    summary = finish_restarted_run(launcher, reference, out, ["world", "monitor"])
    # at the tick each went on from: the world's checkpoint's (tick 0 here: it saves every 1,000 ticks), the last the
    # monitor's bag held
    ticks = {r["node"]: r["tick"] for r in summary["restarts"]}
    assert 0 <= ticks["world"] < 300 <= ticks["monitor"] < _final_tick(reference), ticks
    assert summary["bag_robots_every"] == summary["recording_robots_every"] == 6
    rec = _recording_whole(out, every=6)
    for node, went_on, logged in (
        ("world", "a new world process went on from its checkpoint", "restarted: on from the checkpoint of tick"),
        ("monitor", "a new monitor process went on from its bag", "went on from tick"),
    ):
        tick = ticks[node]
        assert [e for e in rec.events if e[1].startswith(f"{node} restarted")] == [
            (tick, f"{node} restarted at tick {tick}: {went_on}")
        ]
        assert logged in (out / "logs" / f"{node}.log").read_text()
    # DDS forgot the killed monitor's readers 3 s after the kill (config/fastdds.xml's lease), so the world's last
    # status did not wait out LINGER for them (the 20 s default lease made it, in every such run)
    assert "unacknowledged" not in (out / "logs" / "world.log").read_text()


def test_a_world_killed_more_often_than_the_bound_fails_the_run_and_claims_no_outcome(reference, tmp_path):
    out = tmp_path / "run"
    launcher = _launch(out, "--no-recording", "--max-restarts", "0")
    wait_saved(staged_logs(out), 100)
    kill_node(out, "world")
    _, err = launcher.communicate(timeout=120)
    assert launcher.returncode != 0
    assert "world was killed by SIGKILL; it was restarted 0 times already (--max-restarts)" in err
    assert "Traceback" not in err
    # the monitor, stopped, writes the run so far, and says so: nothing claims an outcome the run did not reach
    assert json.loads((out / "summary.json").read_text())["outcome"] == "interrupted"
    assert not processes_mentioning(str(out)), "a process outlived the run"


def _restarting(out: Path, node: str) -> None:
    """Wait for the moment a restarted ``node`` process is killed again: the world's as soon as it exists
    (importing); the monitor's once it has made its own bag, before it has copied its process before's into it
    and gone on from it (what a third process must then find and go on from)."""
    if node == "monitor":
        bags = out.parent.glob
        wait_for(lambda: len(list(bags(f".{out.name}.bag-*"))) >= 2, 60, "the restarted monitor's bag", poll=0.001)


def test_a_world_then_a_monitor_killed_again_while_they_restart_each_come_back_twice(reference, tmp_path):
    out = tmp_path / "run"
    launcher = _launch(out, "--no-recording")
    logs = staged_logs(out)
    for node, tick in (("world", 300), ("monitor", 600)):
        wait_saved(logs, tick)
        first = kill_node(out, node)
        second = node_pid(out, node, not_pid=first)
        _restarting(out, node)
        os.kill(second, signal.SIGKILL)
        node_pid(out, node, not_pid=second)  # the third process, which goes on
    finish_restarted_run(launcher, reference, out, ["world", "world", "monitor", "monitor"])
    # the moments were the ones meant: the second process of each never went on, the third did
    for node, went_on in (("world", "restarted: on from the checkpoint of tick"), ("monitor", "went on from tick")):
        assert (out / "logs" / f"{node}.log").read_text().count(went_on) == 1
