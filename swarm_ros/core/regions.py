"""Regions of the world for the distributed engine: which batch decides which robot, and what it must see.

The world is cut into K strips of whole patch columns along x, one per robot batch. A
batch decides, each tick, for the moving robots that stand in its strip (the column of
a robot is that of the patch nearest to it), so a robot changes batch when its move
takes it across a cut: the handover is the world's row of that robot, which every batch
that needs it receives. Since a decision is a pure function of the state, the seed,
the robot and the tick, who decides a robot never changes what it decides: any
partition gives the in-process engine's result.

A batch sees its strip and a halo of :func:`halo` columns on each side: everything a
rule reads about other robots (the crowding test around the point ahead, after up to
three steps of the ``literal`` moves) lies within it. The frontier, which the ``walk``
rule searches anywhere, is rebuilt from the localizations, which every batch receives.
"""

from __future__ import annotations

import math

import numpy as np

from swarm_ros.core.errors import ParameterError

#: Patches a robot's decision can reach beyond its vision radius: three moves of one patch (the ``literal``
#: steps outside the shape), the point one patch ahead that the crowding test is centred on, and a patch
#: of margin for rounding positions to patches.
REACH = 5


def halo(vision_radius: float) -> int:
    """Columns on each side of a strip whose robots a batch must see to decide for the strip's robots."""
    return int(math.ceil(vision_radius)) + REACH


def columns(x: np.ndarray, radius: int) -> np.ndarray:
    """The column (0 .. 2R) of the patch nearest to each x: the unit regions are made of."""
    return np.floor(np.asarray(x, dtype=np.float64) + 0.5).astype(np.int64) + radius


def parse_cuts(text: str) -> np.ndarray:
    """Cut positions from a list like ``"-20,0,20"`` (x in patches, ascending): empty for none.

    Raises:
        ParameterError: not a list of integers, or not strictly ascending.
    """
    compact = text.replace(" ", "")
    parts = compact.split(",") if compact else []
    if "" in parts:  # '-10,,10' or '10,': a position left out is a typo, not a cut fewer
        raise ParameterError(f"region_cuts must be whole x positions like '-20,0,20', got {text!r} (an empty one)")
    try:
        cuts = np.array([int(p) for p in parts], dtype=np.int64)
    except ValueError:
        raise ParameterError(f"region_cuts must be whole x positions like '-20,0,20', got {text!r}") from None
    if cuts.size > 1 and (np.diff(cuts) <= 0).any():
        raise ParameterError(f"region_cuts must be strictly ascending, got {text!r}")
    return cuts


def balanced_cuts(x: np.ndarray, radius: int, batches: int) -> np.ndarray:
    """Cuts (x positions) that give ``batches`` strips about equal numbers of the robots at ``x``.

    A strip holds at least one column; robots of one column stay in one strip.
    """
    cols = np.sort(columns(x, radius))
    width = 2 * radius + 1
    cuts = []
    lowest = 1  # the first column the next cut may be at
    for k in range(1, batches):
        c = int(cols[min(cols.size - 1, (k * cols.size) // batches)]) if cols.size else (k * width) // batches
        c = min(max(c, lowest), width - (batches - k))  # leave a column for each strip after this one
        cuts.append(c)
        lowest = c + 1
    return np.asarray(cuts, dtype=np.int64) - radius


def strip(batch: int, batches: int, cuts: np.ndarray, radius: int) -> tuple[int, int]:
    """(first, last) column, inclusive, of batch ``batch`` of ``batches`` given the K - 1 ``cuts``.

    Strip k runs from cut k - 1 (or the west wall) up to the column before cut k (or the east wall).

    Raises:
        ParameterError: the cuts are not K - 1, or leave a strip without a column inside the world.
    """
    if batches < 1 or not 0 <= batch < batches:
        raise ParameterError(f"batch must be in [0, {batches}), got {batch}")
    if cuts.size != batches - 1:
        raise ParameterError(f"region_cuts gives {cuts.size} cuts; {batches} batches need {batches - 1}")
    width = 2 * radius + 1
    edges = np.concatenate([[0], cuts + radius, [width]])
    if (np.diff(edges) < 1).any():
        raise ParameterError(f"region_cuts {cuts.tolist()} leave a strip with no column in [-{radius}, {radius}]")
    return int(edges[batch]), int(edges[batch + 1]) - 1


def batch_cuts(shape, params, batches: int, region_cuts: str = "") -> np.ndarray:
    """The K - 1 cuts of a run's ``batches`` strips: ``region_cuts``, or (empty) where each strip starts with as
    many robots; their places at tick 0 follow from the seed, so every process finds the same cuts alone.

    Raises:
        ParameterError: as :func:`parse_cuts`.
    """
    from swarm_ros.core.state import initial_state  # here: it loads numba, which the launcher's checks do without

    if region_cuts:
        return parse_cuts(region_cuts)
    return balanced_cuts(initial_state(shape, params.robots, params.seed).x[4:], shape.world.radius, batches)


def batch_strip(shape, params, batch: int, batches: int, region_cuts: str = "") -> tuple[int, int]:
    """The strip batch ``batch`` of ``batches`` hosts in a run of ``shape`` and ``params`` (:func:`batch_cuts`).

    Raises:
        ParameterError: as :func:`parse_cuts` and :func:`strip`.
    """
    return strip(batch, batches, batch_cuts(shape, params, batches, region_cuts), shape.world.radius)


def shard_batches(shard: int, shards: int, batches: int) -> range:
    """The batches world shard ``shard`` of ``shards`` admits: a run of consecutive strips, as many as can be.

    Raises:
        ParameterError: more shards than batches, or ``shard`` not one of them.
    """
    if not 1 <= shards <= batches:
        raise ParameterError(f"world_shards must be in [1, {batches}] (one batch at least each), got {shards}")
    if not 0 <= shard < shards:
        raise ParameterError(f"shard must be in [0, {shards}), got {shard}")
    return range(shard * batches // shards, (shard + 1) * batches // shards)


def area(strip: tuple[int, int], halo_columns: int, width: int) -> tuple[int, int]:
    """(first, last) column a batch with ``strip`` follows: the strip and ``halo_columns`` each side, in the world."""
    return max(strip[0] - halo_columns, 0), min(strip[1] + halo_columns, width - 1)
