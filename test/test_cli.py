"""The swarm-ros command line: simulate's run directory, reproducibility, bad input."""

import csv
import json
import subprocess
import sys
from pathlib import Path

import pytest
from waiting import wait_for

from swarm_ros.app import cli
from swarm_ros.artifacts import run_dir as output
from swarm_ros.core.darr_niazi.metrics import METRIC_COLUMNS

pytestmark = pytest.mark.process

SUMMARY_KEYS = {
    "shape",
    "shape_patches",
    "robots",
    "vision_radius",
    "rules",
    "join",
    "crowding",
    "steps",
    "seed",
    "engine",
    "outcome",
    "convergence_tick",
    "localized",
    "unlocalized",
    "empty_patches",
    "wall_seconds",
}


def simulate(out: Path, *extra: str) -> int:
    return cli.main(
        ["simulate", "--shape", "rectangle", "--robots", "460", "--seed", "3", "--quiet", "--out", str(out), *extra]
    )


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("cli") / "run"
    assert simulate(out) == 0
    return out


def test_simulate_writes_the_run_directory(run_dir):
    assert sorted(p.name for p in run_dir.iterdir()) == [
        "convergence.png",
        "final.png",
        "final_state.csv",
        "metrics.csv",
        "recording.rrd",
        "summary.json",
    ]
    summary = json.loads((run_dir / "summary.json").read_text())
    assert SUMMARY_KEYS <= set(summary)
    assert summary["engine"] == "inprocess" and summary["outcome"] == "complete_with_extras"
    assert summary["robots"] == 460 and summary["shape_patches"] == 442 and summary["separated"] == 18
    rows = list(csv.reader((run_dir / "metrics.csv").open()))
    assert tuple(rows[0]) == METRIC_COLUMNS
    assert len(rows) == summary["convergence_tick"] + 2 and rows[-1][0] == str(summary["convergence_tick"])
    final = list(csv.DictReader((run_dir / "final_state.csv").open()))
    assert len(final) == 460 and {r["state"] for r in final} == {"seed", "localized", "separated"}
    assert (run_dir / "final.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_same_command_same_seed_gives_identical_files(run_dir, tmp_path):
    again = tmp_path / "again"
    assert simulate(again) == 0
    for name in ("metrics.csv", "final_state.csv"):
        assert (again / name).read_bytes() == (run_dir / name).read_bytes()
    a, b = (json.loads((d / "summary.json").read_text()) for d in (run_dir, again))
    a.pop("wall_seconds"), b.pop("wall_seconds")
    assert a == b


def test_the_rule_set_and_its_switches_come_from_flags_over_the_parameter_file(run_dir, tmp_path):
    assert json.loads((run_dir / "summary.json").read_text())["rules"] == "paper"  # the default
    params = tmp_path / "params.yaml"
    params.write_text("/**:\n  ros__parameters:\n    rules: local\n    crowding: disc\n    steps: literal\n")
    assert simulate(tmp_path / "file", "--params-file", str(params)) == 0
    summary = json.loads((tmp_path / "file" / "summary.json").read_text())
    assert [summary[k] for k in ("rules", "join", "crowding", "steps")] == ["local", "local", "disc", "literal"]
    assert simulate(tmp_path / "flags", "--params-file", str(params), "--rules", "paper", "--crowding", "ahead") == 0
    summary = json.loads((tmp_path / "flags" / "summary.json").read_text())
    assert [summary[k] for k in ("rules", "join", "crowding", "steps")] == ["paper", "walk", "ahead", "literal"]


def test_summary_is_printed(tmp_path, capsys):
    assert cli.main(["simulate", "--shape", "rectangle", "--max-ticks", "10", "--out", str(tmp_path / "r")]) == 0
    text = capsys.readouterr().out
    assert "outcome           timeout" in text and "convergence tick  10" in text


def test_params_file_sets_values_and_flags_override_it(tmp_path):
    pf = tmp_path / "p.yaml"
    pf.write_text("/**:\n  ros__parameters:\n    shape: wrench\n    robots: 300\n    max_ticks: 7\n")
    assert (
        cli.main(["simulate", "--params-file", str(pf), "--robots", "200", "--quiet", "--out", str(tmp_path / "r")])
        == 0
    )
    s = json.loads((tmp_path / "r" / "summary.json").read_text())
    assert (s["shape"], s["robots"], s["max_ticks"]) == ("wrench", 200, 7)


def test_check_flag_runs_the_invariant_checks(tmp_path):
    assert simulate(tmp_path / "r", "--check", "--overwrite") == 0


def _tree(d: Path) -> dict[str, bytes]:
    return {str(p.relative_to(d)): p.read_bytes() if p.is_file() else b"<dir>" for p in sorted(d.rglob("*"))}


def test_existing_output_is_refused_unless_overwrite_and_overwrite_replaces_only_a_run_directory(tmp_path, capsys):
    out = tmp_path / "r"
    assert simulate(out) == 0
    before = _tree(out)
    assert simulate(out) == 2
    assert "exists and is not empty" in capsys.readouterr().err
    assert _tree(out) == before
    assert simulate(out, "--overwrite", "--seed", "4") == 0  # a run directory: replaced
    assert json.loads((out / "summary.json").read_text())["seed"] == 4
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r"]  # no temporary or trash directory left


@pytest.mark.parametrize(
    "content,why",
    [
        ({"important.txt": "x", "sub/notes.txt": "y"}, "holds no summary.json written by swarm-ros"),
        ({"summary.json": "{}"}, "its summary.json was not written by swarm-ros"),
        ({"summary.json": "[1, 2]"}, "its summary.json was not written by swarm-ros"),
        ({"summary.json": "not json"}, "holds no summary.json written by swarm-ros"),
    ],
)
def test_overwrite_refuses_a_directory_this_tool_did_not_write_and_touches_nothing(tmp_path, capsys, content, why):
    out = tmp_path / "mine"
    for name, text in content.items():
        (out / name).parent.mkdir(parents=True, exist_ok=True)
        (out / name).write_text(text)
    before = _tree(tmp_path)
    assert simulate(out, "--overwrite") == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "not a swarm-ros run directory" in err and why in err, err
    assert "nothing was touched" in err
    assert _tree(tmp_path) == before


def test_overwrite_refuses_a_run_directory_a_user_added_a_file_to(tmp_path, capsys):
    out = tmp_path / "r"
    assert simulate(out) == 0
    (out / "analysis.ipynb").write_text("{}")
    before = _tree(tmp_path)
    assert simulate(out, "--overwrite") == 2
    assert "it holds 'analysis.ipynb', which no run writes" in capsys.readouterr().err
    assert _tree(tmp_path) == before


def test_overwrite_of_the_current_directory_is_refused(tmp_path, monkeypatch, capsys):
    (tmp_path / "important.txt").write_text("keep me")
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "notes.txt").write_text("and me")
    monkeypatch.chdir(tmp_path)
    before = _tree(tmp_path)
    assert cli.main(["simulate", "--shape", "rectangle", "--out", ".", "--overwrite", "--quiet"]) == 2
    assert "not a swarm-ros run directory" in capsys.readouterr().err
    assert _tree(tmp_path) == before


