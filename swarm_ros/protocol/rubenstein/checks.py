"""The checks of the rubenstein graph's rows, compiled: one pass over a message's rows, whatever it holds.

Each check finds every fault of the rows at once as a bit mask, one bit per kind of fault in the order
the checks are documented in (:func:`~swarm_ros.protocol.rubenstein.rows.check_rubenstein_rows`,
:func:`~swarm_ros.protocol.rubenstein.rows.check_decisions`); the caller names the lowest bit set, so the
fault reported is the one the first failing check finds. A message of a few hundred rows is checked in
microseconds, where numpy's two dozen passes over strided fields took a large share of a tick.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from swarm_ros.core.rubenstein.rule import JOINED, MOVE_OUTSIDE, NEVER, UNKNOWN_G

#: the faults of rows, by bit: (kind, message); "{robots}" and "{tick}" are filled in
ROW_FAULTS = (
    ("bad ids", "ids must ascend within 0..{last}"),
    ("bad state", "a state code or flag out of its set"),
    ("bad number", "a pose or estimate that is not a finite number"),
    ("bad number", "a gradient or counter below -1"),
    ("bad number", "a tick or count beyond tick {tick}"),
    ("bad state", "joined robots, and only they, have a joining tick"),
)
#: the faults of decisions against the robots as they stand, by bit
DECISION_FAULTS = (
    ("illegal", "a state that skips or goes back"),
    ("illegal", "a joining tick other than the tick the robot joined"),
    ("illegal", "a tick the robot began to move other than the one it did"),
    ("illegal", "a turn other than the rule's"),
    ("illegal", "a move other than one step along the heading"),
)
_STATES = 5  #: the state codes are 0..4 (swarm_ros.core.rubenstein.rule)
_TWO_PI = 2.0 * math.pi


def first_fault(mask: int, faults: tuple[tuple[str, str], ...]) -> tuple[str, str] | None:
    """The fault of the lowest bit set in ``mask``, or None."""
    if not mask:
        return None
    return faults[(mask & -mask).bit_length() - 1]


@numba.njit(cache=True)
def row_faults(rows, robots, tick):
    """The faults (bits of :data:`ROW_FAULTS`) of record rows of a rubenstein row type, of tick ``tick``, in a
    swarm of ``robots``."""
    mask = 0
    for k in range(rows.size):
        r = rows[k]
        if r.id >= robots or (k > 0 and r.id <= rows[k - 1].id):
            mask |= 1
        if r.state >= _STATES or r.est > 1 or r.loc > 1:
            mask |= 2
        if not (
            math.isfinite(r.x)
            and math.isfinite(r.y)
            and math.isfinite(r.heading)
            and math.isfinite(r.ex)
            and math.isfinite(r.ey)
            and r.near >= 0.0  # +inf allowed: no stationary neighbour yet; NaN fails
        ):
            mask |= 4
        if min(r.g, r.still, r.began, r.joined, r.waited, r.blind) < -1:
            mask |= 8
        if max(r.began, r.joined, r.still, r.waited, r.blind) > tick:
            mask |= 16
        if (r.state == JOINED) != (r.joined >= 0):
            mask |= 32
    return mask


@numba.njit(cache=True)
def pack_rows(ids, s, indexed, rows):
    """Write into record ``rows`` robots ``ids``' fields of ``s`` (a ``Robots`` or ``Decided``: ``indexed``,
    robot ``ids[k]``'s at ``ids[k]``, else at k), the core's unknown gradient and never-began tick as -1."""
    for k in range(ids.size):
        i = ids[k] if indexed else k
        r = rows[k]
        r.id = ids[k]
        r.x, r.y, r.heading, r.ex, r.ey, r.near = s.x[i], s.y[i], s.heading[i], s.ex[i], s.ey[i], s.near[i]
        r.state, r.est, r.loc = s.state[i], s.est[i], s.loc[i]
        r.g = -1 if s.g[i] == UNKNOWN_G else s.g[i]
        r.began = -1 if s.began[i] == NEVER else s.began[i]
        r.still, r.joined, r.waited, r.blind = s.still[i], s.joined[i], s.waited[i], s.blind[i]


@numba.njit(cache=True)
def unpack_rows(rows, out):
    """Write checked record rows into ``out`` (a :class:`~swarm_ros.core.rubenstein.rule.Robots` or ``Decided``
    of ``rows.size``), position k row k's, -1 back to the core's unknown gradient and never-began tick;
    return their ids."""
    ids = np.empty(rows.size, dtype=np.int64)
    for k in range(rows.size):
        r = rows[k]
        ids[k] = r.id
        out.x[k], out.y[k], out.heading[k], out.ex[k], out.ey[k], out.near[k] = r.x, r.y, r.heading, r.ex, r.ey, r.near
        out.state[k], out.est[k], out.loc[k] = r.state, r.est, r.loc
        out.g[k] = UNKNOWN_G if r.g == -1 else r.g
        out.began[k] = NEVER if r.began == -1 else r.began
        out.still[k], out.joined[k], out.waited[k], out.blind[k] = r.still, r.joined, r.waited, r.blind
    return ids


@numba.njit(cache=True)
def decision_faults(ids, d, s, tick, turn, step, tolerance):
    """The faults (bits of :data:`DECISION_FAULTS`) of decisions ``d`` (position k robot ``ids[k]``'s) for
    ``tick`` against the robots ``s`` as they stand: the rule's turn and step, a step's end within
    ``tolerance`` of the rule's."""
    mask = 0
    for k in range(ids.size):
        i = ids[k]
        was, now = s.state[i], d.state[k]
        if now != was and now != was + 1:
            mask |= 1
        newly = now == JOINED and was != JOINED
        if (newly and d.joined[k] != tick) or (not newly and d.joined[k] != s.joined[i]):
            mask |= 2
        began = now == MOVE_OUTSIDE and was != MOVE_OUTSIDE
        if (began and d.began[k] != tick) or (not began and d.began[k] != s.began[i]):
            mask |= 4
        h = s.heading[i]
        if not (d.heading[k] == h or d.heading[k] == (h + turn) % _TWO_PI or d.heading[k] == (h - turn) % _TWO_PI):
            mask |= 8
        if d.moves[k]:
            to_x, to_y = s.x[i] + step * math.cos(d.heading[k]), s.y[i] + step * math.sin(d.heading[k])
            if not (abs(d.x[k] - to_x) < tolerance and abs(d.y[k] - to_y) < tolerance):
                mask |= 16
        elif d.x[k] != s.x[i] or d.y[k] != s.y[i]:
            mask |= 16
    return mask
