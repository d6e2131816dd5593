"""What world shards send each other after applying a tick (:class:`Part`), and the checks a shard makes of its
peers' claims before its lottery (:func:`check_claims`) and of their parts before it takes any
(:func:`check_parts`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

import numpy as np

from swarm_ros.core.errors import Rejected
from swarm_ros.core.regions import columns
from swarm_ros.core.state import IS_MOVING, RobotState, has_repeats
from swarm_ros.core.swarm_view import UNKNOWN

if TYPE_CHECKING:
    from swarm_ros.core.params import RunParams
    from swarm_ros.core.rules import Decisions
    from swarm_ros.core.shapes import Shape
    from swarm_ros.core.state import SwarmState


class ShardView(Protocol):
    """What :func:`check_parts` reads of the shard that checks (a :class:`~swarm_ros.core.shards.WorldShard`)."""

    @property
    def index(self) -> int: ...

    @property
    def shape(self) -> Shape: ...

    @property
    def params(self) -> RunParams: ...

    @property
    def plan(self) -> PlanView: ...

    @property
    def tick(self) -> int: ...

    @property
    def state(self) -> SwarmState: ...

    def own_moving(self) -> np.ndarray: ...


class PlanView(Protocol):
    """What :func:`check_parts` reads of the shards' plan (a :class:`~swarm_ros.core.shards.ShardPlan`)."""

    @property
    def radius(self) -> int: ...

    @property
    def width(self) -> int: ...

    @property
    def halo(self) -> int: ...

    @property
    def shards(self) -> int: ...

    @property
    def strips(self) -> list[tuple[int, int]]: ...


#: a part's counts: robots joined; moving inside, outside, walking after the tick; of them, failing at its end
COUNTS = (
    "joined",
    "inside",
    "outside",
    "walking",
    "failing_inside",
    "failing_outside",
    "failing_walking",
    "removing_localized",
    "removing_inside",
    "removing_outside",
    "removing_walking",
)
_PART_STATE = np.zeros(256, dtype=bool)  #: by a state code's byte: may a part hold it (moving, newly localized)
_PART_STATE[[RobotState.MOVING_INSIDE, RobotState.MOVING_OUTSIDE, RobotState.WALKING, RobotState.LOCALIZED]] = True


@dataclass
class Part:
    """What a shard sends the others after applying its robots' decisions of ``tick``: their rows (ids ascending;
    z and pitch empty in 2D), each one's column before the tick, and the counts (:data:`COUNTS`)."""

    tick: int
    source: int  #: the shard that sent it
    ids: np.ndarray
    state: np.ndarray
    x: np.ndarray
    y: np.ndarray
    heading: np.ndarray
    z: np.ndarray
    pitch: np.ndarray
    before: np.ndarray
    counts: np.ndarray
    removing: np.ndarray  #: int64: the sender's robots removed at the tick's end (a lost batch's), to every shard

    def take(self, index: np.ndarray) -> Part:
        """The rows at ``index`` (what one shard receives), with the part's counts."""
        z, pitch = (self.z[index], self.pitch[index]) if self.z.size else (self.z, self.pitch)
        return Part(
            tick=self.tick,
            source=self.source,
            ids=self.ids[index],
            state=self.state[index],
            x=self.x[index],
            y=self.y[index],
            heading=self.heading[index],
            z=z,
            pitch=pitch,
            before=self.before[index],
            counts=self.counts,
            removing=self.removing,
        )


#: a part's arrays and their types, in the order check() takes them
_PART_FIELDS = {
    "ids": np.int64,
    "state": np.int8,
    "x": np.float64,
    "y": np.float64,
    "heading": np.float64,
    "before": np.int64,
    "z": np.float64,
    "pitch": np.float64,
}
_PART_DTYPES = tuple(_PART_FIELDS.values())


def _concatenate(parts: list[Part]) -> Part:
    """The rows of ``parts`` in one (source -1; counts empty)."""
    rows = {
        f: np.concatenate([getattr(q, f) for q in parts]) if parts else np.empty(0, dtype=d)
        for f, d in _PART_FIELDS.items()
    }
    removing = np.concatenate([np.empty(0, np.int64), *(q.removing for q in parts)])
    return Part(tick=parts[0].tick if parts else -1, source=-1, counts=np.empty(0, np.int64), removing=removing, **rows)


