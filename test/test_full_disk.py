"""A disk that is full, or fills during a run: one line that says so, nothing half-written left behind.

Each test mounts a small tmpfs of its own (root only; skipped otherwise).
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from recordings import rrd_verify

pytestmark = pytest.mark.process

PY = sys.executable


@pytest.fixture
def small_disk(tmp_path):
    """A tmpfs of ``size`` (a function of the test's choosing), unmounted at the end."""
    mounted: list[Path] = []

    def make(size: str) -> Path:
        where = tmp_path / f"disk{len(mounted)}"
        where.mkdir()
        if (
            subprocess.run(
                ["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(where)], capture_output=True
            ).returncode
            != 0
        ):
            pytest.skip("cannot mount a tmpfs here (needs root)")
        mounted.append(where)
        return where

    yield make
    for where in mounted:
        subprocess.run(["umount", "-l", str(where)], capture_output=True)


def _swarm(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([PY, "-m", "swarm_ros", *args], cwd=cwd, capture_output=True, text=True, timeout=300)


@pytest.mark.parametrize("command", ["simulate", "run"])
def test_a_disk_nearly_full_is_refused_before_anything_starts(small_disk, tmp_path, command):
    disk = small_disk("4m")
    (disk / "fill").write_bytes(b"\0" * (3 * 1024 * 1024))
    done = _swarm(command, "--out", str(disk / "r"), "--quiet", cwd=tmp_path)
    assert done.returncode == 2, done.stderr
    assert done.stderr.count("\n") == 1 and "MiB free on its disk; a run needs at least 8 MiB" in done.stderr, (
        done.stderr
    )
    assert sorted(p.name for p in disk.iterdir()) == ["fill"]


def test_simulate_whose_recording_fills_the_disk_says_so_and_leaves_nothing(small_disk, tmp_path):
    disk = small_disk("9m")  # the torus's recording takes about 4.6 kB a tick: 2500 ticks do not fit
    done = _swarm(
        "simulate", "--shape", "torus", "--max-ticks", "2500", "--out", str(disk / "r"), "--quiet", cwd=tmp_path
    )
    assert done.returncode == 1, done.stderr  # a run that failed, not bad input
    assert done.stderr.count("\n") == 1, done.stderr
    assert "the recording could not be written whole (no space left on device); it is removed" in done.stderr
    assert list(disk.iterdir()) == []


def test_run_whose_disk_fills_says_so_and_leaves_no_hidden_or_broken_file(small_disk, tmp_path):
    """The disk fills mid-run: the world (whose checkpoint reserves its blocks before it writes through its
    mapping: no SIGBUS) or the monitor fails in one line naming the full disk, no hidden bag folder stays, and a
    recording or a bag left is whole."""
    disk = small_disk("9m")  # the star's bag, recording and the world's checkpoint take more
    done = _swarm("run", "--out", str(disk / "r"), "--quiet", cwd=tmp_path)
    assert done.returncode == 1, done.stderr  # a run that failed, not bad input
    assert "no space left on device" in done.stderr.lower() and "SIGBUS" not in done.stderr, done.stderr
    assert "RecordingError" not in done.stderr, done.stderr  # said in words, not as an exception's name
    assert "Traceback" not in done.stderr
    names = sorted(p.name for p in disk.iterdir())
    # no .r.bag-*; a bag left beside the run is one that closed whole (the world failed first, and the monitor,
    # stopped, could still close it), which a reader opens
    assert set(names) <= {"r.logs", "r.partial.rrd", "r.partial-bag"}, (names, done.stderr)
    if "r.partial.rrd" in names:
        assert rrd_verify(disk / "r.partial.rrd").returncode == 0
    if "r.partial-bag" in names:
        from rosbags.highlevel import AnyReader

        with AnyReader([disk / "r.partial-bag"]) as reader:
            assert any(c.topic == "/swarm/darr_niazi/robots" for c in reader.connections)
