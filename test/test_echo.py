"""``swarm-ros topics --echo`` picks what it prints by each message's publisher time, not by how long a latched topic's
history takes to arrive: live messages when there are any, else the newest of the history. On a fake inspector whose
every spin delivers the next batch of (message, sent before the subscription?) pairs."""

from __future__ import annotations

import time

import pytest
from std_msgs.msg import String

from swarm_ros.tools import topics

pytestmark = pytest.mark.unit


class _Node:
    def __init__(self, inspector: _Inspector) -> None:
        self.inspector = inspector

    def count_publishers(self, topic: str) -> int:
        return 1

    def create_subscription(self, kind, topic, callback, qos):
        self.inspector.callback = callback


class _Inspector:
    """Each spin delivers the next batch; a spin with none left delivers nothing (and takes no time)."""

    def __init__(self, batches: list[list[tuple[str, bool]]]) -> None:
        self.batches, self.callback, self.node = list(batches), None, _Node(self)

    def topics(self) -> dict[str, str]:
        return {"/t": "std_msgs/msg/String"}

    def publisher_qos(self, topic: str) -> None:
        return None

    def spin_for(self, seconds: float, until=lambda: False) -> None:
        if self.callback is None or until():
            return
        for text, old in self.batches.pop(0) if self.batches else []:
            sent = time.time_ns() + (-(10**9) if old else 10**9)  # a second before or after now
            self.callback(String(data=text), {"source_timestamp": sent})


def _echo(batches, count: int = 1, seconds: float = 5.0) -> tuple[int, list[str]]:
    import contextlib
    import io

    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        code = topics._echo(_Inspector(batches), "/t", count, seconds, time.monotonic() + seconds, False)
    return code, [line.split("'")[1] for line in printed.getvalue().splitlines() if line.startswith("data:")]


def test_a_history_that_comes_in_slowly_is_skipped_for_the_live_message_after_it():
    # the history in three slow batches (a loaded machine), then a live message: echo prints the live one
    history = [[("starting", True)], [("old 1", True), ("old 2", True)], [("old 3", True)]]
    assert _echo([*history, [("running", False)]]) == (0, ["running"])


def test_a_topic_with_nothing_new_after_its_history_gives_the_newest_of_it():
    assert _echo([[("shape 1", True), ("shape 2", True)], [], []], count=1) == (0, ["shape 2"])
    assert _echo([[("a", True), ("b", True), ("c", True)]], count=2) == (0, ["b", "c"])


def test_count_live_messages_are_printed_in_order_and_none_in_the_wait_is_an_error():
    assert _echo([[("x", True)], [("one", False)], [("two", False), ("three", False)]], count=2) == (0, ["one", "two"])
    assert _echo([], seconds=0.2) == (1, [])
