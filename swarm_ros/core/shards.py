"""The world's half of a tick, split by region: world shards that each own a group of strips.

The distributed engine's world checks every decision and applies every tick for the whole swarm, so its
work per tick grows with the swarm, whatever the number of robot batches. A :class:`WorldShard` does that
work for the robots of its own strips only (:class:`ShardPlan`: contiguous columns, like a batch's strip),
on a regional :class:`~swarm_ros.core.swarm_view.SwarmView` of its area (its strips and a halo each side, every
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

A shard takes its peers' parts only once all pass its checks (:func:`~swarm_ros.core.shard_parts.check_parts`),
and can be saved at a tick's end and restored in another process (:meth:`WorldShard.saved`,
:meth:`WorldShard.restore`). Nothing here depends on how many shards there are or where the cuts fall:
:func:`~swarm_ros.core.sharded_run.run_sharded` runs S shards in one process, passing only these messages, and
gives ``Simulation``'s run byte for byte (``test/test_shards.py``); in the ROS 2 graph, ``--world-shards S``
runs each shard in a node of its own (``swarm_ros.nodes.world_shard``; docs/protocol.md, "World shards").
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from swarm_ros.core.arbitration import resolve_kernel
from swarm_ros.core.engine import failing_robots
from swarm_ros.core.errors import ContractError
from swarm_ros.core.kernel_state import Moves, grid_of, robots_of, rules_of
from swarm_ros.core.legality import reach
from swarm_ros.core.metrics import END_EXTRAS, METRIC_COLUMNS, OUTCOME_OF_CODE, Outcome, end_code
from swarm_ros.core.params import RunParams
from swarm_ros.core.regions import area, batch_cuts, columns, halo, shard_batches, shard_cuts, strip
from swarm_ros.core.rules import Decisions
from swarm_ros.core.shapes import Shape
from swarm_ros.core.shard_parts import COUNTS, Part, check_claims, check_parts
from swarm_ros.core.state import IS_MOVING, RobotState, SwarmState, initial_state
from swarm_ros.core.swarm_view import UNKNOWN, SwarmView
from swarm_ros.core.tick_kernel import end_tick

_EMPTY = np.empty(0)
_NONE = np.empty(0, dtype=np.int64)
_INSIDE, _OUTSIDE, _WALKING = int(RobotState.MOVING_INSIDE), int(RobotState.MOVING_OUTSIDE), int(RobotState.WALKING)


class ShardPlan:
    """S shards' strips of whole columns (cut at ``cuts``, x positions, as ``region_cuts``) and their areas."""

    def __init__(self, radius: int, vision_radius: float, cuts: np.ndarray) -> None:
        cuts = np.asarray(cuts, dtype=np.int64)
        self.radius, self.width, self.halo = radius, 2 * radius + 1, halo(vision_radius)
        self.shards = int(cuts.size) + 1
        self.strips = [strip(k, self.shards, cuts, radius) for k in range(self.shards)]
        self.areas = [area(s, self.halo, self.width) for s in self.strips]

    def reaches(self, i: int, j: int, claim_reach: float) -> bool:
        """Whether a robot of shard ``i`` (standing in its strips) can claim a patch in shard ``j``'s claim window
        (its strips and the halo), a claim being at most ``claim_reach`` patches from where the robot stands:
        the shards beyond it are sent no claims, and wait for none."""
        (a, b), (c, d), r = self.strips[i], self.strips[j], math.ceil(claim_reach) + 1  # + 1: a column's rounding
        return i != j and a - r <= d + self.halo and c - self.halo <= b + r

    @classmethod
    def placed(cls, shape: Shape, params: RunParams, shard: int, shards: int, batches: int, cuts: str) -> ShardPlan:
        """The plan of a world process: shard ``shard`` of ``shards``, each owning the strips of consecutive robot
        batches of ``batches`` cut at ``cuts`` (``region_cuts``); one shard (the world alone): the whole world.

        Raises:
            ParameterError: more shards than batches, a shard index beyond them, or cuts that are no cut.
        """
        radius, vision = shape.world.radius, params.vision_radius
        if shards == 1:
            return cls(radius, vision, np.empty(0, dtype=np.int64))
        shard_batches(shard, shards, batches)  # checks S <= K and the index
        return cls(radius, vision, shard_cuts(batch_cuts(shape, params, batches, cuts), shards, batches))

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
class ShardSaved:
    """A shard at the end of ``tick`` (:meth:`WorldShard.saved`): the rows it knows (z, pitch: None in 2D), the
    metrics of every tick, the losses, and the counts it keeps."""

    tick: int
    ids: np.ndarray
    state: np.ndarray
    x: np.ndarray
    y: np.ndarray
    heading: np.ndarray
    z: np.ndarray | None
    pitch: np.ndarray | None
    history: np.ndarray
    losses: list[tuple[int, int]]
    localized: int
    alive: int
    removed: np.ndarray  #: every robot removed so far (a shard does not follow every one)


