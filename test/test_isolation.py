"""A unit test stays in its process: what conftest.py wraps round every unit test refuses child processes and ROS 2
contexts, and keeps a record of the attempt where the code under test swallows the error."""

from __future__ import annotations

import multiprocessing
import os
import subprocess
import sys

import pytest
from isolation import children_refused

pytestmark = pytest.mark.unit


@pytest.mark.parametrize(
    "start",
    [
        lambda: subprocess.run([sys.executable, "-c", "pass"], check=True),
        lambda: multiprocessing.get_context("spawn").Process(target=print).start(),
        lambda: multiprocessing.get_context("fork").Process(target=print).start(),
        lambda: os.fork(),  # (looked up at the call: the name, not the function bound at collection)
        lambda: os.posix_spawn(sys.executable, [sys.executable, "-c", "pass"], os.environ),
    ],
    ids=["subprocess", "multiprocessing-spawn", "multiprocessing-fork", "fork", "posix_spawn"],
)
def test_a_child_process_is_refused_and_the_attempt_recorded_even_when_swallowed(start):
    with children_refused() as attempts:
        with pytest.raises(AssertionError, match="move it to a module marked process"):
            start()
        try:  # code that catches whatever a start raises does not hide the attempt
            start()
        except Exception:
            pass
    assert len(attempts) == 2


def test_a_ros_context_is_refused():
    rclpy = pytest.importorskip("rclpy")
    with children_refused() as attempts, pytest.raises(AssertionError, match="a ROS 2 context"):
        rclpy.init(args=[])
    assert attempts == ["started a ROS 2 context (a DDS participant)"]


def test_everything_is_back_once_it_ends():
    before = (subprocess.Popen._execute_child, os.fork)
    with children_refused():
        assert (subprocess.Popen._execute_child, os.fork) != before
    assert (subprocess.Popen._execute_child, os.fork) == before
