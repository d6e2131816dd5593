"""The Kilobot robot's rule and the world's side of its tick, compiled: one rule, read-only on the last tick.

A robot decides from its own state, the shape, and what the robots within the communication
range broadcast at the last tick (their id, state, gradient, position estimate and whether it
is localized), with the distances to them as measured (the true ones plus, optionally, seeded
noise). So any batch of robots can decide in any process, and the union of the batches'
decisions is the whole swarm's. The world then settles the moves so that no two robots ever
overlap (:func:`resolve_kernel`) and writes the decisions in. docs/model.md states the rule.

Robots are found through a cell list over a fixed grid of cells the size of the communication
range, in the seeds' frame; its chains are built in ascending id order, so the neighbours of a
robot are visited in the same order by every process that knows them.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np

from swarm_ros.core.rng import STREAM_PRIORITY, draw_bits, draw_uniform

START, WAIT, MOVE_OUTSIDE, MOVE_INSIDE, JOINED = range(5)  #: a robot's state codes
STATE_NAMES = ("start", "wait_to_move", "move_while_outside", "move_while_inside", "joined_shape")
UNKNOWN_G = 1 << 40  #: the gradient of a robot with no stationary neighbour closer than G
NEVER = 1 << 62  #: the tick a robot that never began to move began
STREAM_RANGE = 64  #: the noise of robot i's measure of robot j at a tick: stream STREAM_RANGE + j
TWO_PI = 2.0 * math.pi


class Robots(NamedTuple):
    """Every robot's true pose and what it broadcasts and keeps (the arrays of a run, by name)."""

    x: np.ndarray
    y: np.ndarray
    heading: np.ndarray
    state: np.ndarray  #: int8, the codes above
    g: np.ndarray  #: int64 gradient
    ex: np.ndarray  #: position estimate
    ey: np.ndarray
    est: np.ndarray  #: int8: has an estimate
    loc: np.ndarray  #: int8: localized (at least 3 good anchors and a settled estimate; kept once reached)
    still: np.ndarray  #: int64: ticks in a row the estimate moved less than the settle tolerance
    near: np.ndarray  #: the smallest measured distance to a stationary neighbour at the last tick (edge-following)
    began: np.ndarray  #: int64: the tick it began to move (NEVER)
    joined: np.ndarray  #: int64: the tick it joined the shape (-1; the seeds 0)
    waited: np.ndarray  #: int64: ticks in a row it has had an edge-follower ahead within YIELD
    blind: np.ndarray  #: int64: ticks in a row it has moved with an estimate and fewer than 3 anchors


class Rule(NamedTuple):
    """The algorithm's parameters, in robot diameters, radians and ticks (``RunParams``' rubenstein ones)."""

    comm: float
    gradient: float
    desired: float
    yield_dist: float
    patience: int
    step: float
    turn: float
    noise: float
    gain: float
    sweeps: int
    min_angle: float
    settle: float
    settle_ticks: int
    stale: int  #: a mover's estimate is dropped after this many ticks without an update (0: kept)
    startup: int
    seed: int


class Bitmap(NamedTuple):
    """The shape in the seeds' frame (:class:`~swarm_ros.core.rubenstein.layout.ShapeFrame`), flat."""

    mask: np.ndarray  #: bool, row-major, row 0 the bottom
    rows: int
    cols: int
    pixel: float
    x0: float
    y0: float


class Cells(NamedTuple):
    """A cell list over the frame: cell (cx, cy) spans [x0 + cx c, x0 + (cx + 1) c) and likewise in y; points
    beyond the grid fall in its edge cells."""

    head: np.ndarray  #: int64 per cell: the first robot in it, or -1
    nxt: np.ndarray  #: int64 per robot: the next robot in its cell, or -1
    x0: float
    y0: float
    side: float
    nx: int
    ny: int


