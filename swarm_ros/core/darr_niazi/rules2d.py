"""The robot's geometry in a 2D world, compiled with numba: patch indices, the cell list of moving robots,
crowding, and the search for the nearest frontier patch within vision (``join: local``) or anywhere
(``join: walk``). The rule itself is one control flow for both dimensions,
:func:`swarm_ros.core.darr_niazi.rules.decide_kernel`; :mod:`swarm_ros.core.darr_niazi.rules3d` is the 3D geometry.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from swarm_ros.core.darr_niazi.rulesets import CROWD_AHEAD
from swarm_ros.core.darr_niazi.state import FRONTIER_BLOCK, FRONTIER_SUPER


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


@numba.njit(cache=True, inline="always")
def _scan_line(ux, uy, dx, dy, count, xi, yi, frontier, blocks, radius, size, nb, ns, best, best_d2):
    """Fold the frontier patches of ``count`` blocks from (ux, uy) on, a step (dx, dy) apart (one of them 1, the
    other 0), into the nearest-so-far; the stretch in a super-block without frontier patches is passed over whole."""
    s = FRONTIER_SUPER
    at = ux if dx else uy  # the coordinate that moves
    end = at + count
    while at < end:
        stop = min(end, (at // s + 1) * s)  # the end of this super-block's stretch of the line
        if blocks[nb * nb + (uy // s) * ns + ux // s] > 0:
            for _ in range(stop - at):
                best, best_d2 = _scan_block(ux, uy, xi, yi, frontier, blocks, radius, size, nb, best, best_d2)
                ux += dx
                uy += dy
        else:
            ux += dx * (stop - at)
            uy += dy * (stop - at)
        at = stop
    return best, best_d2


@numba.njit(cache=True)
def block_distances(blocks, size):
    """Per block of the world (``size`` patches a side), how many blocks away the nearest block holding frontier
    patches is, counted as a king moves (Chebyshev): 0 for a block that holds some. Two passes of the 3 x 3
    neighbourhood over the blocks' counts (``blocks``), which give that distance exactly. A robot's search for
    the nearest frontier patch starts at that ring (:func:`nearest_frontier`): every ring before it is empty."""
    nb = (size + FRONTIER_BLOCK - 1) // FRONTIER_BLOCK
    far = 2 * nb
    d = np.empty(nb * nb, np.int32)
    for i in range(nb * nb):
        d[i] = 0 if blocks[i] > 0 else far
    for y in range(nb):  # from the low corner: the neighbours already visited
        for x in range(nb):
            i = y * nb + x
            v = d[i]
            if x > 0:
                v = min(v, d[i - 1] + 1)
            if y > 0:
                v = min(v, d[i - nb] + 1)
                if x > 0:
                    v = min(v, d[i - nb - 1] + 1)
                if x < nb - 1:
                    v = min(v, d[i - nb + 1] + 1)
            d[i] = v
    for y in range(nb - 1, -1, -1):  # and back from the high corner
        for x in range(nb - 1, -1, -1):
            i = y * nb + x
            v = d[i]
            if x < nb - 1:
                v = min(v, d[i + 1] + 1)
            if y < nb - 1:
                v = min(v, d[i + nb] + 1)
                if x < nb - 1:
                    v = min(v, d[i + nb + 1] + 1)
                if x > 0:
                    v = min(v, d[i + nb - 1] + 1)
            d[i] = v
    return d


@numba.njit(cache=True)
def nearest_frontier(xi, yi, frontier, blocks, radius, size, near=None) -> int:
    """Flat index of the nearest frontier patch anywhere (``join: walk``), or -1 if there is none.

    Distance is Euclidean from (xi, yi) to the patch centre; ties go to the lowest flat
    index, i.e. the lowest (y, x). The search goes outward ring by ring over blocks of
    ``FRONTIER_BLOCK`` patches, skips blocks without frontier patches (``blocks``) or
    farther than the best so far, and stops once a whole ring is farther. The stretch of a ring in a super-block
    of ``FRONTIER_SUPER`` x ``FRONTIER_SUPER`` blocks without frontier patches is passed over in one step, so a
    search costs about the blocks near the frontier it finds and the super-blocks on the way: not the square of
    its distance in blocks, as for a robot far inside a large shape whose frontier is still small (the start of
    a run). Given ``near`` (:func:`block_distances` of ``blocks``), it starts at the first ring that can hold a
    frontier patch. Only what is strictly farther is skipped: the answer is the nearest whatever the order.
    """
    if blocks[blocks.size - 1] == 0:
        return -1
    b = FRONTIER_BLOCK
    nb = (size + b - 1) // b
    ns = (nb + FRONTIER_SUPER - 1) // FRONTIER_SUPER
    bx = (int(math.floor(xi + 0.5)) + radius) // b
    by = (int(math.floor(yi + 0.5)) + radius) // b
    best = -1
    best_d2 = math.inf
    first = 0 if near is None else near[by * nb + bx]  # the rings before it hold no frontier patch
    for k in range(first, max(bx, by, nb - 1 - bx, nb - 1 - by) + 1):
        if k > 0:
            # every patch centre in ring k is at least (k - 1) * b + 0.5 away along x or y
            gap = (k - 1) * b + 0.5
            if gap * gap > best_d2:
                break
        x0, x1 = max(bx - k, 0), min(bx + k, nb - 1)
        for j in range(2 if k > 0 else 1):  # the ring's bottom and top rows: every block in them
            uy = by - k if j == 0 else by + k
            if 0 <= uy < nb:
                best, best_d2 = _scan_line(
                    x0, uy, 1, 0, x1 - x0 + 1, xi, yi, frontier, blocks, radius, size, nb, ns, best, best_d2
                )
        y0, y1 = max(by - k + 1, 0), min(by + k - 1, nb - 1)
        for j in range(2 if k > 0 else 0):  # the ring's left and right columns, between those rows
            ux = bx - k if j == 0 else bx + k
            if 0 <= ux < nb and y1 >= y0:
                best, best_d2 = _scan_line(
                    ux, y0, 0, 1, y1 - y0 + 1, xi, yi, frontier, blocks, radius, size, nb, ns, best, best_d2
                )
    return best
