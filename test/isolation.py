"""What keeps a ``unit`` test in its process (pytest.ini): :func:`children_refused`, which conftest.py wraps round
every unit test."""

from __future__ import annotations

import _posixsubprocess
import contextlib
import os
import subprocess
from collections.abc import Iterator

import pytest


@contextlib.contextmanager
def children_refused() -> Iterator[list[str]]:
    """Within it, starting a child process (``subprocess``, ``multiprocessing``, ``os.fork``, ``posix_spawn``) or a
    ROS 2 context (a DDS participant) raises AssertionError; yields the list of what was attempted, which holds each
    attempt even where the code under test catches the error."""
    attempts: list[str] = []

    def refuse(what: str):
        def refused(*_args, **_kwargs):
            attempts.append(what)
            raise AssertionError(f"a unit test {what}: move it to a module marked process (pytest.ini)")

        return refused

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(subprocess.Popen, "_execute_child", refuse("started a child process"))
        patch.setattr(_posixsubprocess, "fork_exec", refuse("started a child process"))
        for name in ("fork", "forkpty", "posix_spawn", "posix_spawnp"):
            if hasattr(os, name):
                patch.setattr(os, name, refuse(f"called os.{name}"))
        with contextlib.suppress(ImportError):
            import rclpy.context

            patch.setattr(rclpy.context.Context, "init", refuse("started a ROS 2 context (a DDS participant)"))
        yield attempts
