"""The world's half of a tick, split by region: world shards that each own a group of strips.

The distributed engine's world checks every decision and applies every tick for the whole swarm, so its
work per tick grows with the swarm, whatever the number of robot batches. A :class:`WorldShard` does that
work for the robots of its own strips only (:class:`ShardPlan`: contiguous columns, like a batch's strip),
on a regional :class:`~swarm_ros.core.replica.Replica` of its area (its strips and a halo each side, every
stationary robot). A tick goes in two exchanges between shards, each message bounded by what lies near a
shard's borders:

1. **Claims.** Each shard sends each other shard the decisions of its robots that claim a patch within that
   shard's claim window (its strips and a halo each side): the lottery is per patch, and a rival claimant of
   a patch a shard's robot claims always stands within the halo (``test/test_partition.py``).
2. **Apply.** Each shard applies its own robots' decisions with the in-process engine's kernel
   (:func:`~swarm_ros.core.arbitration.resolve_kernel`), its neighbours' claims taking part in the lottery
   only. It sends each shard the rows its area needs (a moving robot whose column before or after the tick
   is in that area; every robot that became stationary, to all) and its :class:`Part`'s counts.
3. **Close.** Every shard sums the counts of all parts (a handful of integers per shard) and ends the tick
   alone, all alike: the metrics row, the end of the run, the separation of the robots left over (each
   shard separates the moving robots it knows: every moving robot is known to its owner), and the scheduled
   failures (each shard removes the failing robots it knows; the counts of the failing moving robots came
   with the parts).

Nothing here depends on how many shards there are or where the cuts fall:
:func:`~swarm_ros.core.sharded_run.run_sharded` runs S shards in one process, passing only these messages, and
gives ``Simulation``'s run byte for byte
(``test/test_shards.py``). The ROS 2 graph's world does not use the shards yet: the split is built and
checked here first (docs/operations.md, "At scale").
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from swarm_ros.core.arbitration import resolve_kernel
from swarm_ros.core.engine import failing_robots
from swarm_ros.core.errors import ContractError, Rejected
from swarm_ros.core.kernel_state import Moves, grid_of, robots_of, rules_of
from swarm_ros.core.metrics import END_EXTRAS, OUTCOME_OF_CODE, RUNNING, Outcome, end_code, metric_values
from swarm_ros.core.params import RunParams
from swarm_ros.core.regions import area, columns, halo, strip
from swarm_ros.core.replica import UNKNOWN, Replica
from swarm_ros.core.rules import Decisions
from swarm_ros.core.shapes import Shape
from swarm_ros.core.state import IS_MOVING, RobotState, SwarmState, has_repeats, initial_state

_EMPTY = np.empty(0)
_INSIDE, _OUTSIDE, _WALKING = int(RobotState.MOVING_INSIDE), int(RobotState.MOVING_OUTSIDE), int(RobotState.WALKING)
_PART_STATE = np.zeros(256, dtype=bool)  #: by a state code's byte: may a part hold it (moving, newly localized)
_PART_STATE[[_INSIDE, _OUTSIDE, _WALKING, RobotState.LOCALIZED]] = True
#: a part's counts: robots joined; moving inside, outside, walking after the tick; of them, failing at its end
COUNTS = ("joined", "inside", "outside", "walking", "failing_inside", "failing_outside", "failing_walking")


class ShardPlan:
    """S shards' strips of whole columns (cut at ``cuts``, x positions, as ``region_cuts``) and their areas."""

    def __init__(self, radius: int, vision_radius: float, cuts: np.ndarray) -> None:
        cuts = np.asarray(cuts, dtype=np.int64)
        self.radius, self.width, self.halo = radius, 2 * radius + 1, halo(vision_radius)
        self.shards = int(cuts.size) + 1
        self.strips = [strip(k, self.shards, cuts, radius) for k in range(self.shards)]
        self.areas = [area(s, self.halo, self.width) for s in self.strips]
        self.owner = np.empty(self.width, dtype=np.int64)  # the shard owning each column
        for k, (first, last) in enumerate(self.strips):
            self.owner[first : last + 1] = k

    def routes(self, before: np.ndarray, after: np.ndarray, stationary: np.ndarray, source: int) -> list[np.ndarray]:
        """Of rows whose robots stood in columns ``before`` and stand in ``after`` (``stationary``: became
        stationary), the indices each shard but ``source`` receives: those its area follows, and every
        stationary one."""
        low, high = np.minimum(before, after), np.maximum(before, after)
        return [
            np.empty(0, dtype=np.int64) if j == source else np.flatnonzero(stationary | ((high >= a) & (low <= b)))
            for j, (a, b) in enumerate(self.areas)
        ]


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
    return Part(tick=parts[0].tick if parts else -1, source=-1, counts=np.empty(0, np.int64), **rows)