#: what no peers send (a shard alone: the world): one part shared by every call, so read-only
_NO_PARTS = _concatenate([])
for _array in (*(getattr(_NO_PARTS, f) for f in _PART_FIELDS), _NO_PARTS.counts, _NO_PARTS.removing):
    _array.flags.writeable = False


def check_parts(shard: ShardView, received: list[Part], whole: bool = True) -> tuple[Part, np.ndarray]:
    """That ``received`` can be the other shards' parts of this tick, as far as this shard knows the swarm:
    one from each; each of its own robots (that stood in its strips, were moving if this shard followed
    them, and stood where it saw them), no robot in two; moves of at most a halo; joins on distinct frontier
    patches this shard's robots did not take, and counts that hold each part's joins. (The counts of a
    shard's moving robots only it knows: in the graph, the tag under the run's key vouches for them.)
    Returns their rows in one part (source -1) and their counts summed. One pass over all the rows,
    whatever the number of shards. ``whole=False``: parts of some of the peers only (to find which fails).

    Raises:
        Rejected: what failed (its ``kind``), with nothing taken.
    """
    tick, n, size, solid = shard.tick, shard.params.robots, shard.plan.width, shard.state.z is not None
    sources = sorted(q.source for q in received)
    peers = [j for j in range(shard.plan.shards) if j != shard.index]
    if sources != peers if whole else (len(set(sources)) < len(sources) or not set(sources) <= set(peers)):
        raise Rejected("parts of the wrong shards", f"shard {shard.index} needs one part from each other shard")
    for q in received:
        if q.tick != tick:
            raise Rejected("part of another tick", f"tick {q.tick} at tick {tick}")
        k = q.ids.size
        arrays = (q.ids, q.state, q.x, q.y, q.heading, q.before) + ((q.z, q.pitch) if solid else ())
        if any(a.shape != (k,) or a.dtype != d for a, d in zip(arrays, _PART_DTYPES)) or (
            not solid and (q.z.size or q.pitch.size)
        ):
            raise Rejected("malformed part", "arrays of other types or lengths")
        if q.counts.shape != (len(COUNTS),) or q.counts.dtype != np.int64:
            raise Rejected("malformed part", f"{q.counts.size} counts")
    if not received:  # a shard with no peers (the world alone)
        return _NO_PARTS, np.zeros(len(COUNTS), dtype=np.int64)
    counts = np.array([q.counts for q in received], dtype=np.int64).reshape(-1, len(COUNTS))
    if (
        (counts < 0).any()
        or (counts[:, 1:4].sum(axis=1) > n).any()
        or (counts[:, 4:7] > counts[:, 1:4]).any()
        or (counts[:, 8:11] > counts[:, 1:4]).any()
        or any(q.removing.size != c[7:].sum() for q, c in zip(received, counts))
    ):
        raise Rejected("impossible counts", str(counts.tolist()))
    rows = _concatenate(received)
    if rows.removing.size and (rows.removing.min() < 0 or rows.removing.max() >= n or has_repeats(rows.removing)):
        raise Rejected("bad robot ids", "robots removed out of range, or twice")
    if not rows.ids.size:
        if counts[:, 0].any():
            raise Rejected("impossible counts", "joins without their rows")
        return rows, counts.sum(axis=0)
    ids = rows.ids
    if ids.min() < 0 or ids.max() >= n or has_repeats(ids):
        raise Rejected("bad robot ids", f"out of 0..{n - 1}, or a robot in two rows")
    if not _PART_STATE[rows.state.view(np.uint8)].all():
        raise Rejected("bad robot state", "a part holds moving and newly localized robots only")
    poses = (rows.x, rows.y, rows.heading) + ((rows.z, rows.pitch) if solid else ())
    if not all(np.isfinite(a).all() for a in poses):
        raise Rejected("bad pose", "not finite")
    sizes = [q.ids.size for q in received]
    first = np.repeat([shard.plan.strips[q.source][0] for q in received], sizes)
    last = np.repeat([shard.plan.strips[q.source][1] for q in received], sizes)
    if ((rows.before < first) | (rows.before > last)).any():
        raise Rejected("not the sender's robots", "a robot that stood outside its strips")
    own = shard.own_moving()  # this tick's deciders, until close() takes the parts
    if own.size and (own[np.minimum(np.searchsorted(own, ids), own.size - 1)] == ids).any():
        raise Rejected("not the sender's robots", f"a robot shard {shard.index} decided for")
    s = shard.state
    was = s.state[ids]
    seen = was != UNKNOWN  # a robot of this shard's in another's part stood elsewhere than this shard saw it
    if (~IS_MOVING[was[seen]]).any():
        raise Rejected("a stationary robot moved")
    if (columns(s.x[ids[seen]], shard.plan.radius) != rows.before[seen]).any():
        raise Rejected("not where it stood", "a robot's column before the tick is not the one this shard saw")
    after = [columns(a, shard.plan.radius) for a in ((rows.x, rows.y, rows.z) if solid else (rows.x, rows.y))]
    if (
        any((a.min() < 0) | (a.max() >= size) for a in after)
        or (np.abs(after[0] - rows.before) > shard.plan.halo).any()
    ):
        raise Rejected("moved too far", "out of the world, or further than a halo in a tick")
    joined = rows.state == RobotState.LOCALIZED
    part_of = np.repeat(np.arange(len(received)), sizes)
    if not np.array_equal(np.bincount(part_of[joined], minlength=len(received)), counts[:, 0]):
        raise Rejected("impossible counts", "a part's joins are not its newly localized rows")
    cells = [a[joined] for a in after]
    p = cells[-1]
    for a in reversed(cells[:-1]):
        p = p * size + a
    if not (shard.shape.mask.ravel()[p] & (s.occupancy[p] < 0) & s.frontier[p]).all() or has_repeats(p):
        raise Rejected("bad join", "off the frontier, on a patch taken this tick, or two robots on one patch")
    return rows, counts.sum(axis=0)