class Decided(NamedTuple):
    """What robots decided at a tick, per position k of the ids decided: every field of :class:`Robots` as it
    will be after the tick, the position the robot moves to if the world grants it (``to_x``, ``to_y``) and
    whether it asks to move."""

    x: np.ndarray
    y: np.ndarray
    heading: np.ndarray
    state: np.ndarray
    g: np.ndarray
    ex: np.ndarray
    ey: np.ndarray
    est: np.ndarray
    loc: np.ndarray
    still: np.ndarray
    near: np.ndarray
    began: np.ndarray
    joined: np.ndarray
    waited: np.ndarray
    blind: np.ndarray
    moves: np.ndarray  #: int8


def decided_for(n: int) -> Decided:
    """Empty arrays for the decisions of ``n`` robots."""
    f, i, b = np.float64, np.int64, np.int8
    kinds = (f, f, f, b, i, f, f, b, b, i, f, i, i, i, i, b)
    return Decided(*(np.empty(n, dtype=k) for k in kinds))


@numba.njit(cache=True, inline="always")
def _cell(x, y, cells):
    cx = min(max(int(math.floor((x - cells.x0) / cells.side)), 0), cells.nx - 1)
    cy = min(max(int(math.floor((y - cells.y0) / cells.side)), 0), cells.ny - 1)
    return cx, cy


@numba.njit(cache=True)
def build_cells(known, x, y, cells):
    """Put robots ``known`` (ascending ids) into the cell list; each chain ends up in ascending id order."""
    for k in range(known.size - 1, -1, -1):
        i = known[k]
        cx, cy = _cell(x[i], y[i], cells)
        c = cy * cells.nx + cx
        cells.nxt[i] = cells.head[c]
        cells.head[c] = i


@numba.njit(cache=True)
def clear_cells(known, x, y, cells):
    """Empty the cells ``build_cells`` filled (the head array is all -1 between ticks)."""
    for k in range(known.size):
        i = known[k]
        cx, cy = _cell(x[i], y[i], cells)
        cells.head[cy * cells.nx + cx] = -1


@numba.njit(cache=True, inline="always")
def inside(x, y, bm):
    """Whether the point (x, y) of the frame is inside the shape."""
    col = int(math.floor((x - bm.x0) / bm.pixel))
    row = int(math.floor((y - bm.y0) / bm.pixel))
    if row < 0 or row >= bm.rows or col < 0 or col >= bm.cols:
        return False
    return bm.mask[row * bm.cols + col]


@numba.njit(cache=True, inline="always")
def _stationary(st):
    return st == START or st == WAIT or st == JOINED


@numba.njit(cache=True, inline="always")
def _angle_at(px, py, qx, qy, rx, ry):
    """The triangle's angle at p."""
    ax, ay, bx, by = qx - px, qy - py, rx - px, ry - py
    na, nb = math.hypot(ax, ay), math.hypot(bx, by)
    if na == 0.0 or nb == 0.0:
        return 0.0
    c = (ax * bx + ay * by) / (na * nb)
    return math.acos(min(1.0, max(-1.0, c)))


@numba.njit(cache=True, inline="always")
def _farthest(ax, ay, n, i):
    """The anchor of ``[:n]`` farthest from anchor i."""
    best, far = i, -1.0
    for k in range(n):
        d = (ax[k] - ax[i]) ** 2 + (ay[k] - ay[i]) ** 2
        if d > far:
            best, far = k, d
    return best


@numba.njit(cache=True)
def good_geometry(ax, ay, n, min_angle):
    """Whether anchors ``[:n]`` hold a triangle whose smallest angle exceeds ``min_angle``. Tried: the two ends
    of the anchors' long axis (the anchor farthest from the first, and the one farthest from that) with each
    other anchor as the third corner, so O(n). A band of anchors a few rows deep along a straight edge of the
    group passes; a line of them does not."""
    if n < 3:
        return False
    a = _farthest(ax, ay, n, 0)
    b = _farthest(ax, ay, n, a)
    if a == b:
        return False
    for k in range(n):
        if k != a and k != b:
            smallest = min(
                _angle_at(ax[a], ay[a], ax[b], ay[b], ax[k], ay[k]),
                _angle_at(ax[b], ay[b], ax[a], ay[a], ax[k], ay[k]),
                _angle_at(ax[k], ay[k], ax[a], ay[a], ax[b], ay[b]),
            )
            if smallest > min_angle:
                return True
    return False