def _select(d: Decisions, index: np.ndarray) -> Decisions:
    solid = {"z": d.z[index], "pitch": d.pitch[index]} if d.z is not None and d.pitch is not None else {}
    return Decisions(d.tick, d.ids[index], d.claim[index], d.x[index], d.y[index], d.heading[index], **solid)


class WorldShard:
    """Shard ``index`` of ``plan``: the world's checks of its own robots and its part of every tick.

    Attributes:
        replica: its area's state (every stationary robot, the moving robots of its area).
        history: the metrics of every tick so far (every shard holds the same).
        outcome: how the run ended, or None.
    """

    def __init__(self, shape: Shape, params: RunParams, plan: ShardPlan, index: int) -> None:
        self.shape, self.params, self.plan, self.index = shape, params, plan, index
        self.strip = plan.strips[index]
        self.replica = Replica(shape, params.robots, area=plan.areas[index])
        s0 = initial_state(shape, params.robots, params.seed)
        ids = np.arange(params.robots)
        self.replica.load(0, ids, s0.state, s0.x, s0.y, s0.heading, s0.z, s0.pitch)
        world = shape.world
        self._solid = world.dims == 3
        self._mask, self._wall, self._nbrs = (
            shape.mask.ravel().copy(),
            world.wall_mask().ravel(),
            world.neighbour_offsets(),
        )
        self._rules = rules_of(params)
        self._patches = shape.patches
        self._best = np.full(world.patch_count, -1, dtype=np.int64)
        counts = s0.counts()
        self.localized = int(counts[RobotState.SEED] + counts[RobotState.LOCALIZED])
        self.alive = params.robots
        self.losses: list[tuple[int, int]] = []
        self.history: list[tuple[int, ...]] = []
        self.outcome: Outcome | None = None
        self._own = self._mine(np.arange(params.robots))  # kept from the rows of each tick on: no scan of the swarm
        moving = counts[_INSIDE], counts[_OUTSIDE], counts[_WALKING]
        self._close(0, *(int(c) for c in moving))

    @property
    def tick(self) -> int:
        return self.replica.tick

    @property
    def state(self) -> SwarmState:
        return self.replica.state

    def own_moving(self) -> np.ndarray:
        """The moving robots standing in this shard's strips, ascending: the ones it applies the decisions of."""
        return self._own.copy()

    def _mine(self, ids: np.ndarray) -> np.ndarray:
        """Of ``ids`` (ascending), the moving robots this shard follows that stand in its strips."""
        s = self.state
        cols = columns(s.x[ids], self.plan.radius)
        st = s.state[ids]
        return ids[IS_MOVING[st] & (st != UNKNOWN) & (cols >= self.strip[0]) & (cols <= self.strip[1])]

    def claims(self, decisions: Decisions) -> list[Decisions]:
        """Exchange 1: per shard, the decisions of this shard's robots claiming a patch in its claim window
        (its strips and the halo); none for this shard."""
        size, h = self.plan.width, self.plan.halo
        cols = decisions.claim % size
        claiming = decisions.claim >= 0
        return [
            _select(decisions, np.flatnonzero(claiming & (cols >= a - h) & (cols <= b + h)))
            if j != self.index
            else _select(decisions, np.empty(0, dtype=np.int64))
            for j, (a, b) in enumerate(self.plan.strips)
        ]

    def apply(self, decisions: Decisions, rivals: list[Decisions]) -> Part:
        """Exchange 2: apply this shard's robots' ``decisions`` (one for each of :meth:`own_moving`), ``rivals``
        (the other shards' claims sent to this one) taking part in the lottery only.

        Raises:
            ContractError: the decisions are for another tick, or not exactly this shard's moving robots.
        """
        if self.outcome is not None:
            raise ContractError(f"the run has ended ({self.outcome}) at tick {self.tick}")
        if decisions.tick != self.tick + 1:
            raise ContractError(f"decisions are for tick {decisions.tick}, the shard is at tick {self.tick}")
        if decisions.ids.size > 1 and not (decisions.ids[1:] > decisions.ids[:-1]).all():
            decisions = _select(decisions, np.argsort(decisions.ids, kind="stable"))
        own = self._own
        if not np.array_equal(decisions.ids, own):
            raise ContractError(f"shard {self.index}: decisions must cover its moving robots exactly once")
        wanted = decisions.claim[decisions.claim >= 0]
        parts = [decisions] + [_select(r, np.flatnonzero(np.isin(r.claim, wanted))) for r in rivals if r.ids.size]
        every = Decisions.concatenate(parts) if len(parts) > 1 else decisions
        n = own.size
        s = self.state
        before = columns(s.x[own], self.plan.radius)
        z, pitch = (every.z, every.pitch) if every.z is not None and every.pitch is not None else (_EMPTY, _EMPTY)
        moves = Moves(every.claim.astype(np.int64), every.x, every.y, z, every.heading, pitch)
        grid = grid_of(self.shape, s, self._mask, self._wall, self._nbrs)
        joined, inside, outside, walking = resolve_kernel(
            every.ids,
            moves,
            robots_of(s),
            grid,
            self._rules,
            decisions.tick,
            self._best,
            self.localized,
            self._patches,
            np.empty(every.ids.size, dtype=np.int8),
            n,
        )
        s.tick = decisions.tick
        counts = np.zeros(len(COUNTS), dtype=np.int64)
        counts[:4] = joined, inside, outside, walking
        p = self.params
        if p.failures > 0 and decisions.tick == p.fail_tick:
            failing = np.intersect1d(failing_robots(p), own, assume_unique=True)
            states = np.bincount(s.state[failing], minlength=8)
            counts[4:] = states[_INSIDE], states[_OUTSIDE], states[_WALKING]
        z, pitch = (s.z[own], s.pitch[own]) if s.z is not None and s.pitch is not None else (_EMPTY, _EMPTY)
        return Part(
            tick=decisions.tick,
            source=self.index,
            ids=own,
            state=s.state[own],
            x=s.x[own],
            y=s.y[own],
            heading=s.heading[own],
            z=z,
            pitch=pitch,
            before=before,
            counts=counts,
        )

    def routes(self, part: Part) -> list[Part]:
        """What of this shard's ``part`` each shard receives (nothing for this one)."""
        after = columns(part.x, self.plan.radius)
        stationary = ~IS_MOVING[part.state]
        return [part.take(i) for i in self.plan.routes(part.before, after, stationary, self.index)]

    def close(self, own: Part, received: list[Part]) -> None:
        """Exchange 2's end: take the other shards' rows (``received``: one part from each other shard, as routed
        to this one) and end the tick from the counts of every part (``own``: this shard's), as every other
        shard does. The parts are checked (:meth:`check`) before any is taken.

        Raises:
            Rejected: a part fails its check; nothing was taken.
        """
        tick = self.tick
        rows, counts = self.check(received)
        if rows.ids.size:
            solid = (rows.z, rows.pitch) if self._solid else (None, None)
            self.replica.merge(rows.ids, rows.state, rows.x, rows.y, rows.heading, *solid)
        kept, come = self._mine(own.ids), self._mine(np.sort(rows.ids))  # disjoint, each ascending
        self._own = np.insert(kept, np.searchsorted(kept, come), come) if come.size else kept
        total = own.counts + counts
        self.localized += int(total[0])
        inside, outside, walking = (int(c) for c in total[1:4])
        code = self._close(tick, inside, outside, walking)
        p = self.params
        if code == RUNNING and p.failures > 0 and tick == p.fail_tick:
            self.history.pop()  # the tick's metrics are redone after the failures, as Simulation.remove does
            self._fail(failing_robots(p))
            self._close(tick, inside - int(total[4]), outside - int(total[5]), walking - int(total[6]))
        self._own = self._mine(self._own)  # less the failed and the separated

    def check(self, received: list[Part]) -> tuple[Part, np.ndarray]:
        """That ``received`` can be the other shards' parts of this tick, as far as this shard knows the swarm:
        one from each; each of its own robots (that stood in its strips, were moving if this shard followed
        them, and stood where it saw them), no robot in two; moves of at most a halo; joins on distinct frontier
        patches this shard's robots did not take, and counts that hold each part's joins. (The counts of a
        shard's moving robots only it knows: in the graph, the tag under the run's key vouches for them.)
        Returns their rows in one part (source -1) and their counts summed. One pass over all the rows,
        whatever the number of shards.

        Raises:
            Rejected: what failed (its ``kind``), with nothing taken.
        """
        tick, n, size, solid = self.tick, self.params.robots, self.plan.width, self._solid
        if sorted(q.source for q in received) != [j for j in range(self.plan.shards) if j != self.index]:
            raise Rejected("parts of the wrong shards", f"shard {self.index} needs one part from each other shard")
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
        counts = np.array([q.counts for q in received], dtype=np.int64).reshape(-1, len(COUNTS))
        if (counts < 0).any() or (counts[:, 1:4].sum(axis=1) > n).any() or (counts[:, 4:] > counts[:, 1:4]).any():
            raise Rejected("impossible counts", str(counts.tolist()))
        rows = _concatenate(received)
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
        first = np.repeat([self.plan.strips[q.source][0] for q in received], sizes)
        last = np.repeat([self.plan.strips[q.source][1] for q in received], sizes)
        if ((rows.before < first) | (rows.before > last)).any():
            raise Rejected("not the sender's robots", "a robot that stood outside its strips")
        s = self.state
        was = s.state[ids]
        seen = was != UNKNOWN  # a robot of this shard's in another's part stood elsewhere than this shard saw it
        if (~IS_MOVING[was[seen]]).any():
            raise Rejected("a stationary robot moved")
        if (columns(s.x[ids[seen]], self.plan.radius) != rows.before[seen]).any():
            raise Rejected("not where it stood", "a robot's column before the tick is not the one this shard saw")
        after = [columns(a, self.plan.radius) for a in ((rows.x, rows.y, rows.z) if solid else (rows.x, rows.y))]
        if (
            any((a.min() < 0) | (a.max() >= size) for a in after)
            or (np.abs(after[0] - rows.before) > self.plan.halo).any()
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
        if not (self._mask[p] & (s.occupancy[p] < 0) & s.frontier[p]).all() or has_repeats(p):
            raise Rejected("bad join", "off the frontier, on a patch taken this tick, or two robots on one patch")
        return rows, counts.sum(axis=0)

    def _fail(self, failing: np.ndarray) -> None:
        """Scheduled failures: remove the failing robots this shard knows, and count them all."""
        s = self.state
        known = s.state[failing]
        gone = failing[known != RobotState.REMOVED]
        self.localized -= int(((known == RobotState.SEED) | (known == RobotState.LOCALIZED)).sum())
        self.alive -= int(gone.size)
        if gone.size:
            self.losses.append((self.tick, int(gone.size)))
        here = gone[s.state[gone] != UNKNOWN]
        solid = (s.z[here], s.pitch[here]) if s.z is not None and s.pitch is not None else (None, None)
        removed = np.full(here.size, RobotState.REMOVED, dtype=np.int8)
        self.replica.merge(here, removed, s.x[here], s.y[here], s.heading[here], *solid)

    def _close(self, tick: int, inside: int, outside: int, walking: int) -> int:
        moving = inside + outside + walking
        code = end_code(self.localized, moving, tick, self._patches, self.alive, self.params.max_ticks)
        separated = 0
        if code == END_EXTRAS:
            s = self.state
            known = IS_MOVING[s.state] & (s.state != UNKNOWN)
            s.state[known] = RobotState.SEPARATED
            separated, inside, outside, walking = moving, 0, 0, 0
        self.history.append(metric_values(tick, self.localized, inside, outside, walking, separated, self._patches))
        self.outcome = OUTCOME_OF_CODE[code]
        return code
