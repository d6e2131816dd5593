"""recording.rrd: what the in-process engine logs, read back with rerun's reader and checked
against metrics.csv and final_state.csv; every k-th tick; runs stopped early; live streaming.

The ROS 2 engine's recordings are compared with these in test_ros_graph.py.
"""

from __future__ import annotations

import csv
import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from recordings import Recording, rrd_verify
from waiting import wait_for

from swarm_ros.app import cli
from swarm_ros.artifacts.darr_niazi.scene import FILLED, FREE, MAP, OCCUPANCY, ROBOTS, RUN_INFO, SERIES, WORLD
from swarm_ros.core.darr_niazi.engine import Simulation
from swarm_ros.core.darr_niazi.metrics import METRIC_COLUMNS
from swarm_ros.core.darr_niazi.state import RobotState
from swarm_ros.core.params import RunParams

pytestmark = pytest.mark.process

FLAGS = ["--shape", "rectangle", "--robots", "460", "--seed", "3", "--quiet"]  # complete_with_extras, 716 ticks


def simulate(out: Path, *extra: str) -> int:
    return cli.main(["simulate", *FLAGS, "--out", str(out), *extra])


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("rec") / "run"
    assert simulate(out) == 0
    return out


@pytest.fixture(scope="module")
def recording(run_dir) -> Recording:
    return Recording(run_dir / "recording.rrd")


def metrics_rows(run_dir: Path) -> np.ndarray:
    rows = list(csv.reader((run_dir / "metrics.csv").open()))
    assert tuple(rows[0]) == METRIC_COLUMNS
    return np.array(rows[1:], dtype=np.int64)


def final_state(run_dir: Path) -> tuple[np.ndarray, np.ndarray]:
    rows = list(csv.DictReader((run_dir / "final_state.csv").open()))
    codes = {s.label: int(s) for s in RobotState}
    xy = np.array([(float(r["x"]), float(r["y"])) for r in rows])
    return xy, np.array([codes[r["state"]] for r in rows])


def assert_matches_run(rec: Recording, run_dir: Path, every: int = 1) -> None:
    """The recording's series equal metrics.csv, its last robots equal final_state.csv, its event the outcome."""
    rows = metrics_rows(run_dir)
    summary = json.loads((run_dir / "summary.json").read_text())
    last = summary["convergence_tick"]
    assert set(rec.series) == set(SERIES)
    for name in SERIES:
        col = rows[:, METRIC_COLUMNS.index(name)]
        assert rec.series[name] == dict(zip(rows[:, 0].tolist(), col.astype(float).tolist())), name
    expected_ticks = sorted({t for t in range(0, last + 1, every)} | {last})
    assert sorted(rec.robots) == expected_ticks
    xy, codes = final_state(run_dir)
    positions, classes = rec.robots[last]
    assert positions.dtype == np.float32
    assert np.array_equal(positions, xy.astype(np.float32))
    assert np.array_equal(classes, codes)
    assert rec.events == [(last, rec.events[0][1])]
    assert rec.events[0][1].startswith(f"{summary['outcome']} at tick {last}: {summary['localized']} localized")


