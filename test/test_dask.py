"""swarm-ros experiment --executor dask: the same rows as the local executor, resume, a killed
worker, Ctrl-C, and what it refuses. One LocalCluster serves the tests that pass --scheduler. (A scheduler that is
not there is a row of docs/bad_input.md: one line, exit 2, nothing written.)"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import psutil
import pytest
from waiting import wait_for

from swarm_ros.app.results_file import read_results

pytestmark = pytest.mark.process

SMALL = """\
name: small
seed: 3
repetitions: {reps}
vision_radius: 1
rules: paper
max_ticks: 20000
shapes:
  rectangle: [400, patches]
  wrench: [500]
"""


def _experiment(tmp_path: Path, reps: int = 2) -> Path:
    config = tmp_path / f"small{reps}.yaml"
    config.write_text(SMALL.format(reps=reps), encoding="utf-8")
    return config


def _cli(*args: str, env: dict | None = None, timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "swarm_ros", "experiment", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        env=env,
    )


def _rows(results: Path) -> list[tuple]:
    """results.csv as sorted rows, without the one column that may differ (wall time)."""
    rows = read_results(results)
    return sorted(tuple((k, v) for k, v in row.items() if k != "wall_seconds") for row in rows)


@pytest.fixture(scope="module")
def scheduler():
    import logging

    from dask.distributed import LocalCluster

    with LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0", silence_logs=logging.ERROR
    ) as cluster:
        yield cluster.scheduler_address


@pytest.fixture(scope="module")
def local_rows(tmp_path_factory) -> list[tuple]:
    tmp = tmp_path_factory.mktemp("local")
    done = _cli(str(_experiment(tmp)), "--out", str(tmp / "exp"), "--jobs", "2", "--quiet")
    assert done.returncode == 0, done.stderr
    return _rows(tmp / "exp" / "results.csv")


def test_a_sweep_on_a_scheduler_gives_the_local_executors_rows(tmp_path, scheduler, local_rows):
    out = tmp_path / "exp"
    done = _cli(str(_experiment(tmp_path)), "--out", str(out), "--executor", "dask", "--scheduler", scheduler)
    assert done.returncode == 0, done.stderr
    assert f"Dask: {scheduler}, dashboard http" in done.stderr
    assert len(local_rows) == 6 and _rows(out / "results.csv") == local_rows
    assert (out / "stats.csv").exists()


def test_rerunning_resumes_only_the_missing_runs(tmp_path, scheduler, local_rows):
    out = tmp_path / "exp"
    config = str(_experiment(tmp_path))
    assert _cli(config, "--out", str(out), "--executor", "dask", "--scheduler", scheduler, "--quiet").returncode == 0
    results = out / "results.csv"
    lines = results.read_text(encoding="utf-8").splitlines(keepends=True)
    results.write_text("".join(lines[:-2]), encoding="utf-8")  # as if stopped before the last two finished
    done = _cli(config, "--out", str(out), "--executor", "dask", "--scheduler", scheduler)
    assert done.returncode == 0, done.stderr
    assert "resuming: 4 of 6 runs already in" in done.stderr
    assert _rows(results) == local_rows  # each run once


def _started(config: Path, out: Path, env: dict | None = None) -> subprocess.Popen:
    """An experiment on its own LocalCluster (2 workers), in the background."""
    return subprocess.Popen(
        [
            sys.executable,
            "-m",
            "swarm_ros",
            "experiment",
            str(config),
            "--out",
            str(out),
            "--executor",
            "dask",
            "--jobs",
            "2",
            "--quiet",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )


def _wait_for_rows(results: Path, proc: subprocess.Popen, n: int = 1, limit: float = 60) -> None:
    def rows() -> bool:
        assert proc.poll() is None, f"the experiment ended (exit {proc.returncode}) before {n} runs were written"
        return results.exists() and len(results.read_text(encoding="utf-8").splitlines()) > n  # header + n rows

    wait_for(rows, limit, f"{n} finished runs")


def _workers(proc: subprocess.Popen) -> list[psutil.Process]:
    """The LocalCluster's worker processes: the command's children that run a Dask worker."""
    found = []
    for child in psutil.Process(proc.pid).children(recursive=True):
        try:
            if "multiprocessing" in " ".join(child.cmdline()):
                found.append(child)
        except psutil.NoSuchProcess:
            pass
    return found


def test_a_worker_killed_mid_sweep_loses_no_row(tmp_path):
    config, out = _experiment(tmp_path, reps=4), tmp_path / "exp"
    reference = tmp_path / "ref"
    assert _cli(str(config), "--out", str(reference), "--jobs", "2", "--quiet").returncode == 0
    proc = _started(config, out)
    _wait_for_rows(out / "results.csv", proc)
    workers = _workers(proc)
    assert workers, "the LocalCluster's workers"
    workers[0].kill()  # SIGKILL, mid-sweep: its run is lost with it, and Dask runs it again
    stdout, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 0, stderr
    assert _rows(out / "results.csv") == _rows(reference / "results.csv")


def test_ctrl_c_keeps_the_finished_rows_and_leaves_no_worker(tmp_path, local_rows):
    config, out = _experiment(tmp_path, reps=4), tmp_path / "exp"
    proc = _started(config, out)
    _wait_for_rows(out / "results.csv", proc)
    workers = _workers(proc)
    assert workers
    proc.send_signal(signal.SIGINT)
    stdout, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 130, stderr
    assert "run the same command again to resume" in stderr
    rows = read_results(out / "results.csv")
    assert 1 <= len(rows) < 12
    gone, alive = psutil.wait_procs(workers, timeout=10)
    assert not alive, [p.pid for p in alive]


def test_the_ros2_engine_is_refused_where_runs_could_share_a_domain(tmp_path):
    env = {**os.environ, "ROS_DOMAIN_ID": "7"}
    done = _cli(
        str(_experiment(tmp_path)),
        "--out",
        str(tmp_path / "exp"),
        "--engine",
        "ros2",
        "--executor",
        "dask",
        "--jobs",
        "1",
        "--quiet",
        env=env,
    )
    assert done.returncode == 2
    assert (
        done.stderr.strip().splitlines() == [done.stderr.strip()]
        and "--engine ros2 on Dask needs a ROS domain of its own for each run" in done.stderr
    )
    assert "ROS_DOMAIN_ID=7" in done.stderr and not (tmp_path / "exp").exists()  # refused before writing


@pytest.mark.parametrize(
    "run_seconds,remaining,workers,expected",
    [
        (None, 360, 2, 1),  # no run finished yet: one per task
        (3.0, 360, 2, 1),  # runs of seconds (a ROS 2 graph): one per task
        (0.0125, 300, 2, 20),  # 12.5 ms paper-protocol runs: a quarter of a second of runs per task
        (0.0125, 12, 2, 4),  # near the end: no less than 50 ms of runs...
        (0.0125, 3, 2, 3),  # ...but no more than is left
        (0.0125, 60, 4, 7),  # half a worker's share of what is left
    ],
)
def test_a_dask_task_holds_a_quarter_second_of_runs_but_the_workers_finish_together(
    run_seconds, remaining, workers, expected
):
    from swarm_ros.app.executors import chunk_size

    assert chunk_size(run_seconds, remaining, workers) == expected


def test_short_runs_share_dask_tasks_and_each_run_comes_back_once(tmp_path, scheduler):
    from dask.distributed import Client, get_task_stream

    from swarm_ros.app.executors import execute_dask, run_inprocess
    from swarm_ros.app.experiment_file import load_experiment

    todo = load_experiment(_experiment(tmp_path, reps=15)).runs()
    with Client(scheduler) as client, get_task_stream(client) as stream:
        rows = list(execute_dask(client, todo, "inprocess", 2))
    tasks = [t for t in stream.data if t["key"].startswith("swarm_ros-runs-")]
    assert len(rows) == len(todo) == 45  # 3 (shape, group size) pairs x 15
    assert len(tasks) < len(todo), "the short runs were sent one per task"
    without_time = lambda row: {k: v for k, v in row.items() if k != "wall_seconds"}
    assert sorted(map(str, map(without_time, rows))) == sorted(str(without_time(run_inprocess(s))) for s in todo)


def test_the_ros2_engine_runs_on_dask_workers_and_equals_the_in_process_engine(tmp_path, scheduler):
    config = tmp_path / "tiny.yaml"
    config.write_text(
        "name: tiny\nseed: 5\nrepetitions: 1\nvision_radius: 1\nrules: paper\nmax_ticks: 20000\n"
        "shapes:\n  rectangle: [120]\n",
        encoding="utf-8",
    )
    out, ref = tmp_path / "exp", tmp_path / "ref"
    done = _cli(
        str(config), "--out", str(out), "--executor", "dask", "--scheduler", scheduler, "--engine", "ros2", "--quiet"
    )
    assert done.returncode == 0, done.stderr
    assert _cli(str(config), "--out", str(ref), "--jobs", "1", "--quiet").returncode == 0
    (ros,), (inprocess,) = read_results(out / "results.csv"), read_results(ref / "results.csv")
    assert (ros["engine"], inprocess["engine"]) == ("ros2", "inprocess")
    same = lambda row: {k: v for k, v in row.items() if k not in ("engine", "wall_seconds")}
    assert same(ros) == same(inprocess)


def test_an_output_directory_of_something_else_is_refused_before_a_cluster_starts(tmp_path):
    out = tmp_path / "exp"
    out.mkdir()
    (out / "mine.txt").write_text("not the tool's", encoding="utf-8")
    done = _cli(str(_experiment(tmp_path)), "--out", str(out), "--executor", "dask", "--jobs", "1")
    assert done.returncode == 2
    assert done.stderr.count("\n") == 1 and "is not empty and holds no" in done.stderr  # no "Dask: ..." line
    assert [p.name for p in out.iterdir()] == ["mine.txt"]


def _heartbeat_failure(exc: BaseException, msg: str = "Failed to communicate with scheduler during heartbeat."):
    import logging

    return logging.LogRecord("distributed.worker", logging.ERROR, "worker.py", 1, msg, None, (type(exc), exc, None))


def test_a_closed_connection_at_a_heartbeat_is_the_one_worker_error_dropped():
    """The record a worker logs when the closing scheduler cut its heartbeat is dropped; the same message for
    another fault, and another error with the same exception, still show."""
    import asyncio

    from distributed.comm.core import CommClosedError

    from swarm_ros.app.dask_workers import keep

    assert not keep(_heartbeat_failure(CommClosedError("in <TCP (closed)>: Stream is closed")))
    assert not keep(_heartbeat_failure(asyncio.CancelledError()))  # its handshake cancelled by the worker's close
    assert keep(_heartbeat_failure(OSError("Connection refused")))
    assert keep(_heartbeat_failure(CommClosedError("closed"), msg="Unexpected exception during heartbeat."))


def test_the_heartbeat_filter_outlives_the_plugins_teardown():
    """A worker's last heartbeat can fail after its plugins are torn down (the suite on three workers printed its
    traceback)."""
    import logging

    from swarm_ros.app.dask_workers import QuietHeartbeatAtClose, keep

    log = logging.getLogger("distributed.worker")
    plugin = QuietHeartbeatAtClose()
    try:
        plugin.setup(None)
        plugin.teardown(None)
        assert keep in log.filters
    finally:
        log.removeFilter(keep)


def _drops_heartbeat_failures() -> bool:
    import logging

    from swarm_ros.app.dask_workers import keep

    return keep in logging.getLogger("distributed.worker").filters


def test_only_the_local_clusters_workers_drop_the_heartbeat_error(scheduler):
    """The LocalCluster an experiment starts gives each of its workers the filter; the workers of a scheduler
    the user runs are left as they are."""
    from swarm_ros.app.executors import dask_client

    with dask_client(None, 2, "inprocess", quiet=True) as client:
        ours = client.run(_drops_heartbeat_failures)
    with dask_client(scheduler, 2, "inprocess", quiet=True) as client:
        theirs = client.run(_drops_heartbeat_failures)
    assert len(ours) == 2 and all(ours.values()), ours
    assert len(theirs) == 2 and not any(theirs.values()), theirs
