"""The robot's geometry in a 3D world, compiled with numba: a position (x, y, z) and a heading that is a
direction. The rule itself is one control flow for both dimensions,
:func:`swarm_ros.core.darr_niazi.rules.decide_kernel`, which calls these where a 3D world differs.

The rule is the 2D rule read in 3D (docs/model.md, "Three dimensions"): a wiggle turns the
heading to a direction uniform on the spherical cap of angular radius ``wiggle`` about it; a
random turn picks a direction uniform on the sphere; a step is one patch (voxel) along the
heading; walls and crowding are tested straight ahead; vision is a ball. These functions differ
from the 2D ones because a 3D heading is two angles and every scan has a third loop; the
arbitration, the frontier, the metrics and the end of a tick are the 2D code's.

A heading is kept as (azimuth ``heading`` in [0, 2 pi), elevation ``pitch`` in [-pi/2, pi/2]).
A 3D rotation draws two numbers: the first from the stream the 2D rule uses, the second from
that stream + :data:`~swarm_ros.core.rng.SPIN`.
"""

from __future__ import annotations

import math

import numba

from swarm_ros.core.darr_niazi.rulesets import CROWD_AHEAD
from swarm_ros.core.darr_niazi.state import FRONTIER_BLOCK

TWO_PI = 2.0 * math.pi


@numba.njit(cache=True, inline="always")
def voxel_index(x, y, z, radius, size) -> int:
    """Flat index of the voxel whose centre is nearest to (x, y, z)."""
    return (
        ((int(math.floor(z + 0.5)) + radius) * size + int(math.floor(y + 0.5)) + radius) * size
        + int(math.floor(x + 0.5))
        + radius
    )


@numba.njit(cache=True, inline="always")
def direction(h, p):
    """The unit vector of heading (azimuth ``h``, elevation ``p``)."""
    cp = math.cos(p)
    return cp * math.cos(h), cp * math.sin(h), math.sin(p)


@numba.njit(cache=True, inline="always")
def angles(dx, dy, dz):
    """(azimuth in [0, 2 pi), elevation) of a non-zero vector."""
    return math.atan2(dy, dx) % TWO_PI, math.atan2(dz, math.hypot(dx, dy))


@numba.njit(cache=True, inline="always")
def wiggled(h, p, wiggle, u, v):
    """A direction uniform on the cap of angular radius ``wiggle`` about (h, p): the angle from it has a
    cosine uniform in [cos wiggle, 1] (``u``), the direction it tilts towards is uniform (``v``)."""
    ct = 1.0 - u * (1.0 - math.cos(wiggle))
    st = math.sqrt(max(0.0, 1.0 - ct * ct))
    a = st * math.cos(TWO_PI * v)
    b = st * math.sin(TWO_PI * v)
    ch, sh, cp, sp = math.cos(h), math.sin(h), math.cos(p), math.sin(p)
    # the heading d = (cp ch, cp sh, sp) and two unit vectors square to it and to each other:
    # e1 = (-sh, ch, 0) (level) and e2 = (-sp ch, -sp sh, cp) (up)
    return angles(ct * cp * ch - a * sh - b * sp * ch, ct * cp * sh + a * ch - b * sp * sh, ct * sp + b * cp)


@numba.njit(cache=True, inline="always")
def random_direction(u, v):
    """A direction uniform on the sphere: azimuth ``2 pi u``, sine of the elevation ``2 v - 1``."""
    return TWO_PI * u, math.asin(2.0 * v - 1.0)


@numba.njit(cache=True)
def index_build3(ids, x, y, z, radius, size, head, nxt):
    """Insert robots ``ids`` into the voxel cell list (:func:`swarm_ros.core.darr_niazi.rules2d.index_build` in 3D)."""
    for k in range(ids.size):
        i = ids[k]
        c = voxel_index(x[i], y[i], z[i], radius, size)
        nxt[i] = head[c]
        head[c] = i


@numba.njit(cache=True)
def index_clear3(ids, x, y, z, radius, size, head):
    for k in range(ids.size):
        i = ids[k]
        head[voxel_index(x[i], y[i], z[i], radius, size)] = -1


@numba.njit(cache=True)
def crowded_ball(ax, ay, az, me, vision, x, y, z, radius, size, head, nxt) -> bool:
    """True if a robot in the cell list other than ``me`` is within ``vision`` of (ax, ay, az)."""
    v2 = vision * vision
    reach = int(math.floor(vision + 1.0))
    cx = int(math.floor(ax + 0.5))
    cy = int(math.floor(ay + 0.5))
    cz = int(math.floor(az + 0.5))
    for pz in range(max(cz - reach, -radius), min(cz + reach, radius) + 1):
        for py in range(max(cy - reach, -radius), min(cy + reach, radius) + 1):
            row = ((pz + radius) * size + py + radius) * size + radius
            for px in range(max(cx - reach, -radius), min(cx + reach, radius) + 1):
                j = head[row + px]
                while j >= 0:
                    if j != me:
                        dx = x[j] - ax
                        dy = y[j] - ay
                        dz = z[j] - az
                        if dx * dx + dy * dy + dz * dz <= v2:
                            return True
                    j = nxt[j]
    return False


