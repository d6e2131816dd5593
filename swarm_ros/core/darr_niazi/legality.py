"""Which decisions the rules could have produced: the world's check of what batches send it.

A robot's decision is a function of the swarm's state at the start of the tick, so the
world could recompute it; that would make the robot batches pointless. It checks bounds
instead, which every decision the rules make keeps and a wrong one (a bug, a stale or a
hostile message) usually breaks:

- the pose it takes if it does not join is finite, inside the world, with a heading in
  [0, 2 pi], and at most the rule set's longest move away from where it stood (one patch a
  tick under ``steps: one``, three under ``literal``);
- a claim names a frontier patch (empty, on the shape, next to a localized robot) that the
  robot could reach: within its longest move plus its joining distance (one patch under
  ``join: walk``, the vision radius under ``local``), plus half a patch's diagonal.

In a 3D world the same bounds hold in 3D (a voxel's diagonal is sqrt 3), and the
heading's elevation must be in [-pi/2, pi/2].

A decision inside these bounds but other than the one the rules would make is accepted:
docs/security.md says what that means.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from swarm_ros.core.darr_niazi.rulesets import JOIN_VALUES
from swarm_ros.core.params import RunParams

#: Longest move of a tick, in patches, by ``steps`` value.
MAX_STEP = {"one": 1.0, "literal": 3.0}
SLACK = 1e-9  # rounding in the robots' own arithmetic


def max_step(params: RunParams) -> float:
    return MAX_STEP[params.ruleset.steps]


#: Patches a robot's decision can reach beyond its vision radius: three moves of one patch (the ``literal``
#: steps outside the shape), the point one patch ahead that the crowding test is centred on, and a patch
#: of margin for rounding positions to patches.
REACH = 5


def halo(vision_radius: float) -> int:
    """Columns on each side of a strip whose robots a batch must see to decide for the strip's robots."""
    return int(math.ceil(vision_radius)) + REACH


def reach(params: RunParams, dims: int = 2) -> float:
    """How far (patch centres, in patches) from where a robot stood it may claim a patch."""
    joining = 1.0 if params.ruleset.join == JOIN_VALUES[0] else float(params.vision_radius)
    diagonal = math.sqrt(float(dims))
    return max_step(params) + max(joining, diagonal) + diagonal / 2


@numba.njit(cache=True)
def _illegal(radius, frontier, x0, y0, z0, claim, x, y, z, heading, pitch, step, reach_, solid, bad):
    """:func:`illegal`'s loop, compiled: one pass over the decisions, no temporary arrays."""
    size = 2 * radius + 1
    limit = radius + 0.5
    cells = size * size * size if solid else size * size
    for k in range(x.size):
        h = heading[k]
        wrong = not (math.isfinite(x[k]) and math.isfinite(y[k]) and 0.0 <= h <= 2.0 * math.pi)
        if solid:
            wrong = wrong or not (math.isfinite(z[k]) and abs(pitch[k]) <= math.pi / 2)
        wrong = wrong or abs(x[k]) > limit or abs(y[k]) > limit or (solid and abs(z[k]) > limit)
        d2 = (x[k] - x0[k]) ** 2 + (y[k] - y0[k]) ** 2
        if solid:
            d2 += (z[k] - z0[k]) ** 2
        wrong = wrong or not math.sqrt(d2) <= step
        c = claim[k]
        wrong = wrong or c < -1 or c >= cells
        if c >= 0 and not wrong:
            e2 = (c % size - radius - x0[k]) ** 2 + ((c // size) % size - radius - y0[k]) ** 2
            if solid:
                e2 += (c // (size * size) - radius - z0[k]) ** 2
            wrong = math.sqrt(e2) > reach_ or not frontier[c]
        bad[k] = wrong


def illegal(
    params: RunParams,
    radius: int,
    frontier: np.ndarray,
    x0: np.ndarray,
    y0: np.ndarray,
    claim: np.ndarray,
    x: np.ndarray,
    y: np.ndarray,
    heading: np.ndarray,
    z0: np.ndarray | None = None,
    z: np.ndarray | None = None,
    pitch: np.ndarray | None = None,
) -> np.ndarray:
    """A bool mask of the decisions the rules could not have produced.

    Args:
        params: the run's parameters (rule set, vision radius).
        radius: the world's radius R (patch coordinates run from -R to R).
        frontier: the flat frontier grid at the start of the tick (W*W bools).
        x0, y0: where each deciding robot stood at the start of the tick (patches).
        claim, x, y, heading: the decisions, aligned with ``x0``/``y0``.
        z0, z, pitch: in a 3D world (all three given), the z before, and the decided z and elevation.
    """
    solid = z0 is not None
    f64 = lambda a: np.ascontiguousarray(a, dtype=np.float64)
    none = np.empty(0)
    bad = np.empty(len(x), dtype=np.bool_)
    _illegal(
        radius,
        frontier,
        f64(x0),
        f64(y0),
        f64(z0) if solid else none,
        np.ascontiguousarray(claim, np.int64),
        f64(x),
        f64(y),
        f64(z) if solid else none,
        f64(heading),
        f64(pitch) if solid else none,
        max_step(params) + SLACK,
        reach(params, 3 if solid else 2) + SLACK,
        solid,
        bad,
    )
    return bad
