"""The rubenstein algorithm's rows between the world and its robot batches, as numpy record types, and their checks:
its ``wire`` in the central world's graph (:data:`WIRE`).

A robot's row is everything it broadcasts and keeps (:class:`~swarm_ros.core.rubenstein.rule.Robots`): its
pose, state, gradient ``g``, position estimate (``ex``, ``ey``), whether it has an estimate and is localized,
and its counters. The world sends batch k its area's rows after each tick (:mod:`swarm_ros.core.strips`),
and batch k answers with a decision row per robot of its strip not joined: the same fields as they will be
after the tick, with ``x``, ``y`` the point the robot moves to if the world grants it, and ``moves``.

They travel as the ``data`` of ``sensor_msgs/PointCloud2`` messages like the study's model's rows
(:mod:`swarm_ros.protocol.rows`): little-endian, a point per robot, ``x``, ``y``, ``z`` first so viewers
draw them, and ``g``, ``ex``, ``ey`` named so a reader of the cloud finds a robot's gradient and estimate.
A PointField has no 64-bit integer, so the counters and ticks travel as int32 (a tick is at most 10^9), a
gradient unknown and a tick never reached as -1; the floats are float64, so the rows carry the exact state
and a batch decides exactly as the world would.
"""

from __future__ import annotations

import numpy as np

from swarm_ros.core.errors import Rejected
from swarm_ros.core.rubenstein.batch import RubensteinBatch
from swarm_ros.core.rubenstein.rule import Decided, Robots, decided_for
from swarm_ros.core.rubenstein.run import RubensteinRun

from ..cdr import register_row_types
from .checks import DECISION_FAULTS, ROW_FAULTS, decision_faults, first_fault, pack_rows, row_faults, unpack_rows

_NAMES = ["x", "y", "z", "heading", "ex", "ey", "near"]
_NAMES += ["g", "still", "began", "joined", "waited", "blind", "id", "state"]
_FORMATS = ["<f8"] * 7 + ["<i4"] * 6 + ["<u4", "<u1"]
_OFFSETS = [0, 8, 16, 24, 32, 40, 48, 56, 60, 64, 68, 72, 76, 80, 84]

#: World -> robot batch k, after each tick: the rows of its area's robots.
RUBENSTEIN_ROW = np.dtype(
    {
        "names": [*_NAMES, "est", "loc"],
        "formats": [*_FORMATS, "<u1", "<u1"],
        "offsets": [*_OFFSETS, 85, 86],
        "itemsize": 88,
    }
)
#: Robot batch k -> world, each tick: each of its robots' decision.
RUBENSTEIN_DECISION_ROW = np.dtype(
    {
        "names": [*_NAMES, "est", "loc", "moves"],
        "formats": [*_FORMATS, "<u1", "<u1", "<u1"],
        "offsets": [*_OFFSETS, 85, 86, 87],
        "itemsize": 88,
    }
)
RUBENSTEIN_ROW_TYPES = (RUBENSTEIN_ROW, RUBENSTEIN_DECISION_ROW)  #: the rubenstein graph's row layouts
register_row_types(*RUBENSTEIN_ROW_TYPES)  # decoded at the speed of the study's model's rows
_STEP_TOLERANCE = 1e-9  #: d: a step's end may differ from the rule's in the last bits of another libm's cos


def rubenstein_rows(ids: np.ndarray, robots: Robots | Decided) -> np.ndarray:
    """The rows of robots ``ids`` (:class:`Robots`: every robot's arrays, indexed by ``ids``) or of decisions
    (:class:`Decided`: position k robot ``ids[k]``'s)."""
    decided = isinstance(robots, Decided)
    rows = np.zeros(ids.size, dtype=RUBENSTEIN_DECISION_ROW if decided else RUBENSTEIN_ROW)
    pack_rows(ids.astype(np.int64, copy=False), robots, not decided, rows)
    if isinstance(robots, Decided):
        rows["moves"] = robots.moves
    return rows


def robots_of_rows(rows: np.ndarray) -> tuple[np.ndarray, Robots]:
    """(ids, the robots' arrays, position k robot ``ids[k]``'s) of checked rows."""
    out = Robots(*decided_for(rows.size)[:-1])
    return unpack_rows(rows, out), out


def decided_of_rows(rows: np.ndarray) -> tuple[np.ndarray, Decided]:
    """(ids, decisions) of checked decision rows."""
    out = decided_for(rows.size)
    ids = unpack_rows(rows, out)
    out.moves[:] = rows["moves"]
    return ids, out


def check_rubenstein_rows(rows: np.ndarray, robots: int, tick: int) -> None:
    """Whether rows of tick ``tick`` (the state after it; decisions: the state they make at it) can be a
    swarm's of ``robots`` robots: ids ascending and in range, states and flags in their sets (and ``moves``
    0 or 1), the floats finite (``near`` may be +inf: no stationary neighbour yet), gradient and counters
    -1 or more, no tick after ``tick``, and a joined robot's joining tick set. Compiled
    (:mod:`swarm_ros.protocol.rubenstein.checks`).

    Raises:
        Rejected: the first fault found, by kind.
    """
    if "moves" in (rows.dtype.names or ()) and np.any(rows["moves"] > 1):
        raise Rejected("bad state", "moves must be 0 or 1")
    fault = first_fault(row_faults(rows, robots, tick), ROW_FAULTS)
    if fault is not None:
        kind, message = fault
        raise Rejected(kind, message.format(last=robots - 1, tick=tick))


def check_decisions(run: RubensteinRun, rows: np.ndarray, tick: int, own: np.ndarray) -> tuple[np.ndarray, Decided]:
    """(ids, decisions) of decision rows for ``tick`` that must be exactly the robots ``own``, each within the
    rule's bounds from where it stands in ``run``: a state moves one step along start, wait, move outside, move
    inside, joined; a robot that moves goes one step along its heading, which turned by at most the turn of a tick.

    Raises:
        Rejected: by kind: the rows' own bounds, robots other than ``own``, or a decision out of the rule's bounds.
    """
    check_rubenstein_rows(rows, run.params.robots, tick)
    ids, d = decided_of_rows(rows)
    if not np.array_equal(ids, own):
        raise Rejected("not its robots", f"{ids.size} decisions for the batch's {own.size} robots")
    fault = first_fault(
        decision_faults(ids, d, run.robots, tick, run.rule.turn, run.rule.step, _STEP_TOLERANCE), DECISION_FAULTS
    )
    if fault is not None:
        raise Rejected(*fault)
    return ids, d


class RubensteinWire:
    """The rubenstein algorithm's rows in the central world's graph (:class:`swarm_ros.protocol.central_rows.Wire`)."""

    row, decision_row = RUBENSTEIN_ROW, RUBENSTEIN_DECISION_ROW
    rows = staticmethod(rubenstein_rows)
    decision_rows = staticmethod(rubenstein_rows)
    robots_of = staticmethod(robots_of_rows)
    decisions_of = staticmethod(decided_of_rows)
    check_decisions = staticmethod(check_decisions)
    batch = RubensteinBatch

    def __init__(self, dims: int = 2) -> None: ...  # (its world is a plane)

    @staticmethod
    def check_rows(run: RubensteinRun, rows: np.ndarray, tick: int) -> None:
        check_rubenstein_rows(rows, run.params.robots, tick)
