"""The robot rule: what each moving robot decides at a tick, from a read-only view of the last one.

A decision depends only on the robot's own state, the shape and its fill state (the
frontier), the moving robots it senses, and its own random stream, so any batch of
robots can decide in any process and the union of the batches' decisions equals the
decision of the whole swarm. The world then settles the claims and sets the new states
(:mod:`swarm_ros.core.darr_niazi.arbitration`).

A moving robot, each tick, under the run's rule set (:mod:`swarm_ros.core.darr_niazi.rulesets`;
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
from typing import NamedTuple

import numba
import numpy as np

from swarm_ros.core.darr_niazi.kernel_state import grid_of, moves_for, robots_of, rules_of
from swarm_ros.core.darr_niazi.rules2d import (
    block_distances,
    cell_index,
    crowded,
    index_build,
    index_clear,
    join_target,
    nearest_frontier,
)
from swarm_ros.core.darr_niazi.rules3d import (
    angles,
    crowded3,
    direction,
    index_build3,
    index_clear3,
    join_target3,
    nearest_frontier3,
    random_direction,
    wiggled,
)
from swarm_ros.core.darr_niazi.rulesets import JOIN_LOCAL, JOIN_WALK, STEPS_ONE
from swarm_ros.core.darr_niazi.state import IS_MOVING, RobotState, SwarmState
from swarm_ros.core.errors import ContractError
from swarm_ros.core.params import RunParams
from swarm_ros.core.rng import (
    SPIN,
    STREAM_TURN,
    STREAM_TURN_2,
    STREAM_WIGGLE,
    STREAM_WIGGLE_2,
    STREAM_WIGGLE_3,
    draw_uniform,
)
from swarm_ros.core.shapes import Shape

TWO_PI = 2.0 * math.pi
_WALKING = np.int8(RobotState.WALKING)


# -- the robot rule, one control flow for 2D and 3D; the per-dimension parts below it ------------------------
@numba.njit(cache=True, inline="always")
def _draws(solid, seed, i, tick, stream):
    """The uniform draws of one of a robot's streams at ``tick``: one in 2D, two in 3D (the second ``SPIN``
    streams on)."""
    u = draw_uniform(seed, i, tick, stream)
    return u, draw_uniform(seed, i, tick, stream + SPIN) if solid else 0.0


@numba.njit(cache=True, inline="always")
def _normal(h, solid):
    """A heading as the robot keeps it: in [0, 2 pi) in 2D; a 3D direction's azimuth is kept as it comes."""
    return h if solid else h % TWO_PI


@numba.njit(cache=True, inline="always")
def _step(h, p, solid):
    """The unit step along heading ``h`` (and pitch ``p``)."""
    if solid:
        return direction(h, p)
    return math.cos(h), math.sin(h), 0.0


@numba.njit(cache=True, inline="always")
def _wiggled(h, p, solid, wiggle, u, v):
    """The heading (and pitch) turned by a wiggle, and the unit step along it: (h, p, ex, ey, ez)."""
    if solid:
        h, p = wiggled(h, p, wiggle, u, v)
    else:
        h = h + wiggle * (2.0 * u - 1.0)
    ex, ey, ez = _step(h, p, solid)
    return h, p, ex, ey, ez


@numba.njit(cache=True, inline="always")
def _turned(solid, u, v):
    """A direction uniform on the circle (2D) or the sphere (3D): (heading, pitch)."""
    if solid:
        return random_direction(u, v)
    return TWO_PI * u, 0.0


@numba.njit(cache=True, inline="always")
def _move(xi, yi, zi, h, p, solid, wiggle, u, v, wall, radius, size):
    """The pseudo-code's Move: turn by a wiggle, then step one patch (voxel) forward unless that patch is a wall.
    Returns (x, y, z, heading, pitch)."""
    h, p, ex, ey, ez = _wiggled(h, p, solid, wiggle, u, v)
    if wall[cell_index(xi + ex, yi + ey, zi + ez, solid, radius, size)]:
        return xi, yi, zi, h, p
    return xi + ex, yi + ey, zi + ez, h, p


