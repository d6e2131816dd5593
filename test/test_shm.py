"""Removing the Fast DDS shared-memory files a run's dead processes left (swarm_ros.ros.shm), on files of its own."""

from __future__ import annotations

import mmap
import os
import uuid
from pathlib import Path

import pytest

from swarm_ros.ros.shm import SHM_DIR, clean_shm

pytestmark = pytest.mark.unit


@pytest.fixture
def dead_segment():
    """A participant's segment whose owner is gone (its lock file can be locked), mapped by this process, as the
    launcher's shut-down node leaves a killed peer's mapped in Fast DDS's process-wide cache."""
    if not SHM_DIR.is_dir():
        pytest.skip("no /dev/shm here")
    name = f"fastrtps_test{uuid.uuid4().hex[:12]}"
    segment, lock = SHM_DIR / name, SHM_DIR / f"{name}_el"
    segment.write_bytes(bytes(4096))
    lock.touch()
    with open(segment, "r+b") as f:
        view = mmap.mmap(f.fileno(), 4096)
    try:
        yield segment, lock
    finally:
        view.close()
        for path in (segment, lock):
            path.unlink(missing_ok=True)


def test_a_dead_segment_mapped_by_a_live_process_stays(dead_segment):
    segment, lock = dead_segment
    assert clean_shm({str(lock)}) == [] and segment.exists() and lock.exists()


def test_a_dead_segment_mapped_only_by_the_processes_said_to_be_no_users_goes(dead_segment):
    segment, lock = dead_segment
    removed = clean_shm({str(lock)}, frozenset({os.getpid()}))
    assert sorted(removed) == sorted([str(segment), str(lock)]) and not segment.exists() and not lock.exists()
    assert not Path(SHM_DIR / f"sem.{segment.name}_mutex").exists()  # none was made: nothing else touched


def test_a_later_run_tidies_what_a_killed_launcher_recorded_and_only_that(tmp_path, monkeypatch):
    """The per-user record of each launcher's Fast DDS files (register): a record whose launcher is dead has its
    files removed once no process holds them, and goes; a live launcher's record, and files no record lists,
    stay."""
    from swarm_ros.ros import shm

    if not SHM_DIR.is_dir():
        pytest.skip("no /dev/shm here")
    monkeypatch.setattr(shm, "_registry", lambda: tmp_path / "shm")
    made = []
    for _ in range(3):
        name = f"fastrtps_test{uuid.uuid4().hex[:12]}"
        (SHM_DIR / name).write_bytes(bytes(16))
        (SHM_DIR / f"{name}_el").touch()
        made.append((SHM_DIR / name, SHM_DIR / f"{name}_el"))
    try:
        dead_pid = 1 << 23  # above Linux's largest pid (2^22): no such process
        assert not Path(f"/proc/{dead_pid}").exists()
        shm.register(dead_pid, {str(made[0][1])})
        shm.register(os.getpid(), {str(made[1][1])})  # a launcher still running
        assert shm.tidy_dead_runs() == [str(made[0][0]), str(made[0][1])]
        assert not made[0][0].exists() and not made[0][1].exists()
        assert all(p.exists() for p in (*made[1], *made[2])), "a live run's files and files of no record stay"
        assert sorted(p.name for p in (tmp_path / "shm").iterdir()) == [f"{os.getpid()}.list"]
        shm.unregister(os.getpid())
        assert shm.tidy_dead_runs() == [] and not list((tmp_path / "shm").iterdir())
    finally:
        for pair in made:
            for path in pair:
                path.unlink(missing_ok=True)


def test_a_port_a_process_died_making_is_found_and_nothing_else(tmp_path, monkeypatch):
    """An empty fastrtps_port file without its lock file, held by no process, is what a process killed while Fast
    DDS made the port leaves (a CI run here: every later participant on the host waited on it in Node()); a port
    with its lock file, one with contents, and an empty one a live process holds open (its maker at work) are not;
    `swarm-ros run` and the launch file refuse to start on one, naming it."""
    from swarm_ros.app.processes import LaunchError, check_shared_memory
    from swarm_ros.ros import shm

    wedged, done, full, held = (tmp_path / f"fastrtps_port{n}" for n in (7002, 7003, 7004, 7005))
    wedged.touch()
    done.touch()
    (tmp_path / "fastrtps_port7003_el").touch()
    full.write_bytes(bytes(64))
    held.touch()
    with open(held, "rb"):
        assert shm.half_made_ports(tmp_path) == [str(wedged)]
        monkeypatch.setattr(shm, "SHM_DIR", tmp_path)
        with pytest.raises(LaunchError, match=r"fastrtps_port7002: a Fast DDS shared-memory port a killed"):
            check_shared_memory()
        monkeypatch.undo()
    wedged.unlink()
    assert shm.half_made_ports(tmp_path) == [str(held)]  # no longer held: its maker died
    assert shm.half_made_ports(tmp_path / "none") == []
