"""The compiled tick, shared by every path of the engine: the whole-run kernel and the end-of-tick bookkeeping.

:meth:`~swarm_ros.core.darr_niazi.engine.Simulation.run` runs many ticks per call of :func:`run_kernel`;
:meth:`~swarm_ros.core.darr_niazi.engine.Simulation.apply` (a distributed engine's decisions) and
:meth:`~swarm_ros.core.darr_niazi.engine.Simulation.remove` (failures) end their tick with the same
:func:`compact_moving` and :func:`close_tick`, so every path gives identical runs.
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

from swarm_ros.core.darr_niazi import metrics
from swarm_ros.core.darr_niazi.arbitration import resolve_kernel
from swarm_ros.core.darr_niazi.rules import decide_robots
from swarm_ros.core.darr_niazi.state import RobotState
from swarm_ros.core.metrics import END_EXTRAS, RUNNING

_MOVING_OUTSIDE, _MOVING_INSIDE = int(RobotState.MOVING_OUTSIDE), int(RobotState.MOVING_INSIDE)
_WALKING = int(RobotState.WALKING)
_SEPARATED = int(RobotState.SEPARATED)
# The metrics' arithmetic, compiled for the kernels below: the same functions metrics.py runs in Python.
end_code = numba.njit(cache=True)(metrics.end_code)
metric_values = numba.njit(cache=True)(metrics.metric_values)


@numba.njit(cache=True)
def compact_moving(moving, m, state):
    """Keep the still-moving robots at the front of ``moving`` (order kept); return their count."""
    j = 0
    for k in range(m):
        i = moving[k]
        if state[i] == _MOVING_OUTSIDE or state[i] == _MOVING_INSIDE or state[i] == _WALKING:
            moving[j] = i
            j += 1
    return j


@numba.njit(cache=True)
def end_tick(tick, localized, inside, outside, walking, shape_patches, robots, max_ticks, row):
    """The end of a tick, for every path that advances a world (the engine's, a world shard's): the end code from
    the tick's counts; if the shape is complete with robots left over (``END_EXTRAS``), those still moving are
    separated (the caller marks its own: their count is returned) and none counts as moving any more; the
    tick's metrics into ``row``. Returns (end code, separated)."""
    code = end_code(localized, inside + outside + walking, tick, shape_patches, robots, max_ticks)
    separated = 0
    if code == END_EXTRAS:
        separated = inside + outside + walking
        inside = 0
        outside = 0
        walking = 0
    values = metric_values(tick, localized, inside, outside, walking, separated, shape_patches)
    for c in range(len(values)):
        row[c] = values[c]
    return code, separated


@numba.njit(cache=True)
def close_tick(moving, m, state, tick, localized, inside, outside, walking, shape_patches, robots, max_ticks, row):
    """The engine's end of a tick (:func:`end_tick`), its robots still moving (``moving[:m]``) separated if the
    tick separates them. Returns (end code, still moving)."""
    code, separated = end_tick(tick, localized, inside, outside, walking, shape_patches, robots, max_ticks, row)
    if code == END_EXTRAS:
        for k in range(m):
            state[moving[k]] = _SEPARATED
        m = 0
    return code, m


class Scratch(NamedTuple):
    """The engine's work arrays: the cell list (``head``, all -1 between ticks; ``nxt``), the lottery's
    ``best`` (all -1 between ticks), and per robot that decided in the last tick its :class:`JoinOutcome`
    and id."""

    head: np.ndarray
    nxt: np.ndarray
    best: np.ndarray
    outcome: np.ndarray
    last_ids: np.ndarray


class End(NamedTuple):
    """What the end check of a tick compares with (:func:`swarm_ros.core.darr_niazi.metrics.end_code`)."""

    shape_patches: int
    robots: int  #: robots not removed
    max_ticks: int


@numba.njit(cache=True)
def run_kernel(moving, robots, grid, rules, scratch, moves, end, rows, m, tick, localized, limit):
    """Up to ``limit`` whole ticks for the robots ``moving[:m]``, stopping when the run ends.

    Row r of ``rows`` gets the metrics of the r-th tick run. Returns (ticks run, still
    moving, localized, robots that decided in the last tick, end code). The robots decide by
    the kernels of the world's dimension (``grid.solid``); everything else is the same code.
    """
    n = 0
    code = RUNNING
    decided = 0
    while n < limit and code == RUNNING:
        tick += 1
        ids = moving[:m]
        scratch.last_ids[:m] = ids
        decide_robots(ids, ids, robots, grid, rules, tick, scratch.head, scratch.nxt, moves)
        joined, inside, outside, walking = resolve_kernel(
            ids, moves, robots, grid, rules, tick, scratch.best, localized, end.shape_patches, scratch.outcome, m
        )
        localized += joined
        decided = m
        m = compact_moving(moving, m, robots.state)
        code, m = close_tick(
            moving,
            m,
            robots.state,
            tick,
            localized,
            inside,
            outside,
            walking,
            end.shape_patches,
            end.robots,
            end.max_ticks,
            rows[n],
        )
        n += 1
    return n, m, localized, decided, code