@numba.njit(cache=True)
def crowded3(crowd, xi, yi, zi, ex, ey, ez, me, vision, x, y, z, radius, size, head, nxt) -> bool:
    """The rule set's crowding test for a robot at (xi, yi, zi) facing the unit vector (ex, ey, ez)."""
    if crowd == CROWD_AHEAD:  # another robot on the voxel ``vision`` straight ahead
        px = int(math.floor(xi + vision * ex + 0.5))
        py = int(math.floor(yi + vision * ey + 0.5))
        pz = int(math.floor(zi + vision * ez + 0.5))
        if max(abs(px), abs(py), abs(pz)) > radius:
            return False  # beyond the walls: nobody there
        j = head[((pz + radius) * size + py + radius) * size + px + radius]
        while j >= 0:
            if j != me:
                return True
            j = nxt[j]
        return False
    return crowded_ball(xi + ex, yi + ey, zi + ez, me, vision, x, y, z, radius, size, head, nxt)


@numba.njit(cache=True)
def join_target3(xi, yi, zi, vision, frontier, radius, size) -> int:
    """Flat index of the nearest frontier voxel within ``vision`` of (xi, yi, zi), or -1 (ties to the
    lowest flat index)."""
    v2 = vision * vision
    reach = int(math.floor(vision + 0.5))
    cx = int(math.floor(xi + 0.5))
    cy = int(math.floor(yi + 0.5))
    cz = int(math.floor(zi + 0.5))
    best = -1
    best_d2 = math.inf
    for pz in range(max(cz - reach, -radius), min(cz + reach, radius) + 1):
        for py in range(max(cy - reach, -radius), min(cy + reach, radius) + 1):
            row = ((pz + radius) * size + py + radius) * size + radius
            for px in range(max(cx - reach, -radius), min(cx + reach, radius) + 1):
                q = row + px
                if frontier[q]:
                    dx = px - xi
                    dy = py - yi
                    dz = pz - zi
                    d2 = dx * dx + dy * dy + dz * dz
                    if d2 <= v2 and d2 < best_d2:
                        best_d2 = d2
                        best = q
    return best


@numba.njit(cache=True)
def _scan_cube(ux, uy, uz, xi, yi, zi, frontier, blocks, radius, size, nb, best, best_d2):
    """Fold the frontier voxels of block (ux, uy, uz) into the nearest-so-far (best, best_d2)."""
    if blocks[(uz * nb + uy) * nb + ux] == 0:
        return best, best_d2
    b = FRONTIER_BLOCK
    x0, y0, z0 = ux * b - radius, uy * b - radius, uz * b - radius
    x1 = min(ux * b + b - 1, size - 1) - radius
    y1 = min(uy * b + b - 1, size - 1) - radius
    z1 = min(uz * b + b - 1, size - 1) - radius
    gx = max(x0 - xi, 0.0, xi - x1)
    gy = max(y0 - yi, 0.0, yi - y1)
    gz = max(z0 - zi, 0.0, zi - z1)
    if gx * gx + gy * gy + gz * gz > best_d2:
        return best, best_d2
    for pz in range(z0, z1 + 1):
        for py in range(y0, y1 + 1):
            row = ((pz + radius) * size + py + radius) * size + radius
            for px in range(x0, x1 + 1):
                q = row + px
                if frontier[q]:
                    dx = px - xi
                    dy = py - yi
                    dz = pz - zi
                    d2 = dx * dx + dy * dy + dz * dz
                    if d2 < best_d2 or (d2 == best_d2 and q < best):
                        best_d2 = d2
                        best = q
    return best, best_d2


@numba.njit(cache=True)
def nearest_frontier3(xi, yi, zi, frontier, blocks, radius, size) -> int:
    """Flat index of the nearest frontier voxel anywhere (``join: walk``), or -1 if there is none; ties to the
    lowest flat index. Searches shells of blocks outward, as
    :func:`swarm_ros.core.darr_niazi.rules2d.nearest_frontier`."""
    if blocks[blocks.size - 1] == 0:
        return -1
    b = FRONTIER_BLOCK
    nb = (size + b - 1) // b
    bx = (int(math.floor(xi + 0.5)) + radius) // b
    by = (int(math.floor(yi + 0.5)) + radius) // b
    bz = (int(math.floor(zi + 0.5)) + radius) // b
    best = -1
    best_d2 = math.inf
    far = max(bx, by, bz, nb - 1 - bx, nb - 1 - by, nb - 1 - bz)
    for k in range(far + 1):
        if k > 0:
            gap = (k - 1) * b + 0.5  # every voxel centre in shell k is at least this far along one axis
            if gap * gap > best_d2:
                break
        for uz in range(max(bz - k, 0), min(bz + k, nb - 1) + 1):
            for uy in range(max(by - k, 0), min(by + k, nb - 1) + 1):
                for ux in range(max(bx - k, 0), min(bx + k, nb - 1) + 1):
                    if max(abs(ux - bx), abs(uy - by), abs(uz - bz)) == k:
                        best, best_d2 = _scan_cube(
                            ux, uy, uz, xi, yi, zi, frontier, blocks, radius, size, nb, best, best_d2
                        )
    return best
