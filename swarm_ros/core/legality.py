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

import numpy as np

from swarm_ros.core.params import RunParams
from swarm_ros.core.rulesets import JOIN_VALUES

#: Longest move of a tick, in patches, by ``steps`` value.
MAX_STEP = {"one": 1.0, "literal": 3.0}
_SLACK = 1e-9  # rounding in the robots' own arithmetic


def max_step(params: RunParams) -> float:
    return MAX_STEP[params.ruleset.steps]


def reach(params: RunParams, dims: int = 2) -> float:
    """How far (patch centres, in patches) from where a robot stood it may claim a patch."""
    joining = 1.0 if params.ruleset.join == JOIN_VALUES[0] else float(params.vision_radius)
    diagonal = math.sqrt(float(dims))
    return max_step(params) + max(joining, diagonal) + diagonal / 2


def illegal(params: RunParams, radius: int, frontier: np.ndarray, x0: np.ndarray, y0: np.ndarray,
            claim: np.ndarray, x: np.ndarray, y: np.ndarray, heading: np.ndarray, z0: np.ndarray | None = None,
            z: np.ndarray | None = None, pitch: np.ndarray | None = None) -> np.ndarray:
    """A bool mask of the decisions the rules could not have produced.

    Args:
        params: the run's parameters (rule set, vision radius).
        radius: the world's radius R (patch coordinates run from -R to R).
        frontier: the flat frontier grid at the start of the tick (W*W bools).
        x0, y0: where each deciding robot stood at the start of the tick (patches).
        claim, x, y, heading: the decisions, aligned with ``x0``/``y0``.
        z0, z, pitch: in a 3D world (all three given), the z before, and the decided z and elevation.
    """
    size = 2 * radius + 1
    limit = radius + 0.5
    step = max_step(params) + _SLACK
    solid = z0 is not None
    before = [x0, y0, z0] if solid else [x0, y0]
    after = [x, y, z] if solid else [x, y]
    bad = ~(np.isfinite(x) & np.isfinite(y) & (heading >= 0) & (heading <= 2 * math.pi))
    if solid:
        bad |= ~(np.isfinite(z) & (np.abs(np.nan_to_num(pitch, nan=np.inf)) <= math.pi / 2))
    for a in after:
        bad |= np.abs(np.nan_to_num(a, nan=np.inf)) > limit
    with np.errstate(invalid="ignore", over="ignore"):
        bad |= ~(np.sqrt(sum((a - b) ** 2 for a, b in zip(after, before))) <= step)
    claims = claim >= 0
    bad |= (claim < -1) | (claim >= size ** len(before))
    ok_claim = claims & ~bad
    p = claim[ok_claim]
    cells = [p % size - radius, (p // size) % size - radius, p // (size * size) - radius] if solid else \
        [p % size - radius, p // size - radius]
    far = np.sqrt(sum((c - b[ok_claim]) ** 2 for c, b in zip(cells, before))) > reach(params, len(before)) + _SLACK
    bad[np.flatnonzero(ok_claim)[far | ~frontier[p]]] = True
    return bad