@numba.njit(cache=True)
def trilaterate(ax, ay, am, n):
    """The least-squares point whose distances to anchors ``[:n]`` are ``am``, from the differences of the
    circles' equations against the first anchor: (x, y, ok)."""
    s11 = s12 = s22 = t1 = t2 = 0.0
    for k in range(1, n):
        a1 = 2.0 * (ax[k] - ax[0])
        a2 = 2.0 * (ay[k] - ay[0])
        r = am[0] ** 2 - am[k] ** 2 + ax[k] ** 2 - ax[0] ** 2 + ay[k] ** 2 - ay[0] ** 2
        s11 += a1 * a1
        s12 += a1 * a2
        s22 += a2 * a2
        t1 += a1 * r
        t2 += a2 * r
    det = s11 * s22 - s12 * s12
    if abs(det) < 1e-12:
        return 0.0, 0.0, False
    return (s22 * t1 - s12 * t2) / det, (s11 * t2 - s12 * t1) / det, True


@numba.njit(cache=True)
def sweep(px, py, ax, ay, am, n, gain):
    """One pass of the distance-error descent over anchors ``[:n]``, in order: for each anchor, move the
    estimate ``gain`` of the way to the point at the measured distance from it, on the line through both."""
    for k in range(n):
        vx, vy = px - ax[k], py - ay[k]
        r = math.hypot(vx, vy)
        if r < 1e-12:
            continue
        nx, ny = ax[k] + am[k] * vx / r, ay[k] + am[k] * vy / r
        px -= (px - nx) * gain
        py -= (py - ny) * gain
    return px, py


