"""The world's side of a tick: settle join claims and apply every robot's decision.

Conflict rule: when several robots claim one patch, the claim with the lowest lottery
ticket wins, where a robot's ticket is 64 bits of its own random stream for that tick
(ties, which need a 64-bit collision, go to the lower robot id). The rule depends only on
(seed, tick, robot id), so it is the same whichever process hosts which robot and in
whatever order decisions arrive.

Join outcomes follow the original study's Z specification: a claim is granted
(``SUCCESS``) only to a robot that is not yet localized, on an empty shape patch, while
fewer robots are localized than the shape has patches; a refused claim's outcome is
``ALREADY_COMPLETE`` if the shape is complete after the tick, else ``INCOMPLETE``. A
refused robot takes the position and heading it decided (under ``steps: literal`` it may
have moved before it claimed).

The world, not the robot, sets each robot's new state, from the previous state, the
decision and the rule set: a winner is localized; under ``join: walk`` a robot that
was inside the shape or walking, while the frontier was not empty, is walking unless it
claimed from standing inside (a walking loser stays walking); every other robot is
moving inside or outside by the patch it now stands on.
"""

from __future__ import annotations

from enum import IntEnum

import numba
import numpy as np

from swarm_ros.core.darr_niazi.rules2d import cell_index
from swarm_ros.core.darr_niazi.rulesets import JOIN_WALK
from swarm_ros.core.darr_niazi.state import FRONTIER_BLOCK, FRONTIER_SUPER, RobotState
from swarm_ros.core.rng import STREAM_PRIORITY, draw_bits

_MOVING_OUTSIDE = np.int8(RobotState.MOVING_OUTSIDE)
_MOVING_INSIDE = np.int8(RobotState.MOVING_INSIDE)
_WALKING = np.int8(RobotState.WALKING)
_LOCALIZED = np.int8(RobotState.LOCALIZED)


class JoinOutcome(IntEnum):
    """Result of one robot's decision at a tick."""

    NO_CLAIM = -1  #: the robot did not try to join (it wandered)
    SUCCESS = 0  #: granted: the robot is localized on the patch it claimed
    ALREADY_COMPLETE = 1  #: refused; the shape is complete
    INCOMPLETE = 2  #: refused (another robot won the patch); the shape is still incomplete


_PENDING = -2


@numba.njit(cache=True, inline="always")
def _wins(a, b, ids, seed, tick):
    ta = draw_bits(seed, ids[a], tick, STREAM_PRIORITY)
    tb = draw_bits(seed, ids[b], tick, STREAM_PRIORITY)
    return ta < tb or (ta == tb and ids[a] < ids[b])