def _select(d: Decisions, index: np.ndarray) -> Decisions:
    solid = {"z": d.z[index], "pitch": d.pitch[index]} if d.z is not None and d.pitch is not None else {}
    return Decisions(d.tick, d.ids[index], d.claim[index], d.x[index], d.y[index], d.heading[index], **solid)


class WorldShard:
    """Shard ``index`` of ``plan``: the world's checks of its own robots and its part of every tick.

    Attributes:
        view: its area's state (every stationary robot, the moving robots of its area).
        history: the metrics of every tick so far (every shard holds the same).
        outcome: how the run ended, or None.
    """

    def __init__(self, shape: Shape, params: RunParams, plan: ShardPlan, index: int) -> None:
        self.shape, self.params, self.plan, self.index = shape, params, plan, index
        self.strip = plan.strips[index]
        others, claim_reach = range(plan.shards), reach(params, shape.world.dims)
        self.claims_to = [j for j in others if plan.reaches(index, j, claim_reach)]  #: the shards it may claim in
        self.claims_from = [i for i in others if plan.reaches(i, index, claim_reach)]  #: those that may claim in it
        self.view = SwarmView(shape, params.robots, area=plan.areas[index])
        s0 = initial_state(shape, params.robots, params.seed)
        ids = np.arange(params.robots)
        self.view.load(0, ids, s0.state, s0.x, s0.y, s0.heading, s0.z, s0.pitch)
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
        self._removed = np.zeros(params.robots, dtype=bool)  # every robot removed so far, known to every shard
        self.losses: list[tuple[int, int]] = []
        self.history: list[tuple[int, ...]] = []
        self.outcome: Outcome | None = None
        self.received: Part | None = None  # the peers' rows taken in the last tick closed, as one part
        self.gone_stationary = _NONE  # stationary robots removed in the last tick closed (failures), that it knew
        self._own = self._mine(np.arange(params.robots))  # kept from the rows of each tick on: no scan of the swarm
        moving = counts[_INSIDE], counts[_OUTSIDE], counts[_WALKING]
        self._close(0, *(int(c) for c in moving))

    @property
    def tick(self) -> int:
        return self.view.tick

    @property
    def state(self) -> SwarmState:
        return self.view.state

    @property
    def removed(self) -> np.ndarray:
        """Whether each robot was removed so far (read only)."""
        view = self._removed.view()
        view.flags.writeable = False
        return view

    def saved(self) -> ShardSaved:
        """What a restarted process of this shard needs to go on from the tick closed last (:meth:`restore`)."""
        s = self.state
        ids = np.flatnonzero(s.state != UNKNOWN)
        return ShardSaved(
            tick=self.tick,
            ids=ids,
            state=s.state[ids].copy(),
            x=s.x[ids].copy(),
            y=s.y[ids].copy(),
            heading=s.heading[ids].copy(),
            z=s.z[ids].copy() if s.z is not None else None,
            pitch=s.pitch[ids].copy() if s.pitch is not None else None,
            history=np.asarray(self.history, dtype=np.int64),
            losses=list(self.losses),
            localized=self.localized,
            alive=self.alive,
            removed=np.flatnonzero(self._removed),
        )

    def restore(self, saved: ShardSaved) -> None:
        """Go on from ``saved`` (:meth:`saved` of a process of this shard before this one): the view is rebuilt
        from its rows, as a robot batch's is from a snapshot.

        Raises:
            ContractError: rows that do not make a consistent swarm.
        """
        v = saved
        self.view.load(v.tick, v.ids, v.state, v.x, v.y, v.heading, v.z, v.pitch)
        self.history = [tuple(int(c) for c in row) for row in v.history]
        self.losses, self.localized, self.alive = list(v.losses), v.localized, v.alive
        self._removed[:] = False
        self._removed[v.removed] = True
        self._own = self._mine(np.flatnonzero(self.state.state != UNKNOWN))
        last = self.history[-1]
        code = end_code(self.localized, last[4], v.tick, self._patches, self.alive, self.params.max_ticks)
        self.outcome = OUTCOME_OF_CODE[code]

    @property
    def own_count(self) -> int:
        """How many moving robots stand in this shard's strips (:meth:`own_moving`, without the copy)."""
        return int(self._own.size)

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
        if self.plan.shards == 1:  # no peers: no claims
            return [_select(decisions, _NONE)]
        size, h = self.plan.width, self.plan.halo
        cols = decisions.claim % size
        claiming = decisions.claim >= 0
        claims = [
            _select(decisions, np.flatnonzero(claiming & (cols >= a - h) & (cols <= b + h)))
            if j != self.index
            else _select(decisions, np.empty(0, dtype=np.int64))
            for j, (a, b) in enumerate(self.plan.strips)
        ]
        beyond = [j for j, c in enumerate(claims) if c.ids.size and j not in self.claims_to]
        if beyond:  # a robot claiming farther than its reach from its strips: decisions_allowed lets none through
            raise ContractError(f"shard {self.index}: claims on shards {beyond}, beyond its robots' reach")
        return claims

    def apply(self, decisions: Decisions, rivals: list[Decisions], removing: np.ndarray | None = None) -> Part:
        """Exchange 2: apply this shard's robots' ``decisions`` (one for each of :meth:`own_moving`), ``rivals``
        (the other shards' claims sent to this one) taking part in the lottery only. ``removing``: robots of
        this shard's removed at the end of the tick, after the scheduled failures (a lost batch's, as
        ``Simulation.remove`` after ``Simulation.apply``).

        Raises:
            ContractError: the decisions are for another tick, or not exactly this shard's moving robots, or
                robots removed that are not this shard's.
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
        given = removing is not None and len(removing) > 0
        removing = np.unique(np.asarray(removing, dtype=np.int64)) if given else np.empty(0, dtype=np.int64)
        if removing.size and (
            own.size == 0 or (own[np.minimum(np.searchsorted(own, removing), own.size - 1)] != removing).any()
        ):
            raise ContractError(f"shard {self.index}: only its own moving robots can be removed")
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
            counts[4:7] = states[_INSIDE], states[_OUTSIDE], states[_WALKING]
            removing = np.setdiff1d(removing, failing, assume_unique=True)  # removed already, as a failure
        states = np.bincount(s.state[removing], minlength=8)
        counts[7:] = states[RobotState.LOCALIZED], states[_INSIDE], states[_OUTSIDE], states[_WALKING]
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
            removing=removing,
        )

    def routes(self, part: Part) -> list[Part]:
        """What of this shard's ``part`` each shard receives (nothing for this one)."""
        if self.plan.shards == 1:  # no peers: nothing to route
            return [part.take(_NONE)]
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
        self.received, self.gone_stationary = rows, _NONE
        if rows.ids.size:
            solid = (rows.z, rows.pitch) if self._solid else (None, None)
            self.view.merge(rows.ids, rows.state, rows.x, rows.y, rows.heading, *solid)
        kept, come = self._mine(own.ids), self._mine(np.sort(rows.ids)) if rows.ids.size else _NONE  # disjoint, sorted
        self._own = np.insert(kept, np.searchsorted(kept, come), come) if come.size else kept
        total = own.counts + counts
        self.localized += int(total[0])
        inside, outside, walking = (int(c) for c in total[1:4])
        code = self._close(tick, inside, outside, walking)
        p = self.params
        failing = self.outcome is None and p.failures > 0 and tick == p.fail_tick
        gone = np.concatenate([own.removing, rows.removing])
        if code == END_EXTRAS or failing or gone.size:  # robots left its own: separated, failed or removed
            self._end_of_tick(tick, total, gone, failing, inside, outside, walking)

    def _end_of_tick(
        self, tick: int, total: np.ndarray, gone: np.ndarray, failing: bool, inside: int, outside: int, walking: int
    ) -> None:
        """The end of a tick where robots stopped being its own: the scheduled failures, then the robots of lost
        batches, each redoing the tick's metrics as ``Simulation.remove`` does; and its own robots, less those."""
        if failing:
            self.history.pop()  # the tick's metrics are redone after the failures, as Simulation.remove does
            self._fail(failing_robots(self.params))
            inside, outside, walking = inside - int(total[4]), outside - int(total[5]), walking - int(total[6])
            self._close(tick, inside, outside, walking)
        if self.outcome is None and gone.size:  # then the robots of lost batches, as Lockstep removes them
            self.history.pop()
            self.localized -= int(total[7])
            self.alive -= int(gone.size)
            self.losses.append((tick, int(gone.size)))
            self._remove(gone)
            inside, outside, walking = inside - int(total[8]), outside - int(total[9]), walking - int(total[10])
            self._close(tick, inside, outside, walking)
        self._own = self._mine(self._own)  # less the failed, the removed and the separated

    def check(self, received: list[Part], whole: bool = True) -> tuple[Part, np.ndarray]:
        """That ``received`` can be the other shards' parts of this tick (:func:`check_parts`); returns their rows
        in one part and their counts summed. ``whole=False``: parts of some of the peers only.

        Raises:
            Rejected: what failed (its ``kind``), with nothing taken.
        """
        return check_parts(self, received, whole)

    def check_claims(self, source: int, claims: Decisions) -> None:
        """That ``claims`` can be shard ``source``'s rival claims for the tick this shard applies next
        (:func:`~swarm_ros.core.shard_parts.check_claims`).

        Raises:
            Rejected: what failed (its ``kind``), with nothing taken.
        """
        check_claims(self, source, claims)

    def _fail(self, failing: np.ndarray) -> None:
        """Scheduled failures: remove the failing robots this shard knows, and count them all."""
        s = self.state
        gone = failing[~self._removed[failing]]
        known = s.state[gone]
        self.localized -= int(((known == RobotState.SEED) | (known == RobotState.LOCALIZED)).sum())
        self.alive -= int(gone.size)
        if gone.size:
            self.losses.append((self.tick, int(gone.size)))
        self._remove(gone)

    def _remove(self, ids: np.ndarray) -> None:
        """Robots ``ids`` are removed: those this shard knows turn removed (a localized one frees its patch)."""
        self._removed[ids] = True
        s = self.state
        here = ids[(s.state[ids] != UNKNOWN) & (s.state[ids] != RobotState.REMOVED)]
        self.gone_stationary = np.union1d(self.gone_stationary, here[~IS_MOVING[s.state[here]]])
        solid = (s.z[here], s.pitch[here]) if s.z is not None and s.pitch is not None else (None, None)
        removed = np.full(here.size, RobotState.REMOVED, dtype=np.int8)
        self.view.merge(here, removed, s.x[here], s.y[here], s.heading[here], *solid)

    def _close(self, tick: int, inside: int, outside: int, walking: int) -> int:
        """The tick's end from the counts of every shard (:func:`~swarm_ros.core.tick_kernel.end_tick`, as the
        engine's); robots it separates, this shard marks in its own view."""
        row = np.empty(len(METRIC_COLUMNS), dtype=np.int64)
        code, _ = end_tick(
            tick, self.localized, inside, outside, walking, self._patches, self.alive, self.params.max_ticks, row
        )
        if code == END_EXTRAS:
            s = self.state
            known = IS_MOVING[s.state] & (s.state != UNKNOWN)
            s.state[known] = RobotState.SEPARATED
        self.history.append(tuple(int(v) for v in row))
        self.outcome = OUTCOME_OF_CODE[int(code)]
        return int(code)