@numba.njit(cache=True)
def decide_kernel(ids, s, rule, bm, cells, tick, out, ax, ay, am):
    """Decide for robots ``ids`` (none joined) at ``tick`` from ``s``, the robots at the last tick (read, never
    written), every robot they sense in the cell list. Writes ``out`` (:class:`Decided`) per position k;
    ``ax``, ``ay``, ``am`` are scratch for as many anchors as a robot can have."""
    c2 = rule.comm * rule.comm
    cap = ax.size
    for k in range(ids.size):
        i = ids[k]
        xi, yi, st = s.x[i], s.y[i], s.state[i]
        gmin = UNKNOWN_G
        cur, g_close = np.inf, UNKNOWN_G  # the closest stationary neighbour: measured distance, gradient
        moving_near, yield_to = False, False
        h, h_id = -1, -1  # the largest gradient among the non-joined stationary neighbours, and its largest id
        n = 0
        cx, cy = _cell(xi, yi, cells)
        for gy in range(max(cy - 1, 0), min(cy + 2, cells.ny)):
            for gx in range(max(cx - 1, 0), min(cx + 2, cells.nx)):
                j = cells.head[gy * cells.nx + gx]
                while j >= 0:
                    dx, dy = s.x[j] - xi, s.y[j] - yi
                    d2 = dx * dx + dy * dy
                    if j != i and d2 < c2:
                        m = math.sqrt(d2)
                        if rule.noise > 0.0:
                            m += rule.noise * (2.0 * draw_uniform(rule.seed, i, tick, STREAM_RANGE + j) - 1.0)
                        sj = s.state[j]
                        if _stationary(sj):
                            if m < rule.gradient and s.g[j] < gmin:
                                gmin = s.g[j]
                            if m < cur:
                                cur, g_close = m, s.g[j]
                            if s.loc[j] and s.est[j] and n < cap:
                                ax[n], ay[n], am[n] = s.ex[j], s.ey[j], m
                                n += 1
                            if sj != JOINED and s.g[j] < UNKNOWN_G:
                                if s.g[j] > h:
                                    h, h_id = s.g[j], j
                                elif s.g[j] == h and j > h_id:
                                    h_id = j
                        else:
                            moving_near = True
                            if m < rule.yield_dist and (
                                s.began[j] < s.began[i] or (s.began[j] == s.began[i] and j < i)
                            ):
                                yield_to = True
                    j = cells.nxt[j]
        g = gmin + 1 if gmin < UNKNOWN_G else UNKNOWN_G
        # localization
        ex, ey, est, loc, still, blind = s.ex[i], s.ey[i], s.est[i], s.loc[i], s.still[i], s.blind[i]
        moving = st == MOVE_OUTSIDE or st == MOVE_INSIDE
        # the anchors' geometry gates the first estimate; once it has one, a robot sweeps with any three anchors
        if (est and n >= 3) or good_geometry(ax, ay, n, rule.min_angle):
            blind = 0
            if est:
                px, py = ex, ey
                for _ in range(rule.sweeps if moving else 1):  # a mover lags
                    px, py = sweep(px, py, ax, ay, am, n, rule.gain)
                still = still + 1 if math.hypot(px - ex, py - ey) < rule.settle else 0
                ex, ey = px, py
            else:
                px, py, ok = trilaterate(ax, ay, am, n)
                if ok:
                    ex, ey, est, still = px, py, 1, 0
            if still >= rule.settle_ticks:
                loc = 1
        elif est and moving:  # it walks on, its estimate where it was last updated
            blind += 1
            if rule.stale > 0 and blind >= rule.stale:  # too stale to descend from: trilaterate afresh
                est, loc, still, blind = 0, 0, 0, 0
        # the state's rule
        heading, began, joined, near = s.heading[i], s.began[i], s.joined[i], s.near[i]
        moves = 0
        to_x, to_y = xi, yi
        if st == START:
            if tick >= rule.startup:
                st = WAIT
        elif st == WAIT:
            gi = s.g[i]
            if not moving_near and gi < UNKNOWN_G and (gi > h or (gi == h and i > h_id)):
                st, began = MOVE_OUTSIDE, tick
        elif st == MOVE_OUTSIDE and est and inside(ex, ey, bm):
            st = MOVE_INSIDE
        elif (
            st == MOVE_INSIDE
            and est
            and (
                not inside(ex + rule.step * math.cos(heading), ey + rule.step * math.sin(heading), bm)
                or (g < UNKNOWN_G and g <= g_close)
            )
        ):
            st, joined = JOINED, tick
        waited = s.waited[i] + 1 if yield_to else 0
        if (st == MOVE_OUTSIDE or st == MOVE_INSIDE) and began < tick:  # edge-follow, or yield
            if waited == 0 or waited > rule.patience:
                if cur < rule.desired:
                    turn = 0.0 if near < cur else rule.turn  # left, unless the distance grows
                else:
                    turn = 0.0 if near > cur else -rule.turn  # right, unless it shrinks
                heading = (heading + turn) % TWO_PI
                to_x, to_y = xi + rule.step * math.cos(heading), yi + rule.step * math.sin(heading)
                moves = 1
            near = cur
        out.x[k], out.y[k], out.heading[k], out.state[k], out.g[k] = to_x, to_y, heading, st, g
        out.ex[k], out.ey[k], out.est[k], out.loc[k], out.still[k] = ex, ey, est, loc, still
        out.near[k], out.began[k], out.joined[k], out.waited[k], out.blind[k] = near, began, joined, waited, blind
        out.moves[k] = moves