def test_simulate_writes_recording_and_convergence_plot(run_dir):
    assert sorted(p.name for p in run_dir.iterdir()) == [
        "convergence.png",
        "final.png",
        "final_state.csv",
        "metrics.csv",
        "recording.rrd",
        "summary.json",
    ]
    assert (run_dir / "convergence.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not list(run_dir.parent.glob("*.partial.rrd"))


def test_recording_holds_every_tick_of_metrics_and_robots(recording, run_dir):
    assert_matches_run(recording, run_dir)


def test_recording_holds_the_static_world_blueprint_and_occupancy(recording, run_dir):
    assert {f"/{e}" for e in (WORLD, MAP, OCCUPANCY, ROBOTS, RUN_INFO)} <= recording.static
    assert recording.blueprints == 1
    # occupancy is logged when it changes; the last image is the final filled shape
    summary = json.loads((run_dir / "summary.json").read_text())
    last_image = recording.occupancy[max(recording.occupancy)]
    assert set(np.unique(last_image)) <= {FREE, FILLED}
    assert int((last_image == FILLED).sum()) == summary["localized"]
    assert min(recording.occupancy) == 0 and int((recording.occupancy[0] == FILLED).sum()) == 4  # the seeds
    counts = [int((img == FILLED).sum()) for _, img in sorted(recording.occupancy.items())]
    assert counts == sorted(set(counts)), "an image is logged only when the filled patches changed"


def run_table(rrd: Path) -> str:
    """The recording's static run table (the run's parameters, markdown)."""
    import warnings

    from rerun.chunk import RrdReader

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        chunks = RrdReader(str(rrd)).stream().to_chunks()
    texts = [
        c.to_record_batch().column("TextDocument:text").flatten().to_pylist()[0]
        for c in chunks
        if c.entity_path == f"/{RUN_INFO}" and c.is_static
    ]
    assert len(texts) == 1
    return texts[0]


def test_the_run_table_names_the_rule_set_and_its_switches(run_dir):
    table = run_table(run_dir / "recording.rrd")
    for row in (
        "| rules | paper |",
        "| join | walk |",
        "| crowding | ahead |",
        "| steps | one |",
        "| rule set in force | paper |",
        "| robots logged | every 1 tick(s) |",
    ):
        assert row in table, row


def test_rerun_rrd_verify_passes(run_dir):
    done = rrd_verify(run_dir / "recording.rrd")
    assert done.returncode == 0, done.stderr


def test_every_kth_tick_logs_fewer_robots_and_every_metric(tmp_path):
    out = tmp_path / "every"
    assert simulate(out, "--record-every", "50") == 0
    assert_matches_run(Recording(out / "recording.rrd"), out, every=50)


def test_a_large_swarm_is_logged_every_kth_tick_chosen_from_its_size_and_says_so(tmp_path, monkeypatch, capsys):
    """With no --record-every, a swarm of more robots than POSES_PER_TICK is logged every ceil(N / it)-th tick
    (lowered here so that the 460 robots stand for a large swarm); the run table and the command say so."""
    from swarm_ros.artifacts import recording_options
    from swarm_ros.core import params

    monkeypatch.setattr(params, "POSES_PER_TICK", 200)
    out = tmp_path / "auto"
    assert cli.main(["simulate", *[f for f in FLAGS if f != "--quiet"], "--out", str(out)]) == 0
    assert_matches_run(Recording(out / "recording.rrd"), out, every=3)
    assert (
        "the recording logs the robots every 3 ticks (460 robots; --record-every 1 logs every tick)"
        in capsys.readouterr().err
    )
    assert "| robots logged | every 3 tick(s) |" in run_table(out / "recording.rrd")
    monkeypatch.setattr(params, "POSES_PER_TICK", 460)  # as many as the swarm: every tick
    assert recording_options.RecordingOptions().every_for(RunParams(460)) == 1
    assert recording_options.RecordingOptions(every=7).every_for(RunParams(10**6)) == 7  # chosen by the user: kept


def test_same_seed_gives_a_recording_with_the_same_data(recording, tmp_path):
    out = tmp_path / "again"
    assert simulate(out) == 0
    assert Recording(out / "recording.rrd").same_data(recording)


def test_no_recording_flag_writes_none(tmp_path):
    out = tmp_path / "none"
    assert simulate(out, "--no-recording") == 0
    assert not (out / "recording.rrd").exists() and (out / "convergence.png").exists()


def _stop_at_tick_120(monkeypatch, error):
    """From tick 120 on, Simulation.run raises ``error``, or, for SIGINT, sends it to this process."""
    real_run = Simulation.run

    def run(self, max_ticks=None, on_tick=None):
        if self.tick >= 120:
            if error is signal.SIGINT:
                os.kill(os.getpid(), signal.SIGINT)  # what Ctrl-C does; simulate checks for it between chunks
                return None
            raise error("stop")
        return real_run(self, max_ticks=min(max_ticks or 10**9, 120 - self.tick), on_tick=on_tick)

    monkeypatch.setattr(Simulation, "run", run)


@pytest.mark.parametrize("algorithm, shape, robots", [("darr-niazi", "rectangle", 460), ("rubenstein", "star", 200)])
def test_a_close_stuck_on_a_full_disk_gives_up_and_removes_the_file_one_that_ends_is_kept(
    tmp_path, monkeypatch, algorithm, shape, robots
):
    """Rerun's disconnect() can hang for good after the disk filled (a monitor was killed in it in CI, leaving a
    recording without its footer): on a full disk, a file that stops growing for STUCK_S is given up on and
    removed; with free space the close waits for a slow disconnect, however long, and keeps a whole file. Every
    algorithm's recording ends so (rerun_recording.close_stream)."""
    import threading

    import rerun as rr

    from swarm_ros.artifacts import rerun_recording
    from swarm_ros.artifacts.recording_options import RecordingOptions
    from swarm_ros.artifacts.run_dir import RecordingError
    from swarm_ros.core import Shape
    from swarm_ros.core.algorithm import algorithm_of

    entry = algorithm_of(algorithm)
    run = entry.hook("engine")(Shape.load(shape), RunParams(robots=robots, seed=3, algorithm=algorithm))
    stuck = entry.hook("recording")(tmp_path / "stuck.rrd", run, RecordingOptions())
    never, disconnect = threading.Event(), rr.RecordingStream.disconnect
    monkeypatch.setattr(rr.RecordingStream, "disconnect", lambda rec: never.wait(60))  # stuck on the full disk
    monkeypatch.setattr(rerun_recording, "_disk_full", lambda path: True)
    began = time.monotonic()
    with pytest.raises(RecordingError, match="could not be written whole .no space left on device.; it is removed"):
        stuck.finish(run, "failed")
    assert time.monotonic() - began < rerun_recording.STUCK_S + 5  # given up on, not waited out
    assert not (tmp_path / "stuck.rrd").exists()
    never.set()

    monkeypatch.setattr(rerun_recording, "_disk_full", lambda path: False)
    slow = entry.hook("recording")(tmp_path / "slow.rrd", run, RecordingOptions())
    monkeypatch.setattr(
        rr.RecordingStream, "disconnect", lambda rec: (time.sleep(rerun_recording.STUCK_S + 0.5), disconnect(rec))
    )
    slow.finish(run, "failed")
    assert rrd_verify(tmp_path / "slow.rrd").returncode == 0


def test_a_crashed_run_keeps_a_readable_recording_up_to_that_tick(tmp_path, monkeypatch, capsys):
    _stop_at_tick_120(monkeypatch, RuntimeError)
    out = tmp_path / "run"
    with pytest.raises(RuntimeError):
        simulate(out)
    assert not out.exists()
    partial = tmp_path / "run.partial.rrd"
    assert f"the recording so far is in {partial}" in capsys.readouterr().err
    assert rrd_verify(partial).returncode == 0
    rec = Recording(partial)
    assert max(rec.robots) == 120 and max(rec.series["localized"]) == 120
    assert rec.events == [(120, rec.events[0][1])] and rec.events[0][1].startswith("failed at tick 120")


def test_an_interrupted_run_writes_its_run_directory_so_far(tmp_path, monkeypatch, capsys):
    _stop_at_tick_120(monkeypatch, signal.SIGINT)
    out = tmp_path / "run"
    assert simulate(out) == 130
    assert f"interrupted at tick 120; the run so far is in {out}" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]  # no partial file left beside it
    summary = json.loads((out / "summary.json").read_text())
    assert summary["outcome"] == "interrupted" and summary["convergence_tick"] == 120
    assert len(metrics_rows(out)) == 121
    assert rrd_verify(out / "recording.rrd").returncode == 0
    assert_matches_run(Recording(out / "recording.rrd"), out)
    assert (out / "final.png").stat().st_size > 0 and (out / "convergence.png").stat().st_size > 0


