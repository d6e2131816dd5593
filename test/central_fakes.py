"""A central world's logic (swarm_ros.protocol.central_world) driven with a fake port and log, no ROS."""

from __future__ import annotations

import numpy as np


class Log:
    """A logger that keeps its lines."""

    def __init__(self) -> None:
        self.lines: list[str] = []

    def info(self, text: str) -> None:
        self.lines.append(text)

    warn = warning = info


class WorldPort:
    """What a CentralWorld sends, recorded; the monitor reads from the start, readers acknowledge at once."""

    def __init__(self) -> None:
        self.watched: list[str] = []
        self.areas: list[tuple[str, int, np.ndarray, bool]] = []
        self.records: list[tuple[int, np.ndarray, np.ndarray]] = []
        self.statuses: list[tuple[int, str, str, dict]] = []
        self.clocks: list[int] = []  # each tick as it went out
        self.sent_at: list[float] = []  # the clock at each area sent
        self.clock = lambda: 0.0
        self.status_acked = True  # whether every reader of the status has the last one (told())
        self.reads = True  # whether the monitor reads the run's topics (monitor_reads())

    def watch_batch(self, name):
        self.watched.append(name)

    def send_area(self, name, tick, rows, whole):
        self.areas.append((name, tick, rows, whole))
        self.sent_at.append(self.clock())

    def publish_record(self, tick, metrics, robots):
        self.records.append((tick, metrics, robots))

    def publish_clock(self, tick):
        self.clocks.append(tick)

    def publish_status(self, tick, outcome, message, values):
        self.statuses.append((tick, outcome, message, values))

    def monitor_reads(self):
        return self.reads

    def monitor_seen(self):
        return "/swarm/status: robot_batch_0"

    def delivered(self):
        return True

    def told(self):
        return self.status_acked

    def startup_seconds(self):
        return 1.5