@numba.njit(cache=True, inline="always")
def _mark(q, on, frontier, blocks, size):
    """Set patch ``q``'s frontier flag to ``on``, keeping its block's count, its super-block's and the total in
    step (:func:`swarm_ros.core.darr_niazi.state.frontier_blocks_of`).

    Blocks and super-blocks are numbered in flat order, ``(bz * nb + by) * nb + bx``; a 2D world's (its
    ``frontier`` is ``size`` squared) have no z.
    """
    if frontier[q] != on:
        frontier[q] = on
        b, s = FRONTIER_BLOCK, FRONTIER_SUPER
        nb = (size + b - 1) // b
        ns = (nb + s - 1) // s
        bz = (q // (size * size)) // b
        by = ((q // size) % size) // b
        bx = (q % size) // b
        base = nb * nb * (nb if frontier.size > size * size else 1)  # the blocks', before the super-blocks'
        d = 1 if on else -1
        blocks[(bz * nb + by) * nb + bx] += d
        blocks[base + ((bz // s) * ns + by // s) * ns + bx // s] += d
        blocks[blocks.size - 1] += d


@numba.njit(cache=True)
def occupy(p, i, occupancy, frontier, blocks, shape, nbrs, size):
    """Robot ``i`` localizes on patch ``p``: occupy it and move the frontier around it.

    ``nbrs``: the flat offsets of a patch's neighbours (8 in 2D, 26 in 3D; ``World.neighbour_offsets``).
    """
    occupancy[p] = i
    _mark(p, False, frontier, blocks, size)
    for d in nbrs:
        q = p + d
        if shape[q] and occupancy[q] < 0:
            _mark(q, True, frontier, blocks, size)


@numba.njit(cache=True)
def vacate(p, occupancy, frontier, blocks, shape, nbrs, size):
    """The robot on patch ``p`` is removed: empty it and recompute the frontier around it (``occupy``'s inverse)."""
    occupancy[p] = -1
    for k in range(nbrs.size + 1):  # p itself, then its neighbours
        q = p + nbrs[k - 1] if k else p
        if not shape[q] or occupancy[q] >= 0:
            continue
        near = False
        for e in nbrs:
            if occupancy[q + e] >= 0:
                near = True
        _mark(q, near, frontier, blocks, size)


@numba.njit(cache=True)
def resolve_kernel(ids, moves, robots, grid, rules, tick, best, localized, shape_patches, outcome, applied):
    """Apply the ``moves`` of robots ``ids[:applied]`` (position k: robot ``ids[k]``'s) to ``robots`` and ``grid``
    in place: the lottery of each claimed patch, then each robot's new pose and state
    (:mod:`swarm_ros.core.darr_niazi.kernel_state`). The robots after ``applied`` only take part in the lottery: their
    claims can beat an applied robot's, and what becomes of them is left to whoever applies them (a world
    shard is given its neighbours' claims on the patches its own robots claim, :mod:`swarm_ros.core.central_shards`).

    ``best`` is a W^d int array of -1 (scratch; left as found). ``localized`` is the number of
    localized robots (seeds included) before the tick. Writes each applied robot's :class:`JoinOutcome`
    to ``outcome[k]``. Returns (joined, moving inside, moving outside, walking) counted over the
    applied robots after the tick. The grant's cap (fewer localized robots than shape patches) never
    binds, since the winners claim distinct empty shape patches, so the order of ``ids`` changes nothing.
    """
    claim, new_x, new_y, new_z, new_heading, new_pitch = (
        moves.claim,
        moves.x,
        moves.y,
        moves.z,
        moves.heading,
        moves.pitch,
    )
    x, y, z, heading, pitch, state = robots.x, robots.y, robots.z, robots.heading, robots.pitch, robots.state
    occupancy, frontier, blocks, shape, nbrs, radius, size, solid = (
        grid.occupancy,
        grid.frontier,
        grid.blocks,
        grid.shape,
        grid.nbrs,
        grid.radius,
        grid.size,
        grid.solid,
    )
    seed, join = rules.seed, rules.join
    n = ids.size
    walk = join == JOIN_WALK and blocks[blocks.size - 1] > 0  # the frontier the robots saw was not empty
    for k in range(n):
        p = claim[k]
        if p < 0 or occupancy[p] >= 0 or not shape[p]:
            continue
        b = best[p]
        if b < 0 or _wins(k, b, ids, seed, tick):
            best[p] = k
    joined = 0
    inside = 0
    outside = 0
    walking = 0
    for k in range(applied):
        i = ids[k]
        p = claim[k]
        st = state[i]
        if p >= 0:
            if (
                best[p] == k
                and localized < shape_patches
                and (st == _MOVING_INSIDE or st == _MOVING_OUTSIDE or st == _WALKING)
            ):
                occupy(p, i, occupancy, frontier, blocks, shape, nbrs, size)
                state[i] = _LOCALIZED
                x[i] = float(p % size - radius)
                if solid:
                    y[i] = float((p // size) % size - radius)
                    z[i] = float(p // (size * size) - radius)
                else:
                    y[i] = float(p // size - radius)
                localized += 1
                joined += 1
                outcome[k] = 0
                continue
            outcome[k] = _PENDING
        else:
            outcome[k] = -1
        x[i] = new_x[k]
        y[i] = new_y[k]
        heading[i] = new_heading[k]
        zi = 0.0
        if solid:
            zi = new_z[k]
            z[i] = zi
            pitch[i] = new_pitch[k]
        if walk and (st == _WALKING or (st == _MOVING_INSIDE and p < 0)):
            state[i] = _WALKING
            walking += 1
        elif shape[cell_index(x[i], y[i], zi, solid, radius, size)]:
            state[i] = _MOVING_INSIDE
            inside += 1
        else:
            state[i] = _MOVING_OUTSIDE
            outside += 1
    refused = 1 if localized >= shape_patches else 2
    for k in range(n):
        p = claim[k]
        if p >= 0:
            best[p] = -1
            if k < applied and outcome[k] == _PENDING:
                outcome[k] = refused
    return joined, inside, outside, walking