def test_an_unwritable_output_place_is_refused_before_anything_runs(tmp_path, monkeypatch, capsys):
    """Permission bits do not tell (root may write anywhere but /sys, /proc): the check really tries."""
    assert not output.writable_dir(Path("/sys"))
    assert output.writable_dir(tmp_path) and list(tmp_path.iterdir()) == []  # the probe file is gone
    assert simulate(Path("/sys/x"), "--max-ticks", "5") == 2
    assert capsys.readouterr().err == "swarm-ros: error: /sys: directory is not writable, so /sys/x cannot be created\n"


def test_shapes_lists_the_six_builtins(capsys):
    assert cli.main(["shapes"]) == 0
    text = capsys.readouterr().out
    for name, patches in [("star", 1036), ("tyre", 1284), ("spinner", 1041)]:
        assert any(line.split()[:2] == [name, str(patches)] for line in text.splitlines())


def test_shapes_in_a_small_world_lists_every_shape_and_marks_those_that_do_not_fit(capsys):
    assert cli.main(["shapes", "--world-radius", "20"]) == 0
    lines = {ln.split()[0]: ln for ln in capsys.readouterr().out.splitlines()[1:-1]}
    assert sorted(lines) == ["k-letter", "rectangle", "spinner", "star", "tyre", "wrench"]
    assert lines["rectangle"].split()[1] == "442" and "does not fit" not in lines["rectangle"]
    for name in ("k-letter", "spinner", "star", "tyre", "wrench"):
        assert "does not fit: shape reaches beyond the walls of the 41 x 41 world" in lines[name]