@numba.njit(cache=True, inline="always")
def _ahead(a, b, seed, tick):
    """Whether robot a's move goes before robot b's: the lower lottery ticket of the tick (ties: lower id)."""
    ta = draw_bits(seed, a, tick, STREAM_PRIORITY)
    tb = draw_bits(seed, b, tick, STREAM_PRIORITY)
    return ta < tb or (ta == tb and a < b)


@numba.njit(cache=True)
def resolve_kernel(ids, out, s, seed, cells, tick, slot, granted):
    """Settle the moves of robots ``ids`` (decided into ``out``; ``slot[i]`` is robot i's position k in ``ids``,
    -1 for every robot not deciding) so that no two robots overlap: robot i moves to (``to_x``, ``to_y``)
    only if that point is at least one diameter from every other robot where it stands now and from where
    every robot whose move goes before i's asks to go (:func:`_ahead`). Whatever the others' outcomes, no two
    robots then overlap, and the outcome does not depend on the order of ``ids``. Writes ``granted[k]``."""
    for k in range(ids.size):
        granted[k] = 0
        if not out.moves[k]:
            continue
        i = ids[k]
        tx, ty = out.x[k], out.y[k]
        ok = True
        cx, cy = _cell(s.x[i], s.y[i], cells)
        for gy in range(max(cy - 1, 0), min(cy + 2, cells.ny)):
            for gx in range(max(cx - 1, 0), min(cx + 2, cells.nx)):
                j = cells.head[gy * cells.nx + gx]
                while j >= 0 and ok:
                    if j != i:
                        if (s.x[j] - tx) ** 2 + (s.y[j] - ty) ** 2 < 1.0:
                            ok = False
                        else:
                            q = slot[j]
                            if (
                                q >= 0
                                and out.moves[q]
                                and (out.x[q] - tx) ** 2 + (out.y[q] - ty) ** 2 < 1.0
                                and _ahead(j, i, seed, tick)
                            ):
                                ok = False
                    j = cells.nxt[j]
        granted[k] = ok


@numba.njit(cache=True)
def apply_kernel(ids, out, granted, s):
    """Write robots ``ids``' decisions into ``s``: their new state, and the position asked for where granted."""
    for k in range(ids.size):
        i = ids[k]
        if granted[k]:
            s.x[i], s.y[i] = out.x[k], out.y[k]
        s.heading[i], s.state[i], s.g[i] = out.heading[k], out.state[k], out.g[k]
        s.ex[i], s.ey[i], s.est[i], s.loc[i], s.still[i] = out.ex[k], out.ey[k], out.est[k], out.loc[k], out.still[k]
        s.near[i], s.began[i], s.joined[i], s.waited[i] = out.near[k], out.began[k], out.joined[k], out.waited[k]
        s.blind[i] = out.blind[k]


@numba.njit(cache=True)
def cover(x, y, bm, covered):
    """Mark the shape pixels a robot of diameter 1 at (x, y) covers (its disc meets the pixel's square);
    return how many were newly covered."""
    new = 0
    c0 = int(math.floor((x - 0.5 - bm.x0) / bm.pixel))
    c1 = int(math.floor((x + 0.5 - bm.x0) / bm.pixel))
    r0 = int(math.floor((y - 0.5 - bm.y0) / bm.pixel))
    r1 = int(math.floor((y + 0.5 - bm.y0) / bm.pixel))
    for row in range(max(r0, 0), min(r1, bm.rows - 1) + 1):
        for col in range(max(c0, 0), min(c1, bm.cols - 1) + 1):
            p = row * bm.cols + col
            if bm.mask[p] and not covered[p]:
                left, bottom = bm.x0 + col * bm.pixel, bm.y0 + row * bm.pixel
                dx = max(left - x, 0.0, x - left - bm.pixel)
                dy = max(bottom - y, 0.0, y - bottom - bm.pixel)
                if dx * dx + dy * dy < 0.25:
                    covered[p] = 1
                    new += 1
    return new