@numba.njit(cache=True, inline="always")
def _crowded(solid, crowd, xi, yi, zi, h, ex, ey, ez, me, vision, robots, radius, size, head, nxt) -> bool:
    """The rule set's crowding test for a robot at (xi, yi, zi) facing ``h`` (the unit step (ex, ey, ez))."""
    if solid:
        return crowded3(
            crowd, xi, yi, zi, ex, ey, ez, me, vision, robots.x, robots.y, robots.z, radius, size, head, nxt
        )
    return crowded(crowd, xi, yi, h, me, vision, robots.x, robots.y, radius, size, head, nxt)


@numba.njit(cache=True, inline="always")
def _nearest_frontier(xi, yi, zi, solid, frontier, blocks, radius, size, near) -> int:
    if solid:
        return nearest_frontier3(xi, yi, zi, frontier, blocks, radius, size)
    return nearest_frontier(xi, yi, frontier, blocks, radius, size, near)


@numba.njit(cache=True, inline="always")
def _join_target(xi, yi, zi, solid, vision, frontier, radius, size) -> int:
    if solid:
        return join_target3(xi, yi, zi, vision, frontier, radius, size)
    return join_target(xi, yi, vision, frontier, radius, size)


@numba.njit(cache=True, inline="always")
def _toward(q, xi, yi, zi, hi, pi, solid, radius, size):
    """A walking robot and its nearest frontier patch ``q``: claim it if within one patch, standing; else face it
    and step exactly one patch towards it. Returns (claim, x, y, z, heading, pitch)."""
    dx = (q % size - radius) - xi
    dz = 0.0
    if solid:
        dy = ((q // size) % size - radius) - yi
        dz = (q // (size * size) - radius) - zi
    else:
        dy = (q // size - radius) - yi
    d2 = dx * dx + dy * dy + dz * dz
    if d2 <= 1.0:
        return q, xi, yi, zi, hi, pi
    d = math.sqrt(d2)
    if solid:
        hi, pi = angles(dx, dy, dz)
        return -1, xi + dx / d, yi + dy / d, zi + dz / d, hi, pi
    return -1, xi + dx / d, yi + dy / d, zi, math.atan2(dy, dx) % TWO_PI, pi


def _rule_for(solid: bool):
    """The rule compiled for one dimension: ``solid`` (a 3D world) is a constant of the compilation, not data
    tested for every robot, so each of the two kernels holds only its own dimension's code. (Tested at run time,
    inside the inlined helpers, it cost the 2D engine 20-30% of its speed: docs/benchmarks.md.) numba keys each
    kernel's cache by the value it closes over."""

    @numba.njit(cache=True)
    def decide_kernel(ids, robots, grid, rules, tick, head, nxt, out, near):
        """Decide for robots ``ids`` (moving, all inserted in the cell list ``head``, ``nxt``) at ``tick`` under
        ``rules`` (:class:`~swarm_ros.core.darr_niazi.kernel_state.Rules`), in a world of this kernel's dimension (3D:
        the robots' geometry is :mod:`swarm_ros.core.darr_niazi.rules3d`'s; the rule is this one control flow for both).

        Writes ``out`` (:class:`~swarm_ros.core.darr_niazi.kernel_state.Moves`), per position k of ``ids``: the claimed
        patch (flat index, or -1) and the pose the robot takes if it does not win a claim. Reads only the
        previous tick's ``robots`` and ``grid``, and ``near`` (2D, ``join: walk``: each block's distance to the
        frontier, :func:`~swarm_ros.core.darr_niazi.rules2d.block_distances`, which only speeds the search up); writes
        only ``out``.
        """
        x, y, z, heading, pitch, state = robots.x, robots.y, robots.z, robots.heading, robots.pitch, robots.state
        shape, wall, frontier, blocks, radius, size = (
            grid.shape,
            grid.wall,
            grid.frontier,
            grid.blocks,
            grid.radius,
            grid.size,
        )
        vision, wiggle, seed, join, crowd, steps = (
            rules.vision,
            rules.wiggle,
            rules.seed,
            rules.join,
            rules.crowd,
            rules.steps,
        )
        for k in range(ids.size):
            i = ids[k]
            xi, yi, hi = x[i], y[i], heading[i]
            zi = z[i] if solid else 0.0
            pi = pitch[i] if solid else 0.0
            claim = -1
            inside = shape[cell_index(xi, yi, zi, solid, radius, size)]
            walked = False
            if join == JOIN_WALK and (state[i] == _WALKING or inside):
                q = _nearest_frontier(xi, yi, zi, solid, frontier, blocks, radius, size, near)
                if q >= 0:  # an empty frontier: nothing to walk to, so the robot wanders
                    claim, xi, yi, zi, hi, pi = _toward(q, xi, yi, zi, hi, pi, solid, radius, size)
                    walked = True
            if walked:
                pass
            elif steps == STEPS_ONE:
                if join == JOIN_LOCAL and inside:
                    claim = _join_target(xi, yi, zi, solid, vision, frontier, radius, size)
                if claim < 0:
                    u, v = _draws(solid, seed, i, tick, STREAM_WIGGLE)
                    h, p, ex, ey, ez = _wiggled(hi, pi, solid, wiggle, u, v)
                    if wall[cell_index(xi + ex, yi + ey, zi + ez, solid, radius, size)] or _crowded(
                        solid, crowd, xi, yi, zi, h, ex, ey, ez, i, vision, robots, radius, size, head, nxt
                    ):
                        u, v = _draws(solid, seed, i, tick, STREAM_TURN)
                        hi, pi = _turned(solid, u, v)
                    else:
                        xi, yi, zi, hi, pi = xi + ex, yi + ey, zi + ez, _normal(h, solid), p
            else:  # the pseudo-code's Move calls, as written
                u, v = _draws(solid, seed, i, tick, STREAM_WIGGLE)
                xi, yi, zi, hi, pi = _move(xi, yi, zi, hi, pi, solid, wiggle, u, v, wall, radius, size)
                if not inside:
                    ex, ey, ez = _step(hi, pi, solid)
                    if wall[cell_index(xi + ex, yi + ey, zi + ez, solid, radius, size)]:
                        u, v = _draws(solid, seed, i, tick, STREAM_TURN)
                        hi, pi = _turned(solid, u, v)
                    else:
                        u, v = _draws(solid, seed, i, tick, STREAM_WIGGLE_2)
                        xi, yi, zi, hi, pi = _move(xi, yi, zi, hi, pi, solid, wiggle, u, v, wall, radius, size)
                ex, ey, ez = _step(hi, pi, solid)
                if _crowded(solid, crowd, xi, yi, zi, hi, ex, ey, ez, i, vision, robots, radius, size, head, nxt):
                    u, v = _draws(solid, seed, i, tick, STREAM_TURN_2 if not inside else STREAM_TURN)
                    hi, pi = _turned(solid, u, v)
                else:
                    u, v = _draws(solid, seed, i, tick, STREAM_WIGGLE_3 if not inside else STREAM_WIGGLE_2)
                    xi, yi, zi, hi, pi = _move(xi, yi, zi, hi, pi, solid, wiggle, u, v, wall, radius, size)
                hi = _normal(hi, solid)
                if inside and join == JOIN_LOCAL:
                    claim = _join_target(xi, yi, zi, solid, vision, frontier, radius, size)
            out.claim[k] = claim
            out.x[k] = xi
            out.y[k] = yi
            out.heading[k] = hi
            if solid:
                out.z[k] = zi
                out.pitch[k] = pi

    return decide_kernel


decide_kernel_2d = _rule_for(False)  #: the rule in a 2D world
decide_kernel_3d = _rule_for(True)  #: the rule in a 3D world


@numba.njit(cache=True)
def decide_robots(moving, ids, robots, grid, rules, tick, head, nxt, out):
    """Decide for robots ``ids`` (a subset of ``moving``, the moving robots they sense) at ``tick``, in either
    dimension: ``moving`` go into the cell list (``head``: all -1, left so), then each of ``ids`` decides
    (the rule compiled for ``grid``'s dimension, :func:`_rule_for`) into ``out``."""
    if grid.solid:
        index_build3(moving, robots.x, robots.y, robots.z, grid.radius, grid.size, head, nxt)
        decide_kernel_3d(ids, robots, grid, rules, tick, head, nxt, out, np.empty(0, np.int32))
        index_clear3(moving, robots.x, robots.y, robots.z, grid.radius, grid.size, head)
    else:
        index_build(moving, robots.x, robots.y, grid.radius, grid.size, head, nxt)
        # under join: walk, each block's distance to the frontier, once a tick for every search of the tick
        near = block_distances(grid.blocks, grid.size) if rules.join == JOIN_WALK else np.empty(0, np.int32)
        decide_kernel_2d(ids, robots, grid, rules, tick, head, nxt, out, near)
        index_clear(moving, robots.x, robots.y, grid.radius, grid.size, head)


class Decided(NamedTuple):
    """A 2D batch's decisions as a central world's graph carries them (:mod:`swarm_ros.core.strips`): arrays
    aligned with the ids sent beside them, as :class:`Decisions`' own."""

    claim: np.ndarray
    x: np.ndarray
    y: np.ndarray
    heading: np.ndarray


class Decided3D(NamedTuple):
    """A 3D batch's decisions, as :class:`Decided`, with z and the heading's elevation."""

    claim: np.ndarray
    x: np.ndarray
    y: np.ndarray
    heading: np.ndarray
    z: np.ndarray
    pitch: np.ndarray


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
        solid = (
            {"z": view.z[ids].copy(), "pitch": view.pitch[ids].copy()}
            if view.z is not None and view.pitch is not None
            else {}
        )
        return Decisions(
            tick=tick,
            ids=ids,
            claim=np.full(ids.size, -1, dtype=np.int64),
            x=view.x[ids].copy(),
            y=view.y[ids].copy(),
            heading=view.heading[ids].copy(),
            **solid,
        )

    @staticmethod
    def of(tick: int, ids: np.ndarray, decided: Decided | Decided3D) -> Decisions:
        """The decisions ``decided`` of robots ``ids`` for ``tick``."""
        return Decisions(tick, ids, *decided)

    @property
    def decided(self) -> Decided | Decided3D:
        """Its arrays as the central world's graph carries them."""
        if self.z is not None and self.pitch is not None:
            return Decided3D(self.claim, self.x, self.y, self.heading, self.z, self.pitch)
        return Decided(self.claim, self.x, self.y, self.heading)

    @staticmethod
    def concatenate(parts: list[Decisions]) -> Decisions:
        """Join the decisions of several batches of one tick (any order)."""
        ticks = {p.tick for p in parts}
        if len(ticks) != 1:
            raise ContractError(f"decisions from different ticks: {sorted(ticks)}")
        if len({p.z is None for p in parts}) != 1:
            raise ContractError("decisions from a 2D and a 3D world")
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
            ContractError: an id is out of range or not a moving robot in ``view``.
        """
        ids = np.asarray(ids, dtype=np.int64)
        if view.robots != self.params.robots:
            raise ContractError(f"the view has {view.robots} robots, the run {self.params.robots}")
        if ids.size and (ids.min() < 0 or ids.max() >= view.robots):
            raise ContractError(f"robot ids must be in [0, {view.robots}), got {ids.min()}..{ids.max()}")
        if not IS_MOVING[view.state[ids]].all():
            raise ContractError("decide() takes moving robots only")
        if moving is None:
            moving = view.moving_ids()
        n = ids.size
        out = moves_for(n, self.shape.dims == 3)
        try:
            decide_robots(
                moving,
                ids,
                robots_of(view),
                grid_of(self.shape, view, self._shape, self._wall, self._nbrs),
                self._rules,
                tick,
                self._head,
                self._nxt,
                out,
            )
        except BaseException:
            self._head.fill(-1)  # the cell list is left as found, whatever happened half-way
            raise
        solid = {"z": out.z, "pitch": out.pitch} if self.shape.dims == 3 else {}
        return Decisions(tick=tick, ids=ids, claim=out.claim, x=out.x, y=out.y, heading=out.heading, **solid)


def decide(view: SwarmState, ids: np.ndarray, shape: Shape, params: RunParams, tick: int) -> Decisions:
    """Decisions of the moving robots ``ids`` at ``tick`` from ``view``, the state at tick - 1.

    This is what one robot batch runs (see :class:`Decider`); ``view`` is read, never written.

    Raises:
        ContractError: an id is out of range or not a moving robot in ``view``.
    """
    return Decider(shape, params).decide(view, ids, tick)
