"""The robot rule: what each moving robot decides at a tick, from a read-only view of the last one.

A decision depends only on the robot's own state, the shape and its fill state (the
frontier), the moving robots it senses, and its own random stream, so any batch of
robots can decide in any process and the union of the batches' decisions equals the
decision of the whole swarm. The world then settles the claims and sets the new states
(:mod:`swarm_ros.core.arbitration`).

A moving robot, each tick, under the run's rule set (:mod:`swarm_ros.core.rulesets`;
docs/model.md states the rule in full):

* ``join: walk``, a robot inside the shape or already walking: it targets the nearest
  frontier patch anywhere (ties to the lowest (y, x)); within one patch of its centre it
  claims it, else it faces it and steps exactly one patch towards it. With no frontier
  patch at all it wanders.
* ``join: local``, a robot inside the shape (``steps: one``): it claims the nearest
  frontier patch within its vision radius, if any; else it wanders.
* wandering, ``steps: one``: turn by a uniform wiggle; if the patch one step ahead is a
  wall, or the robot is crowded (``crowding``), turn to a uniform random heading and
  stay; else step one patch forward.
* wandering, ``steps: literal``: the pseudo-code's Move calls as written, up to three
  steps outside the shape and two inside, then (``join: local``) a claim from where the
  robot now stands.

The hot loops are compiled with numba: they visit each moving robot once, each of its
nearby cells of a patch-sized cell list, and (``walk``) the blocks of frontier patches
out to the nearest one, so a tick costs O(moving robots).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from swarm_ros.core.kernel_state import grid_of, moves_for, robots_of, rules_of
from swarm_ros.core.params import RunParams
from swarm_ros.core.rng import (
    STREAM_TURN,
    STREAM_TURN_2,
    STREAM_WIGGLE,
    STREAM_WIGGLE_2,
    STREAM_WIGGLE_3,
    draw_uniform,
)
from swarm_ros.core.rules3d import decide_kernel3, index_build3, index_clear3
from swarm_ros.core.rulesets import CROWD_AHEAD, JOIN_LOCAL, JOIN_WALK, STEPS_ONE
from swarm_ros.core.shapes import Shape
from swarm_ros.core.state import FRONTIER_BLOCK, IS_MOVING, RobotState, SwarmState

TWO_PI = 2.0 * math.pi
_WALKING = np.int8(RobotState.WALKING)


@numba.njit(cache=True, inline="always")
def patch_index(x: float, y: float, radius: int, size: int) -> int:
    """Flat index of the patch whose centre is nearest to (x, y)."""
    return (int(math.floor(y + 0.5)) + radius) * size + int(math.floor(x + 0.5)) + radius


@numba.njit(cache=True, inline="always")
def cell_index(x: float, y: float, z: float, solid: bool, radius: int, size: int) -> int:
    """Flat index of the patch nearest to (x, y), or (``solid``, a 3D world) of the voxel nearest to (x, y, z)."""
    c = patch_index(x, y, radius, size)
    if solid:
        c += (int(math.floor(z + 0.5)) + radius) * size * size
    return c


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
def crowded_disc(ax, ay, me, vision, x, y, radius, size, head, nxt) -> bool:
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
def crowded_ahead(xi, yi, h, me, vision, radius, size, head, nxt) -> bool:
    """True if a robot in the cell list other than ``me`` is on the patch ``vision`` ahead of (xi, yi) along ``h``."""
    px = int(math.floor(xi + vision * math.cos(h) + 0.5))
    py = int(math.floor(yi + vision * math.sin(h) + 0.5))
    if px < -radius or px > radius or py < -radius or py > radius:
        return False  # beyond the walls: nobody there
    j = head[(py + radius) * size + px + radius]
    while j >= 0:
        if j != me:
            return True
        j = nxt[j]
    return False


@numba.njit(cache=True, inline="always")
def crowded(crowd, xi, yi, h, me, vision, x, y, radius, size, head, nxt) -> bool:
    """The rule set's crowding test for a robot at (xi, yi) facing ``h``."""
    if crowd == CROWD_AHEAD:
        return crowded_ahead(xi, yi, h, me, vision, radius, size, head, nxt)
    return crowded_disc(xi + math.cos(h), yi + math.sin(h), me, vision, x, y, radius, size, head, nxt)


