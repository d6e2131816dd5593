"""The world and the monitor SIGKILLed at the moments only processes have come back, and the run directory is
byte-identical to the unfaulted run's: metrics.csv, final_state.csv and the outcome; the bag holds every tick
(bagcheck) and the recording every tick's metrics and robots. The moments: the world while it starts (before tick 0),
each in the middle, the monitor while it writes the run directory, and each during its restart (killed again). Past
the restart bound the command fails (the run so far is written, as interrupted). The kills in the middle run with the
robots every 6th tick (``--record-every 6``, as large swarms run by default); the others with the robots every tick.

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
from bagcheck import assert_bag_holds_run
from graph_runs import (
    STAR_SHORT,
    assert_identical_run,
    finish_restarted_run,
    kill_node,
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


# -- the world ------------------------------------------------------------------------------------------
def test_a_world_killed_before_tick_0_starts_again_and_the_run_is_identical(reference, tmp_path):
    out = tmp_path / "run"
    launcher = _launch(out, "--no-recording")
    kill_node(out, "world")  # seen as soon as it exists: still importing
    summary = finish_restarted_run(launcher, reference, out, ["world"])
    assert summary["restarts"][0]["tick"] == 0


@pytest.mark.parametrize(
    ("node", "went_on", "logged"),
    [
        ("world", "a new world process went on from its checkpoint", "restarted: on from the checkpoint of tick"),
        ("monitor", "a new monitor process went on from its bag", "went on from tick"),
    ],
)
def test_a_node_killed_mid_run_goes_on_and_the_run_is_identical_and_whole(reference, tmp_path, node, went_on, logged):
    """The world from its checkpoint, the monitor from its bag; the recording shows the restart at its tick.
    With ``--record-every 6`` the world sends its tally every tick and every robot's row every 6th: a new world
    sends again, from its checkpoint, the tallies and rows the monitor has not confirmed; a new monitor counts
    the ticks of its bag from their tallies and its view from their rows. (Every other kill here runs with
    the robots every tick.)"""
    out = tmp_path / "run"
    launcher = _launch(out, "--record-every", "6")
    wait_saved(staged_logs(out), 300)
    kill_node(out, node)
    summary = finish_restarted_run(launcher, reference, out, [node])
    # at the tick it went on from: the world's checkpoint's (tick 0 here: it saves every 1,000 ticks), the last the
    # monitor's bag held
    tick = summary["restarts"][0]["tick"]
    assert (0 <= tick if node == "world" else 0 < tick) and tick < _final_tick(reference)
    assert summary["bag_robots_every"] == summary["recording_robots_every"] == 6
    rec = _recording_whole(out, every=6)
    assert [e for e in rec.events if e[1].startswith(f"{node} restarted")] == [
        (tick, f"{node} restarted at tick {tick}: {went_on}")
    ]
    assert logged in (out / "logs" / f"{node}.log").read_text()


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


# -- the monitor ----------------------------------------------------------------------------------------
def test_a_monitor_killed_while_it_writes_the_run_directory_writes_it_again(reference, tmp_path):
    out = tmp_path / "run"
    launcher = _launch(out)
    # write_run's temporary directory: the writing has begun
    wait_for(lambda: list(tmp_path.glob(".run.tmp-*")), 180, "the run directory's writing", poll=0.001)
    kill_node(out, "monitor")
    _, err = launcher.communicate(timeout=300)
    assert launcher.returncode == 0, err
    assert_identical_run(reference, out)
    assert_bag_holds_run(out)
    _recording_whole(out)
    assert not list(tmp_path.glob(".run.*")), "nothing of the run left beside it"


def _restarting(out: Path, node: str) -> None:
    """Wait for the moment a restarted ``node`` process is killed again: the world's as soon as it exists
    (importing); the monitor's once it has made its own bag, before it has copied its process before's into it
    and gone on from it (what a third process must then find and go on from)."""
    if node == "monitor":
        bags = out.parent.glob
        wait_for(lambda: len(list(bags(f".{out.name}.bag-*"))) >= 2, 60, "the restarted monitor's bag", poll=0.001)


@pytest.mark.parametrize(
    ("node", "went_on"),
    [("world", "restarted: on from the checkpoint of tick"), ("monitor", "went on from tick")],
)
def test_a_node_killed_again_while_it_restarts_comes_back_twice(reference, tmp_path, node, went_on):
    out = tmp_path / "run"
    launcher = _launch(out, "--no-recording")
    wait_saved(staged_logs(out), 500)
    first = kill_node(out, node)
    second = node_pid(out, node, not_pid=first)
    _restarting(out, node)
    os.kill(second, signal.SIGKILL)
    finish_restarted_run(launcher, reference, out, [node, node])
    # the moment was the one meant: the second process never went on, the third did
    assert (out / "logs" / f"{node}.log").read_text().count(went_on) == 1