def test_a_parameter_files_monitor_section_sets_the_recording_and_flags_override_it(tmp_path):
    pf = tmp_path / "p.yaml"
    pf.write_text("/monitor:\n  ros__parameters:\n    record: false\n    record_every: 3\n")
    assert simulate(tmp_path / "off", "--params-file", str(pf)) == 0
    assert not (tmp_path / "off" / "recording.rrd").exists()
    pf.write_text(f"/monitor:\n  ros__parameters:\n    out_dir: {tmp_path / 'there'}\n")
    assert cli.main(["simulate", "--shape", "rectangle", "--max-ticks", "3", "--quiet", "--params-file", str(pf)]) == 0
    assert (tmp_path / "there" / "recording.rrd").exists()


def test_a_failure_while_writing_leaves_nothing_behind(tmp_path, monkeypatch, capsys):
    def broken(sim, path):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr("swarm_ros.artifacts.darr_niazi.plots.save_final_png", broken)
    assert simulate(tmp_path / "run") == 2
    err = capsys.readouterr().err
    assert "No space left on device" in err and err.count("\n") == 1
    # no run directory, no temporary files; the finished recording is kept and named in the message
    assert [p.name for p in tmp_path.iterdir()] == ["run.partial.rrd"]
    assert f"the recording is kept in {tmp_path / 'run.partial.rrd'}" in err


def test_installed_console_script_reports_errors_without_a_traceback(tmp_path):
    exe = Path(sys.executable).parent / "swarm-ros"
    result = subprocess.run(
        [str(exe), "simulate", "--shape", str(tmp_path / "missing.png")],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=tmp_path,
    )
    assert result.returncode == 2
    assert result.stderr.startswith("swarm-ros: error: ") and "Traceback" not in result.stderr
    assert not (tmp_path / output.RUNS_DIR).exists()


def test_output_piped_into_a_closed_pipe_stops_quietly():
    exe = Path(sys.executable).parent / "swarm-ros"
    result = subprocess.run(f"'{exe}' shapes | head -1", shell=True, capture_output=True, text=True, timeout=120)
    assert result.stdout.startswith("shape") and "Traceback" not in result.stderr


def test_a_second_command_for_a_run_directory_in_use_is_refused_at_once(tmp_path, capsys):
    """Two commands with one --out: the second gets one line naming the first, before it runs anything."""
    import signal
    import time

    out = tmp_path / "run"
    first = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "swarm_ros",
            "simulate",
            "--shape",
            "star",
            "--vision",
            "3",
            "--rules",
            "local",
            "--crowding",
            "disc",
            "--no-recording",
            "--quiet",
            "--max-ticks",
            "60000",
            "--out",
            str(out),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        lock_dir = Path(__import__("tempfile").gettempdir()) / "swarm_ros-runs"
        wait_for(
            lambda: any(f"pid {first.pid}:" in p.read_text() for p in lock_dir.glob("*.lock") if p.is_file()),
            60,
            "the first command's claim on the run directory",
        )
        for command in ("simulate", "run"):
            started = time.monotonic()
            assert cli.main([command, "--out", str(out), "--quiet"]) == 2
            err = capsys.readouterr().err
            assert err.count("\n") == 1 and time.monotonic() - started < 5, err
            assert (
                f"{out}: another swarm-ros command is writing this run directory now (pid {first.pid}: "
                f"swarm-ros simulate --shape star" in err
            )
        assert first.poll() is None  # the first goes on, untouched
    finally:
        first.send_signal(signal.SIGTERM)
        _, first_err = first.communicate(timeout=30)
    assert json.loads((out / "summary.json").read_text())["outcome"] == "interrupted", first_err
    assert cli.main(["simulate", "--out", str(tmp_path / "next"), "--quiet", "--max-ticks", "3"]) == 0  # released