@numba.njit(cache=True)
def join_target(xi, yi, vision, frontier, radius, size) -> int:
    """Flat index of the nearest frontier patch within ``vision`` of (xi, yi), or -1 (``join: local``)."""
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


@numba.njit(cache=True, inline="always")
def _scan_block(ux, uy, xi, yi, frontier, blocks, radius, size, nb, best, best_d2):
    """Fold the frontier patches of block (ux, uy) into the nearest-so-far (best, best_d2)."""
    if blocks[uy * nb + ux] == 0:
        return best, best_d2
    b = FRONTIER_BLOCK
    x0 = ux * b - radius
    x1 = min(ux * b + b - 1, size - 1) - radius
    y0 = uy * b - radius
    y1 = min(uy * b + b - 1, size - 1) - radius
    gx = max(x0 - xi, 0.0, xi - x1)
    gy = max(y0 - yi, 0.0, yi - y1)
    if gx * gx + gy * gy > best_d2:
        return best, best_d2
    for py in range(y0, y1 + 1):
        row = (py + radius) * size + radius
        for px in range(x0, x1 + 1):
            q = row + px
            if frontier[q]:
                dx = px - xi
                dy = py - yi
                d2 = dx * dx + dy * dy
                if d2 < best_d2 or (d2 == best_d2 and q < best):
                    best_d2 = d2
                    best = q
    return best, best_d2


@numba.njit(cache=True)
def nearest_frontier(xi, yi, frontier, blocks, radius, size) -> int:
    """Flat index of the nearest frontier patch anywhere (``join: walk``), or -1 if there is none.

    Distance is Euclidean from (xi, yi) to the patch centre; ties go to the lowest flat
    index, i.e. the lowest (y, x). The search goes outward ring by ring over blocks of
    ``FRONTIER_BLOCK`` patches, skips blocks without frontier patches (``blocks``) or
    farther than the best so far, and stops once a whole ring is farther: it costs about
    the blocks within the distance found, not the frontier's size.
    """
    if blocks[blocks.size - 1] == 0:
        return -1
    b = FRONTIER_BLOCK
    nb = (size + b - 1) // b
    bx = (int(math.floor(xi + 0.5)) + radius) // b
    by = (int(math.floor(yi + 0.5)) + radius) // b
    best = -1
    best_d2 = math.inf
    for k in range(max(bx, by, nb - 1 - bx, nb - 1 - by) + 1):
        if k > 0:
            # every patch centre in ring k is at least (k - 1) * b + 0.5 away along x or y
            gap = (k - 1) * b + 0.5
            if gap * gap > best_d2:
                break
        for uy in range(max(by - k, 0), min(by + k, nb - 1) + 1):
            if uy == by - k or uy == by + k:  # the ring's bottom or top row: every block in it
                for ux in range(max(bx - k, 0), min(bx + k, nb - 1) + 1):
                    best, best_d2 = _scan_block(ux, uy, xi, yi, frontier, blocks, radius, size, nb, best, best_d2)
            else:  # the rows between: the ring's left and right blocks
                if bx - k >= 0:
                    best, best_d2 = _scan_block(bx - k, uy, xi, yi, frontier, blocks, radius, size, nb, best,
                                                best_d2)
                if bx + k < nb:
                    best, best_d2 = _scan_block(bx + k, uy, xi, yi, frontier, blocks, radius, size, nb, best,
                                                best_d2)
    return best


@numba.njit(cache=True, inline="always")
def _move(xi, yi, h, wiggle, u, wall, radius, size):
    """The pseudo-code's Move: turn by a wiggle (``u`` uniform in [0, 1)), then step 1 patch forward
    unless that patch is a wall. Returns (x, y, heading)."""
    h = h + wiggle * (2.0 * u - 1.0)
    ax = xi + math.cos(h)
    ay = yi + math.sin(h)
    if wall[patch_index(ax, ay, radius, size)]:
        return xi, yi, h
    return ax, ay, h


