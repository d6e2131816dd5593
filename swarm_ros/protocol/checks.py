"""Every message a node takes is checked here first, one function per message type.

A message that fails is dropped, never raised: the node counts it by kind of fault and
logs one line per kind at most every ``LOG_PERIOD`` seconds (:class:`Rejections`); the
world reports its counts on /swarm/status (``rejected_messages``), the monitor in the
run's summary. docs/security.md says what these checks keep out and what they cannot.
"""

from __future__ import annotations

import math
import re
import time
from collections import Counter

import numpy as np

from swarm_ros.core.errors import ContractError, Rejected
from swarm_ros.core.strips import has_repeats
from swarm_ros.protocol.rows import TICK_SECONDS, check_fields, parse_batch_label

LOG_PERIOD = 5.0  # seconds between two log lines about one kind of fault
_NODE_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]{0,127}")  # a ROS node name, as batch names are


class Rejections:
    """Counts of the messages a node dropped, by topic and kind of fault, with rate-limited log lines."""

    def __init__(self, logger) -> None:
        self.logger = logger
        self.counts: Counter[str] = Counter()
        self._logged: dict[str, float] = {}

    def drop(self, topic: str, fault: Rejected) -> None:
        key = f"{topic}: {fault.kind}"
        self.counts[key] += 1
        now = time.monotonic()
        if now - self._logged.get(key, -math.inf) >= LOG_PERIOD:
            self._logged[key] = now
            self.logger.warn(f"dropped a message on {topic} ({fault}); {self.counts[key]} so far of this kind")

    @property
    def total(self) -> int:
        return sum(self.counts.values())

    def text(self) -> str:
        """``topic: kind=n`` items joined by ``; `` (the ``rejected_messages`` value of /swarm/status)."""
        return "; ".join(f"{key}={n}" for key, n in sorted(self.counts.items()))


def cloud(msg, dtype: np.dtype, max_rows: int, min_rows: int = 1) -> np.ndarray:
    """The rows of a PointCloud2 of ``dtype`` rows (a read-only view of its bytes).

    Raises:
        Rejected: another point layout, a size that does not match it, big-endian data,
            fewer rows than ``min_rows``, or more than ``max_rows``.
    """
    try:
        check_fields([(f.name, f.offset, f.datatype, f.count) for f in msg.fields], msg.point_step, dtype)
    except ContractError as exc:
        raise Rejected("point layout", str(exc)) from None
    rows = int(msg.width) * int(msg.height)
    if msg.is_bigendian:
        raise Rejected("byte order", "big-endian data")
    if len(msg.data) != rows * dtype.itemsize or int(msg.row_step) != int(msg.width) * dtype.itemsize:
        raise Rejected(
            "size",
            f"{len(msg.data)} bytes for {msg.width} x {msg.height} points of "
            f"{dtype.itemsize} bytes (row step {msg.row_step})",
        )
    if rows < min_rows:
        raise Rejected("empty")
    if rows > max_rows:
        raise Rejected("too many rows", f"{rows} rows, at most {max_rows}")
    return np.frombuffer(msg.data, dtype=dtype)


def ids_in_range(ids: np.ndarray, low: int, robots: int) -> None:
    """Raises Rejected unless every id is in ``low``..``robots - 1`` and none repeats."""
    if not ids.size:
        return
    if ids.min() < low or ids.max() >= robots:
        raise Rejected(
            "robot id out of range", f"ids {int(ids.min())}..{int(ids.max())}, the run has {low}..{robots - 1}"
        )
    if has_repeats(ids):
        raise Rejected("repeated robot id")


def announcement(msg, width: int) -> tuple[str, int, tuple[int, int]]:
    """(batch name, incarnation, (first, last) column of its strip) of a /swarm/batches message, checked
    against the world's ``width`` columns."""
    label = msg.layout.dim[0].label if msg.layout.dim else ""
    name, incarnation = parse_batch_label(label)
    if not _NODE_NAME.fullmatch(name):
        raise Rejected("batch name", f"{label[:80]!r} is not a node name")
    if len(msg.data) != 2:
        raise Rejected("strip", f"{len(msg.data)} values, expected its first and last column")
    first, last = int(msg.data[0]), int(msg.data[1])
    if not 0 <= first <= last < width:
        raise Rejected("strip", f"columns {first}..{last}, the world has 0..{width - 1}")
    return name, incarnation, (first, last)


def tick_stamp(header) -> int:
    """A message's tick, from its stamp (whole seconds, as the world stamps them)."""
    if header.stamp.nanosec != 0 or header.stamp.sec < 0:
        raise Rejected("stamp", f"{header.stamp.sec} s {header.stamp.nanosec} ns is not a tick")
    return int(header.stamp.sec) // TICK_SECONDS


def held_report(values: np.ndarray, newest: int) -> tuple[int, bool]:
    """The monitor's report on /swarm/held, ``[tick, ended]``, checked: the last tick whose record its bag holds
    (-1: none yet), at most ``newest``, and whether it holds the run's outcome too.

    Raises:
        Rejected: ("held") not two values, a tick out of range, or ``ended`` neither 0 nor 1.
    """
    if values.size != 2:
        raise Rejected("held", f"{values.size} values, expected the tick and whether the run ended")
    tick, ended = int(values[0]), int(values[1])
    if not -1 <= tick <= newest or ended not in (0, 1):
        raise Rejected("held", f"tick {tick}, ended {ended}; the world published up to tick {newest}")
    return tick, bool(ended)
