"""The robot rule: what each moving robot decides at a tick, from a read-only view of the last one.

A decision depends only on the robot's own state, the shape, the moving robots within
its vision radius of the point ahead, the frontier patches within its vision radius,
and its own random stream, so any batch of robots can decide in any process and the
union of the batches' decisions equals the decision of the whole swarm. The world then
settles the claims (:mod:`swarm_ros.core.arbitration`).

A moving robot, each tick (MODEL.md):

1. if its patch is a shape patch, it looks for a join target: the nearest frontier
   patch (empty shape patch with a localized 8-neighbour) whose centre is within the
   vision radius of the robot; ties go to the lowest (y, x). If there is one, the robot
   claims it and does nothing else this tick;
2. otherwise it turns by a uniform angle in [-wiggle, +wiggle]; if the patch one step
   ahead is a wall, or another moving robot is within the vision radius of the point
   one step ahead, it turns to a uniform random heading and stays; else it steps one
   patch forward.

The hot loops are compiled with numba: they visit each moving robot once and each of
its nearby cells of a patch-sized cell list, so a tick costs O(moving robots).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from .params import RunParams
from .rng import STREAM_TURN, STREAM_WIGGLE, draw_uniform
from .shapes import Shape
from .state import RobotState, SwarmState

TWO_PI = 2.0 * math.pi


@numba.njit(cache=True, inline="always")
def patch_index(x: float, y: float, radius: int, size: int) -> int:
    """Flat index of the patch whose centre is nearest to (x, y)."""
    return (int(math.floor(y + 0.5)) + radius) * size + int(math.floor(x + 0.5)) + radius


@numba.njit(cache=True)
def index_build(ids, x, y, radius, size, head, nxt):
    """Insert robots ``ids`` into the cell list (one cell per patch).

    ``head`` (W*W) holds the first robot of each cell or -1; ``nxt`` (N) links robots of a
    cell. Only the cells of ``ids`` are touched, so :func:`index_clear` undoes it in O(len(ids)).
    """
    for k in range(ids.size):
        i = ids[k]
        c = patch_index(x[i], y[i], radius, size)
        nxt[i] = head[c]
        head[c] = i


@numba.njit(cache=True)
def index_clear(ids, x, y, radius, size, head):
    """Empty the cells :func:`index_build` filled (positions must be unchanged since)."""
    for k in range(ids.size):
        i = ids[k]
        head[patch_index(x[i], y[i], radius, size)] = -1


@numba.njit(cache=True)
def crowded(ax, ay, me, vision, x, y, radius, size, head, nxt) -> bool:
    """True if a robot in the cell list other than ``me`` is within ``vision`` of (ax, ay)."""
    v2 = vision * vision
    reach = int(math.floor(vision + 1.0))
    cx = int(math.floor(ax + 0.5))
    cy = int(math.floor(ay + 0.5))
    for py in range(max(cy - reach, -radius), min(cy + reach, radius) + 1):
        row = (py + radius) * size + radius
        for px in range(max(cx - reach, -radius), min(cx + reach, radius) + 1):
            j = head[row + px]
            while j >= 0:
                if j != me:
                    dx = x[j] - ax
                    dy = y[j] - ay
                    if dx * dx + dy * dy <= v2:
                        return True
                j = nxt[j]
    return False


@numba.njit(cache=True)
def join_target(xi, yi, vision, frontier, radius, size) -> int:
    """Flat index of the nearest frontier patch within ``vision`` of (xi, yi), or -1."""
    v2 = vision * vision
    reach = int(math.floor(vision + 0.5))
    cx = int(math.floor(xi + 0.5))
    cy = int(math.floor(yi + 0.5))
    best = -1
    best_d2 = math.inf
    for py in range(max(cy - reach, -radius), min(cy + reach, radius) + 1):
        row = (py + radius) * size + radius
        for px in range(max(cx - reach, -radius), min(cx + reach, radius) + 1):
            q = row + px
            if frontier[q]:
                dx = px - xi
                dy = py - yi
                d2 = dx * dx + dy * dy
                if d2 <= v2 and d2 < best_d2:
                    best_d2 = d2
                    best = q
    return best


@numba.njit(cache=True)
def decide_kernel(ids, x, y, heading, shape, wall, frontier, radius, size, vision, wiggle, seed, tick,
                  head, nxt, out_claim, out_x, out_y, out_heading):
    """Decide for robots ``ids`` (moving, all inserted in the cell list) at ``tick``.

    Writes, per position k of ``ids``: the claimed patch (flat index, or -1) and the
    position and heading the robot will have if it does not join. Reads only the
    previous tick's arrays; writes only the ``out_*`` arrays.
    """
    for k in range(ids.size):
        i = ids[k]
        xi = x[i]
        yi = y[i]
        claim = -1
        if shape[patch_index(xi, yi, radius, size)]:
            claim = join_target(xi, yi, vision, frontier, radius, size)
        out_claim[k] = claim
        if claim >= 0:
            out_x[k] = xi
            out_y[k] = yi
            out_heading[k] = heading[i]
            continue
        h = heading[i] + wiggle * (2.0 * draw_uniform(seed, i, tick, STREAM_WIGGLE) - 1.0)
        ax = xi + math.cos(h)
        ay = yi + math.sin(h)
        if wall[patch_index(ax, ay, radius, size)] or crowded(ax, ay, i, vision, x, y, radius, size, head, nxt):
            out_x[k] = xi
            out_y[k] = yi
            out_heading[k] = TWO_PI * draw_uniform(seed, i, tick, STREAM_TURN)
        else:
            out_x[k] = ax
            out_y[k] = ay
            out_heading[k] = h % TWO_PI


@dataclass(frozen=True)
class Decisions:
    """What a batch of robots decided at one tick; arrays are aligned with ``ids``.

    Attributes:
        tick: the tick decided.
        ids: robot ids (int64).
        claim: flat patch index each robot claims to join, or -1 (int64).
        x, y: position in patches if the robot does not join (float64).
        heading: heading in radians if the robot does not join (float64).
    """

    tick: int
    ids: np.ndarray
    claim: np.ndarray
    x: np.ndarray
    y: np.ndarray
    heading: np.ndarray

    @staticmethod
    def concatenate(parts: list[Decisions]) -> Decisions:
        """Join the decisions of several batches of one tick (any order)."""
        ticks = {p.tick for p in parts}
        if len(ticks) != 1:
            raise ValueError(f"decisions from different ticks: {sorted(ticks)}")
        return Decisions(
            tick=ticks.pop(),
            ids=np.concatenate([p.ids for p in parts]),
            claim=np.concatenate([p.claim for p in parts]),
            x=np.concatenate([p.x for p in parts]),
            y=np.concatenate([p.y for p in parts]),
            heading=np.concatenate([p.heading for p in parts]),
        )


class Decider:
    """Decides for batches of robots tick after tick, keeping its scratch arrays between calls.

    A robot-batch process holds one; :func:`decide` makes a throwaway one.
    """

    def __init__(self, shape: Shape, params: RunParams) -> None:
        world = shape.world
        self.shape, self.params = shape, params
        self._radius, self._size = world.radius, world.size
        self._shape = shape.mask.ravel().copy()
        self._wall = world.wall_mask().ravel()
        self._head = np.full(world.patch_count, -1, dtype=np.int32)
        self._nxt = np.empty(params.robots, dtype=np.int32)

    def decide(self, view: SwarmState, ids: np.ndarray, tick: int, moving: np.ndarray | None = None) -> Decisions:
        """Decisions of the moving robots ``ids`` at ``tick`` from ``view``, the state at tick - 1.

        ``view`` is read, never written. ``moving`` (all moving robots of ``view``, which
        the robots sense) is computed when not given. Any split of the moving robots into
        batches gives, concatenated, the same decisions as one batch.

        Raises:
            ValueError: an id is out of range or not a moving robot in ``view``.
        """
        ids = np.asarray(ids, dtype=np.int64)
        if view.robots != self.params.robots:
            raise ValueError(f"the view has {view.robots} robots, the run {self.params.robots}")
        if ids.size and (ids.min() < 0 or ids.max() >= view.robots):
            raise ValueError(f"robot ids must be in [0, {view.robots}), got {ids.min()}..{ids.max()}")
        st = view.state[ids]
        if np.any((st != RobotState.MOVING_INSIDE) & (st != RobotState.MOVING_OUTSIDE)):
            raise ValueError("decide() takes moving robots only")
        if moving is None:
            moving = view.moving_ids()
        n = ids.size
        claim = np.empty(n, dtype=np.int64)
        x, y, heading = np.empty(n), np.empty(n), np.empty(n)
        r, w = self._radius, self._size
        index_build(moving, view.x, view.y, r, w, self._head, self._nxt)
        try:
            decide_kernel(ids, view.x, view.y, view.heading, self._shape, self._wall, view.frontier, r, w,
                          self.params.vision_radius, self.params.wiggle_rad, self.params.seed, tick,
                          self._head, self._nxt, claim, x, y, heading)
        finally:
            index_clear(moving, view.x, view.y, r, w, self._head)
        return Decisions(tick=tick, ids=ids, claim=claim, x=x, y=y, heading=heading)


def decide(view: SwarmState, ids: np.ndarray, shape: Shape, params: RunParams, tick: int) -> Decisions:
    """Decisions of the moving robots ``ids`` at ``tick`` from ``view``, the state at tick - 1.

    This is what one robot batch runs (see :class:`Decider`); ``view`` is read, never written.

    Raises:
        ValueError: an id is out of range or not a moving robot in ``view``.
    """
    return Decider(shape, params).decide(view, ids, tick)