@numba.njit(cache=True)
def decide_kernel(ids, robots, grid, rules, tick, head, nxt, out):
    """Decide for robots ``ids`` (moving, all inserted in the cell list ``head``, ``nxt``) at ``tick`` under
    ``rules`` (:class:`~swarm_ros.core.kernel_state.Rules`), in a 2D world.

    Writes ``out`` (:class:`~swarm_ros.core.kernel_state.Moves`), per position k of ``ids``: the claimed
    patch (flat index, or -1) and the position and heading the robot takes if it does not win a claim.
    Reads only the previous tick's ``robots`` and ``grid``; writes only ``out``.
    """
    x, y, heading, state = robots.x, robots.y, robots.heading, robots.state
    shape, wall, frontier, blocks, radius, size = grid.shape, grid.wall, grid.frontier, grid.blocks, grid.radius, \
        grid.size
    vision, wiggle, seed, join, crowd, steps = rules.vision, rules.wiggle, rules.seed, rules.join, rules.crowd, \
        rules.steps
    out_claim, out_x, out_y, out_heading = out.claim, out.x, out.y, out.heading
    for k in range(ids.size):
        i = ids[k]
        xi = x[i]
        yi = y[i]
        hi = heading[i]
        claim = -1
        inside = shape[patch_index(xi, yi, radius, size)]
        if join == JOIN_WALK and (state[i] == _WALKING or inside):
            q = nearest_frontier(xi, yi, frontier, blocks, radius, size)
            if q >= 0:
                dx = (q % size - radius) - xi
                dy = (q // size - radius) - yi
                d2 = dx * dx + dy * dy
                if d2 <= 1.0:
                    claim = q  # within one patch: claim it, standing
                else:  # face it and step exactly one patch towards it
                    d = math.sqrt(d2)
                    xi += dx / d
                    yi += dy / d
                    hi = math.atan2(dy, dx) % TWO_PI
                out_claim[k] = claim
                out_x[k] = xi
                out_y[k] = yi
                out_heading[k] = hi
                continue
            # an empty frontier: nothing to walk to, so the robot wanders
        if steps == STEPS_ONE:
            if join == JOIN_LOCAL and inside:
                claim = join_target(xi, yi, vision, frontier, radius, size)
            if claim < 0:
                h = hi + wiggle * (2.0 * draw_uniform(seed, i, tick, STREAM_WIGGLE) - 1.0)
                ax = xi + math.cos(h)
                ay = yi + math.sin(h)
                if wall[patch_index(ax, ay, radius, size)] or crowded(crowd, xi, yi, h, i, vision, x, y, radius,
                                                                      size, head, nxt):
                    hi = TWO_PI * draw_uniform(seed, i, tick, STREAM_TURN)
                else:
                    xi, yi, hi = ax, ay, h % TWO_PI
        else:  # the pseudo-code's Move calls, as written
            xi, yi, hi = _move(xi, yi, hi, wiggle, draw_uniform(seed, i, tick, STREAM_WIGGLE), wall, radius, size)
            if not inside:
                if wall[patch_index(xi + math.cos(hi), yi + math.sin(hi), radius, size)]:
                    hi = TWO_PI * draw_uniform(seed, i, tick, STREAM_TURN)
                else:
                    xi, yi, hi = _move(xi, yi, hi, wiggle, draw_uniform(seed, i, tick, STREAM_WIGGLE_2), wall,
                                       radius, size)
            if crowded(crowd, xi, yi, hi, i, vision, x, y, radius, size, head, nxt):
                hi = TWO_PI * draw_uniform(seed, i, tick, STREAM_TURN_2 if not inside else STREAM_TURN)
            else:
                xi, yi, hi = _move(xi, yi, hi, wiggle,
                                   draw_uniform(seed, i, tick, STREAM_WIGGLE_3 if not inside else STREAM_WIGGLE_2),
                                   wall, radius, size)
            hi = hi % TWO_PI
            if inside and join == JOIN_LOCAL:
                claim = join_target(xi, yi, vision, frontier, radius, size)
        out_claim[k] = claim
        out_x[k] = xi
        out_y[k] = yi
        out_heading[k] = hi


@numba.njit(cache=True)
def decide_robots(moving, ids, robots, grid, rules, tick, head, nxt, out):
    """Decide for robots ``ids`` (a subset of ``moving``, the moving robots they sense) at ``tick``, in either
    dimension: ``moving`` go into the cell list (``head``: all -1, left so), then each of ``ids`` decides
    (:func:`decide_kernel`, :func:`~swarm_ros.core.rules3d.decide_kernel3`) into ``out``."""
    if grid.solid:
        index_build3(moving, robots.x, robots.y, robots.z, grid.radius, grid.size, head, nxt)
        decide_kernel3(ids, robots, grid, rules, tick, head, nxt, out)
        index_clear3(moving, robots.x, robots.y, robots.z, grid.radius, grid.size, head)
    else:
        index_build(moving, robots.x, robots.y, grid.radius, grid.size, head, nxt)
        decide_kernel(ids, robots, grid, rules, tick, head, nxt, out)
        index_clear(moving, robots.x, robots.y, grid.radius, grid.size, head)


@dataclass(frozen=True)
class Decisions:
    """What a batch of robots decided at one tick; arrays are aligned with ``ids``.

    Attributes:
        tick: the tick decided.
        ids: robot ids (int64).
        claim: flat patch index each robot claims to join, or -1 (int64).
        x, y: position in patches if the robot does not join (float64).
        heading: heading in radians if the robot does not join (float64).
        z, pitch: (3D only; None in 2D) z position and heading elevation if the robot does not join.
    """

    tick: int
    ids: np.ndarray
    claim: np.ndarray
    x: np.ndarray
    y: np.ndarray
    heading: np.ndarray
    z: np.ndarray | None = None
    pitch: np.ndarray | None = None

    @staticmethod
    def standing(view: SwarmState, ids: np.ndarray, tick: int) -> Decisions:
        """Decisions of robots ``ids`` to stand still, as they are in ``view``: no claim, the same pose."""
        solid = {"z": view.z[ids].copy(), "pitch": view.pitch[ids].copy()} if view.z is not None else {}
        return Decisions(tick=tick, ids=ids, claim=np.full(ids.size, -1, dtype=np.int64), x=view.x[ids].copy(),
                         y=view.y[ids].copy(), heading=view.heading[ids].copy(), **solid)

    @staticmethod
    def concatenate(parts: list[Decisions]) -> Decisions:
        """Join the decisions of several batches of one tick (any order)."""
        ticks = {p.tick for p in parts}
        if len(ticks) != 1:
            raise ValueError(f"decisions from different ticks: {sorted(ticks)}")
        if len({p.z is None for p in parts}) != 1:
            raise ValueError("decisions from a 2D and a 3D world")
        solid = parts[0].z is not None
        return Decisions(
            tick=ticks.pop(),
            ids=np.concatenate([p.ids for p in parts]),
            claim=np.concatenate([p.claim for p in parts]),
            x=np.concatenate([p.x for p in parts]),
            y=np.concatenate([p.y for p in parts]),
            heading=np.concatenate([p.heading for p in parts]),
            z=np.concatenate([p.z for p in parts]) if solid else None,
            pitch=np.concatenate([p.pitch for p in parts]) if solid else None,
        )


class Decider:
    """Decides for batches of robots tick after tick, keeping its scratch arrays between calls.

    A robot-batch process holds one; :func:`decide` makes a throwaway one.
    """

    def __init__(self, shape: Shape, params: RunParams) -> None:
        world = shape.world
        self.shape, self.params = shape, params
        self._shape = shape.mask.ravel().copy()
        self._wall = world.wall_mask().ravel()
        self._nbrs = world.neighbour_offsets()
        self._head = np.full(world.patch_count, -1, dtype=np.int32)
        self._nxt = np.empty(params.robots, dtype=np.int32)
        self._rules = rules_of(params)

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
        if not IS_MOVING[view.state[ids]].all():
            raise ValueError("decide() takes moving robots only")
        if moving is None:
            moving = view.moving_ids()
        n = ids.size
        out = moves_for(n, self.shape.dims == 3)
        try:
            decide_robots(moving, ids, robots_of(view), grid_of(self.shape, view, self._shape, self._wall, self._nbrs),
                          self._rules, tick, self._head, self._nxt, out)
        except BaseException:
            self._head.fill(-1)  # the cell list is left as found, whatever happened half-way
            raise
        solid = {"z": out.z, "pitch": out.pitch} if self.shape.dims == 3 else {}
        return Decisions(tick=tick, ids=ids, claim=out.claim, x=out.x, y=out.y, heading=out.heading, **solid)


def decide(view: SwarmState, ids: np.ndarray, shape: Shape, params: RunParams, tick: int) -> Decisions:
    """Decisions of the moving robots ``ids`` at ``tick`` from ``view``, the state at tick - 1.

    This is what one robot batch runs (see :class:`Decider`); ``view`` is read, never written.

    Raises:
        ValueError: an id is out of range or not a moving robot in ``view``.
    """
    return Decider(shape, params).decide(view, ids, tick)