def test_a_killed_run_leaves_a_recording_readable_up_to_the_last_batch(tmp_path):
    """SIGKILL: no footer is written, but what was sent before is in the file and reads back."""
    out = tmp_path / "killed"
    code = (
        "import sys, numpy as np; from swarm_ros.app import cli; from swarm_ros.core.darr_niazi.engine import "
        "Simulation\n"
        "real = Simulation.run\n"
        "def run(self, max_ticks=None, on_tick=None):\n"
        "    if self.tick >= 300:\n"
        "        import os, signal, time; time.sleep(0.5); os.kill(os.getpid(), signal.SIGKILL)\n"
        "    return real(self, max_ticks=min(max_ticks or 10**9, 300 - self.tick), on_tick=on_tick)\n"
        "Simulation.run = run\n"
        f"cli.main(['simulate', *{FLAGS!r}, '--out', {str(out)!r}])\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == -signal.SIGKILL, done.stderr
    rec = Recording(tmp_path / "killed.partial.rrd")
    batch = 64  # recording.BATCH_TICKS: ticks 0..255 were sent in whole batches before the kill
    assert set(range(4 * batch)) <= set(rec.robots) and max(rec.robots) <= 300
    assert rec.events == []


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_connect_to_a_port_where_no_viewer_listens_says_so_in_one_line_and_goes_on(tmp_path, capsys):
    import socket

    with socket.socket() as s:  # a port that was free a moment ago: nothing listens there
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    url = f"rerun+http://127.0.0.1:{port}/proxy"
    assert simulate(tmp_path / "run", "--connect", url) == 0
    err = capsys.readouterr().err
    assert err == f"swarm-ros: warning: no Rerun viewer answers at {url} (Connection refused); going on without it\n"
    assert (tmp_path / "run" / "recording.rrd").is_file()


def test_connect_streams_the_same_data_to_a_running_viewer(recording, tmp_path):
    """A headless `rerun --serve-grpc --save` stands in for a viewer and saves what it receives."""
    port, saved = _free_port(), tmp_path / "live.rrd"
    server = subprocess.Popen(
        [str(Path(sys.executable).with_name("rerun")), "--serve-grpc", "--port", str(port), "--save", str(saved)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )

    def listening() -> bool:
        with socket.socket() as s:
            return s.connect_ex(("127.0.0.1", port)) == 0

    def saved_whole() -> bool:  # the server writes what it receives as it comes: read until it is all there
        try:
            return Recording(saved).same_data(recording)
        except Exception:  # not there yet, or cut short mid-message
            return False

    try:
        wait_for(listening, 30, "the stand-in viewer listening", poll=0.1)
        out = tmp_path / "run"
        assert simulate(out, "--connect", f"rerun+http://127.0.0.1:{port}/proxy") == 0
        wait_for(saved_whole, 30, "the viewer saving everything the run streamed", poll=0.2)
    finally:
        server.send_signal(signal.SIGINT)
        server.communicate(timeout=30)
    assert Recording(saved).same_data(recording)
    assert Recording(out / "recording.rrd").same_data(recording)


@pytest.mark.parametrize(
    "args,message",
    [
        (["--record-every=-1"], "record_every must be an integer >= 1 (0 = chosen from the swarm's size), got -1"),
        (["--connect", "http://localhost:9876"], "viewer URL must start with one of rerun://"),
    ],
)
def test_bad_recording_options_get_one_line_and_write_nothing(tmp_path, capsys, args, message):
    assert simulate(tmp_path / "run", *args) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1
    assert list(tmp_path.iterdir()) == []


def _fake_viewer(tmp_path: Path, body: str) -> str:
    exe = tmp_path / "rerun"
    exe.write_text(f"#!{sys.executable}\n{body}\n")
    exe.chmod(0o755)
    return str(exe)


def test_spawn_returns_the_url_of_a_viewer_that_answers_and_stays_up(tmp_path, capsys):
    from swarm_ros.artifacts.rerun_recording import spawn_viewer

    port = _free_port()
    exe = _fake_viewer(
        tmp_path,
        "import socket, sys, time\nport = int(sys.argv[1].split('=')[1])\n"
        "s = socket.create_server(('127.0.0.1', port))\ntime.sleep(30)",
    )
    assert spawn_viewer(port, exe=exe) == f"rerun+http://127.0.0.1:{port}/proxy"
    assert capsys.readouterr().err == ""


def test_spawn_without_a_display_says_so_in_one_line_and_goes_on(tmp_path, capsys):
    """The real viewer, with no display, binds its port and exits: no URL, one warning, no viewer's errors."""
    from swarm_ros.artifacts.rerun_recording import spawn_viewer

    exe = _fake_viewer(
        tmp_path,
        "import socket, sys, time\nport = int(sys.argv[1].split('=')[1])\n"
        "s = socket.create_server(('127.0.0.1', port))\n"
        "print('Error: neither WAYLAND_DISPLAY nor DISPLAY is set', file=sys.stderr)\n"
        "sys.exit(1)",
    )
    start = time.monotonic()
    assert spawn_viewer(_free_port(), exe=exe) is None
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "the Rerun viewer exited at once (status 1; no display?)" in err, err
    assert time.monotonic() - start < 5


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_a_rubenstein_simulate_writes_the_run_and_a_recording_of_state_gradient_and_estimates(tmp_path):
    import json
    import subprocess
    import sys
    import warnings

    from recordings import rrd_verify
    from rerun.chunk import RrdReader

    grid = tmp_path / "square.txt"
    grid.write_text("######\n" * 6)
    out = tmp_path / "run"
    cmd = [sys.executable, "-m", "swarm_ros", "simulate", "--algorithm", "rubenstein", "--shape", str(grid)]
    done = subprocess.run([*cmd, "--robots", "40", "--out", str(out), "--quiet"], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["algorithm"] == "rubenstein" and summary["outcome"].startswith("complete")
    assert summary["coverage"] == 1.0 and summary["fill_50_tick"] <= summary["fill_90_tick"]
    assert "vision_radius" not in summary and summary["comm_range"] == 3.5  # its own algorithm's parameters
    assert {p.name for p in tmp_path.iterdir()} == {"square.txt", "run"}  # nothing half-written beside it
    final = np.genfromtxt(out / "final_state.csv", delimiter=",", names=True, dtype=None, encoding="utf-8")
    assert rrd_verify(out / "recording.rrd").returncode == 0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        chunks = RrdReader(str(out / "recording.rrd")).stream().to_chunks()
    last: dict[str, tuple[int, object]] = {}
    for chunk in chunks:
        if chunk.is_static:
            continue
        batch = chunk.to_record_batch()
        for k, tick in enumerate(batch.column("tick").to_numpy().tolist()):
            if tick >= last.get(chunk.entity_path, (-1, None))[0]:
                last[chunk.entity_path] = (tick, {n: batch.column(n)[k] for n in batch.schema.names})
    tick, robots = last["/world/robots"]
    assert tick == summary["convergence_tick"]
    xy = robots["Points2D:positions"].values.flatten().to_numpy(zero_copy_only=False).reshape(-1, 2)
    assert np.allclose(xy, np.stack([final["x"], final["y"]], axis=1), atol=1e-5)
    colours = robots["Points2D:colors"].values.to_numpy(zero_copy_only=False)
    from swarm_ros.artifacts.rubenstein.recording import STATE_COLOURS
    from swarm_ros.core.rubenstein.rule import STATE_NAMES

    packed = [int.from_bytes(bytes([*STATE_COLOURS[STATE_NAMES.index(st)], 255]), "big") for st in final["state"]]
    assert colours.tolist() == packed  # each robot's colour is its state's
    assert "/world/gradient" in last and "/world/estimates" in last
    assert last["/metrics/covered"][1]["Scalars:scalars"].values.to_numpy()[0] == 36
    assert "outcome: complete" in str(last["/events"][1]["TextLog:text"])