def test_a_leftover_of_an_earlier_run_is_refused_and_kept(tmp_path, capsys):
    """A killed run's recording or bag beside --out is never replaced by a new run."""
    for left in ("run.partial.rrd", "run.partial-bag"):
        path = tmp_path / left
        path.mkdir() if left.endswith("bag") else path.write_bytes(b"earlier")
        assert simulate(tmp_path / "run") == 2
        err = capsys.readouterr().err
        assert f"{path}: left by an earlier run of {tmp_path / 'run'} that stopped early" in err
        assert path.exists() and not (tmp_path / "run").exists()
        path.rmdir() if path.is_dir() else path.unlink()


def test_run_directories_and_their_files_get_the_umasks_mode(run_dir):
    import os
    import stat

    mask = os.umask(0)
    os.umask(mask)
    assert stat.S_IMODE(run_dir.stat().st_mode) == 0o777 & ~mask
    assert {stat.S_IMODE(p.stat().st_mode) for p in run_dir.iterdir() if p.is_file()} == {0o666 & ~mask}


def test_counts_of_processes_read_as_english():
    from swarm_ros.app.launcher import plural

    assert plural(1, "robot-batch process") == "1 robot-batch process"
    assert plural(2, "robot-batch process") == "2 robot-batch processes"
    assert plural(3, "robot") == "3 robots"


def test_run_refuses_a_pipe_as_its_shape_in_one_line(tmp_path, monkeypatch, capsys):
    """simulate reads a pipe (a shell's <(...)) once; each node of the graph would read it again: refused."""
    import os

    read, write = os.pipe()
    os.write(write, b".....\n.###.\n.###.\n.###.\n.....\n")
    os.close(write)
    monkeypatch.chdir(tmp_path)
    try:
        assert cli.main(["run", "--shape", f"/dev/fd/{read}", "--out", "r"]) == 2
    finally:
        os.close(read)
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"/dev/fd/{read}: not a regular file; each node of the graph reads" in err, err
    assert list(tmp_path.iterdir()) == []


def test_summary_says_how_often_the_recording_holds_every_robot(run_dir, tmp_path):
    assert json.loads((run_dir / "summary.json").read_text())["recording_robots_every"] == 1  # 460 robots
    big = ["--shape", "star", "--world-radius", "80", "--robots", "25000", "--max-ticks", "2", "--quiet"]
    assert cli.main(["simulate", *big, "--out", str(tmp_path / "auto")]) == 0
    assert json.loads((tmp_path / "auto" / "summary.json").read_text())["recording_robots_every"] == 3
    assert cli.main(["simulate", *big, "--record-every", "2", "--out", str(tmp_path / "two")]) == 0
    assert json.loads((tmp_path / "two" / "summary.json").read_text())["recording_robots_every"] == 2
    assert simulate(tmp_path / "none", "--no-recording") == 0
    assert json.loads((tmp_path / "none" / "summary.json").read_text())["recording_robots_every"] is None


def test_an_unwritable_home_gets_no_matplotlib_warning_and_leaves_no_temporary_directory(tmp_path):
    """matplotlib warned twice and made a /tmp/matplotlib-* per process when HOME could not be written; the
    pictures now go through one configuration directory of the user's, reused by every later run."""
    import os
    import tempfile

    before = set(Path(tempfile.gettempdir()).glob("matplotlib-*"))
    env = {k: v for k, v in os.environ.items() if k not in ("MPLCONFIGDIR", "XDG_CONFIG_HOME")}
    env["HOME"] = "/proc/no-such-home"  # cannot be made, by root either
    done = subprocess.run(
        [sys.executable, "-m", "swarm_ros", "simulate", "--max-ticks", "3", "--quiet", "--out", str(tmp_path / "r")],
        capture_output=True,
        text=True,
        timeout=120,
        env=env,
    )
    assert done.returncode == 0 and done.stderr == "", done.stderr
    assert (tmp_path / "r" / "final.png").is_file()
    assert set(Path(tempfile.gettempdir()).glob("matplotlib-*")) <= before