_CLAIM_DTYPES = (np.int64, np.int64, np.float64, np.float64, np.float64)


def check_claims(shard: ShardView, source: int, claims: Decisions) -> None:
    """That ``claims`` can be shard ``source``'s claims on this shard's window for the tick it is about to
    apply, as far as this shard knows the swarm: robots of the sender's that claim (each once) patches of
    this shard's strips and halo, poses that are numbers, and, for a robot this shard follows, one that is
    moving and stands in the sender's strips. A forged rival could otherwise win a patch from this shard's
    robot.

    Raises:
        Rejected: what failed (its ``kind``), with nothing taken.
    """
    n, size, solid, tick = shard.params.robots, shard.plan.width, shard.state.z is not None, shard.tick + 1
    if claims.tick != tick:
        raise Rejected("claims of another tick", f"tick {claims.tick} at tick {tick}")
    k = claims.ids.size
    arrays = (claims.ids, claims.claim, claims.x, claims.y, claims.heading)
    extra = (claims.z, claims.pitch)
    if (
        any(a.shape != (k,) or a.dtype != d for a, d in zip(arrays, _CLAIM_DTYPES))
        or (solid and any(a is None or a.shape != (k,) or a.dtype != np.float64 for a in extra))
        or (not solid and any(a is not None for a in extra))
    ):
        raise Rejected("malformed claims", "arrays of other types or lengths")
    if not k:
        return
    ids = claims.ids
    if ids.min() < 0 or ids.max() >= n or has_repeats(ids):
        raise Rejected("bad robot ids", f"out of 0..{n - 1}, or a robot twice")
    poses = arrays[2:] + (tuple(a for a in extra if a is not None) if solid else ())
    if not all(np.isfinite(a).all() for a in poses):
        raise Rejected("bad pose", "not finite")
    first, last = shard.plan.strips[shard.index]
    h, cols = shard.plan.halo, claims.claim % size
    if (
        claims.claim.min() < 0
        or claims.claim.max() >= shard.shape.world.patch_count
        or ((cols < first - h) | (cols > last + h)).any()
    ):
        raise Rejected("bad claim", "a patch outside this shard's strips and halo")
    own = shard.own_moving()
    if own.size and (own[np.minimum(np.searchsorted(own, ids), own.size - 1)] == ids).any():
        raise Rejected("not the sender's robots", f"a robot shard {shard.index} decides for")
    s = shard.state
    was = s.state[ids]
    seen = was != UNKNOWN
    where = columns(s.x[ids[seen]], shard.plan.radius)
    a, b = shard.plan.strips[source]
    if (~IS_MOVING[was[seen]]).any() or ((where < a) | (where > b)).any():
        raise Rejected("not the sender's robots", "a robot not moving, or not in its strips")
