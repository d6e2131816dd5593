"""The launcher's progress display follows the world's /swarm/status alone (swarm_ros.tools.progress); the command
line's own participants (it, ``topics``, ``replay``) are made with Ctrl-C and SIGTERM held (swarm_ros.ros.runtime)."""

from __future__ import annotations

import io
import os
import signal

import pytest

pytest.importorskip("rclpy")

from tqdm import tqdm

from swarm_ros.ros import graph as msgs
from swarm_ros.ros.runtime import signals_held
from swarm_ros.tools.progress import Progress

pytestmark = pytest.mark.unit


def _progress() -> Progress:
    """A Progress without its ROS side: what _on_status updates."""
    p = Progress.__new__(Progress)
    p.bar = tqdm(total=1036, file=io.StringIO())  # enabled (a disabled bar counts nothing), written nowhere
    p.tick, p.started, p.ended_at = -1, False, None
    return p


def test_the_bar_follows_the_status_from_tick_0_to_the_outcome():
    p = _progress()
    p._on_status(msgs.status_message(0, "starting", "waiting for robot batches"))
    assert not p.started and p.tick == -1 and p.bar.n == 0
    said = {"progress": 300, "progress_total": 1036, "progress_words": "moving", "moving": 700}
    p._on_status(msgs.status_message(40, "running", "running", extra=said))
    assert p.started and p.tick == 40 and p.bar.n == 300 and p.ended_at is None
    assert set(p.bar.postfix.split(", ")) == {"tick=40", "moving=700"}
    p._on_status(msgs.status_message(30, "running", "running", extra={"progress": 250}))  # an older one, late
    assert p.tick == 40
    p._on_status(msgs.status_message(405, "complete", "complete at tick 405", extra={"progress": 1036}))
    assert p.tick == 405 and p.bar.n == 1036 and p.ended_at is not None


def test_the_bar_counts_what_the_worlds_algorithm_counts():
    """A rubenstein world's status: pixels covered of the shape's, and the robots joined (as simulate's bar)."""
    p = _progress()
    said = {"progress": 12, "progress_total": 600, "progress_words": "joined", "joined": 31}
    p._on_status(msgs.status_message(2000, "running", "running", extra=said))
    assert p.bar.total == 600 and p.bar.n == 12 and set(p.bar.postfix.split(", ")) == {"tick=2000", "joined=31"}


def test_values_that_are_not_counts_do_not_break_the_bar():
    p = _progress()
    said = {"progress": "x", "progress_total": -2, "progress_words": "moving,gone", "moving": -2}
    p._on_status(msgs.status_message(3, "running", "running", extra=said))
    assert p.started and p.tick == 3 and p.bar.n == 0 and p.bar.total == 1036


def test_a_sigterm_while_a_participant_is_made_is_acted_on_once_it_is_whole():
    """A tool's SIGTERM handler raises KeyboardInterrupt; one that landed inside rclpy's making of a node left a
    half-made logger whose ``__del__`` printed a traceback (CI). Held, it is raised as the block ends, once."""

    def interrupt(signum: int, frame: object) -> None:
        raise KeyboardInterrupt

    before = signal.signal(signal.SIGTERM, interrupt)
    steps: list[str] = []
    try:
        with pytest.raises(KeyboardInterrupt):
            with signals_held():
                os.kill(os.getpid(), signal.SIGTERM)
                steps.extend(str(i) for i in range(1000))  # many bytecodes: the handler would have run by now
                steps.append("whole")
        assert steps[-1] == "whole"
        assert signal.getsignal(signal.SIGTERM) is interrupt  # the tool's handler is back
    finally:
        signal.signal(signal.SIGTERM, before)
