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
