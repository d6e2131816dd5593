"""The rubenstein algorithm's whole ticks, compiled: the robots decide, the world settles and applies, the joined
robots cover the shape, and the tick's metrics and end are taken (:class:`~swarm_ros.core.rubenstein.run.RubensteinRun`
calls :func:`run_kernel` for many ticks at a time)."""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np

from swarm_ros.core.metrics import END_COMPLETE, END_EXTRAS, END_INCOMPLETE, END_TIMEOUT, RUNNING
from swarm_ros.core.rubenstein.rule import (
    JOINED,
    MOVE_INSIDE,
    MOVE_OUTSIDE,
    apply_kernel,
    build_cells,
    clear_cells,
    cover,
    decide_kernel,
    inside,
    resolve_kernel,
)


class Tally(NamedTuple):
    """The run's running counts, kept between calls of :func:`run_kernel` (int64 / float64 arrays of one)."""

    outside: np.ndarray  #: robots (seeds aside) joined with their centre outside the shape
    error: np.ndarray  #: the sum of the joined robots' localization errors
    last_join: np.ndarray  #: the last tick a robot joined


@numba.njit(cache=True)
def join_robot(i, s, bm, covered, tally, seeds, tick):
    """Robot i has joined at ``tick``: cover the pixels its disc meets and count it."""
    cover(s.x[i], s.y[i], bm, covered)
    if i >= seeds and not inside(s.x[i], s.y[i], bm):
        tally.outside[0] += 1
    tally.error[0] += math.hypot(s.ex[i] - s.x[i], s.ey[i] - s.y[i])
    tally.last_join[0] = tick


@numba.njit(cache=True)
def metrics_row(tick, s, covered, tally, seeds, row):
    """The tick's metrics into ``row``: tick, joined, moving, waiting, covered pixels, joined outside, the mean
    localization error of the joined robots other than the seeds."""
    joined = moving = waiting = 0
    for i in range(s.state.size):
        st = s.state[i]
        if st == JOINED:
            joined += 1
        elif st == MOVE_OUTSIDE or st == MOVE_INSIDE:
            moving += 1
        else:
            waiting += 1
    others = joined - seeds
    row[0], row[1], row[2], row[3] = tick, joined, moving, waiting
    row[4], row[5] = covered.sum(), tally.outside[0]
    row[6] = tally.error[0] / others if others > 0 else 0.0
    return joined


@numba.njit(cache=True)
def end_code(tick, joined, robots, covered, pixels, last_join, startup, stall, max_ticks):
    """How the run stands after ``tick`` (docs/model.md): complete (with extras), incomplete, timeout, or on."""
    if covered == pixels:
        return END_COMPLETE if joined == robots else END_EXTRAS
    if joined == robots or tick - max(last_join, startup) >= stall:
        return END_INCOMPLETE
    if tick >= max_ticks:
        return END_TIMEOUT
    return RUNNING


@numba.njit(cache=True)
def settle_tick(mine, s, rule, bm, cells, out, granted, slot, covered, tally, row, tick, end):
    """The world's half of ``tick``: robots ``mine`` (every robot not joined, ascending) decided into ``out``
    (position k robot ``mine[k]``'s), and ``cells`` holds every robot where it stood. Settle and apply the
    moves, cover the pixels of the robots that joined, and write the tick's metrics into ``row``. Empties
    ``cells``. Returns the end code."""
    n = s.state.size
    seeds, stall, max_ticks = end
    m = mine.size
    for k in range(m):
        slot[mine[k]] = k
    resolve_kernel(mine, out, s, rule.seed, cells, tick, slot, granted)
    cells.head[:] = -1
    for k in range(m):
        slot[mine[k]] = -1
    apply_kernel(mine, out, granted, s)
    for k in range(m):
        if s.state[mine[k]] == JOINED:
            join_robot(mine[k], s, bm, covered, tally, seeds, tick)
    joined = metrics_row(tick, s, covered, tally, seeds, row)
    return end_code(tick, joined, n, covered.sum(), bm.mask.sum(), tally.last_join[0], rule.startup, stall, max_ticks)


@numba.njit(cache=True)
def settle_shard_kernel(present, deciding, own, s, rule, cells, out, granted, slot, tick):
    """A world shard's half of ``tick`` (:mod:`swarm_ros.core.central_shards`): ``deciding`` holds its own deciding
    robots (the first ``own``) and then its halo's, their decisions in ``out``; ``present`` every robot it holds
    (ascending), where it stood. Settle every deciding robot's move against the robots present, as
    :func:`settle_tick` does (a grant reads the robots within one cell, each in the shard's own columns or its
    halo), and apply its own robots' decisions."""
    for k in range(deciding.size):
        slot[deciding[k]] = k
    build_cells(present, s.x, s.y, cells)
    resolve_kernel(deciding, out, s, rule.seed, cells, tick, slot, granted)
    clear_cells(present, s.x, s.y, cells)
    for k in range(deciding.size):
        slot[deciding[k]] = -1
    apply_kernel(deciding[:own], out, granted, s)


@numba.njit(cache=True)
def not_joined(state, ids):
    """Write the ids of the robots not joined, ascending, into ``ids``; return how many."""
    m = 0
    for i in range(state.size):
        if state[i] != JOINED:
            ids[m] = i
            m += 1
    return m


@numba.njit(cache=True)
def run_kernel(s, rule, bm, cells, out, granted, slot, ax, ay, am, covered, tally, rows, tick, limit, end):
    """Up to ``limit`` whole ticks after ``tick`` for every robot, stopping when the run ends; row r of ``rows``
    gets the r-th tick's metrics. ``end`` = (seeds, stall ticks, max ticks). Returns (ticks run, end code)."""
    n = s.state.size
    everyone = np.arange(n)
    ids = np.empty(n, dtype=np.int64)
    code = RUNNING
    t = 0
    while t < limit and code == RUNNING:
        tick += 1
        mine = ids[: not_joined(s.state, ids)]
        build_cells(everyone, s.x, s.y, cells)
        decide_kernel(mine, s, rule, bm, cells, tick, out, ax, ay, am)
        code = settle_tick(mine, s, rule, bm, cells, out, granted, slot, covered, tally, rows[t], tick, end)
        t += 1
    return t, code
