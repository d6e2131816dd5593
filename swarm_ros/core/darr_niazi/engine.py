"""The simulation: the world's state, one tick at a time, and the fast in-process engine.

A tick has two halves. Robots decide from the state at the end of the last tick
(:func:`swarm_ros.core.darr_niazi.rules.decide`, any batch of robots, anywhere); the world
applies all decisions at once (:meth:`Simulation.apply`), then counts, checks for the
end of the run and, if the shape is complete with robots left over, separates them.
:meth:`Simulation.step` and :meth:`Simulation.run` do both halves in compiled code
(``run`` many ticks per call); :meth:`Simulation.apply` applies decisions made elsewhere. All
these share every kernel and the end of a tick (:func:`~swarm_ros.core.darr_niazi.tick_kernel.end_tick`, through
:func:`~swarm_ros.core.darr_niazi.tick_kernel.close_tick`), so they give identical runs. The ROS 2 graph's world
applies its batches' decisions with :meth:`Simulation.apply`; a world shard's half of a tick is
:meth:`Simulation.settle_shard` and :meth:`Simulation.close_shard` (:mod:`swarm_ros.core.central_shards`),
which sum the shards' counts and end the tick with the same ``end_tick``.

Only moving robots cost anything per tick: the cell list, the claims and the list of
moving robots are touched only where moving robots are, and the metrics are kept as
running counts.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from swarm_ros.core.algorithm import check_engine
from swarm_ros.core.darr_niazi.arbitration import occupy, resolve_kernel, vacate
from swarm_ros.core.darr_niazi.kernel_state import grid_of, moves_for, robots_of, rules_of
from swarm_ros.core.darr_niazi.legality import halo, reach
from swarm_ros.core.darr_niazi.metrics import METRIC_COLUMNS, TickMetrics, progress_of
from swarm_ros.core.darr_niazi.rules import Decided, Decided3D, Decisions
from swarm_ros.core.darr_niazi.rules2d import cell_index
from swarm_ros.core.darr_niazi.state import (
    IS_MOVING,
    STATE_COUNT,
    Poses,
    Poses3D,
    RobotState,
    SwarmState,
    initial_state,
    poses_of,
)
from swarm_ros.core.darr_niazi.tick_kernel import End, Scratch, close_tick, compact_moving, end_tick, run_kernel
from swarm_ros.core.errors import ContractError
from swarm_ros.core.grid import CellMap
from swarm_ros.core.metrics import END_EXTRAS, OUTCOME_OF_CODE, Outcome
from swarm_ros.core.params import RunParams
from swarm_ros.core.rng import STREAM_FAIL, uniform_array
from swarm_ros.core.shapes import Shape
from swarm_ros.core.strips import StripGrid

_STATIONARY_LOCALIZED = (int(RobotState.SEED), int(RobotState.LOCALIZED))
_STATIONARY, _MOVING = METRIC_COLUMNS.index("stationary"), METRIC_COLUMNS.index("moving")
_COUNTED = [RobotState.MOVING_INSIDE, RobotState.MOVING_OUTSIDE, RobotState.WALKING]  #: the moving, as metrics count


def failing_robots(params: RunParams) -> np.ndarray:
    """The ids of the robots that fail at ``params.fail_tick``: the ``params.failures`` robots with the
    lowest draws of the failure stream (a pure function of seed and ids, so every engine picks the same)."""
    ids = np.arange(params.robots)
    draws = uniform_array(params.seed, ids, params.fail_tick, STREAM_FAIL)
    return np.sort(ids[np.argsort(draws, kind="stable")[: params.failures]])


_CHUNK = 4096  # ticks per compiled call in run(): long enough to hide the call, short enough for progress


class Simulation:
    """One run of the model: shape, parameters and the swarm's state, advanced tick by tick.

    Example:
        >>> sim = Simulation(Shape.load("star"), RunParams(robots=1036, seed=7))
        >>> outcome = sim.run()

    Attributes:
        shape: the shape being formed.
        params: the run's parameters.
        state: the swarm at the end of the current tick (read it, do not write it).
        outcome: how the run ended, or None while it goes on.
    """

    def __init__(self, shape: Shape, params: RunParams) -> None:
        check_engine(params.algorithm, Simulation)
        self.shape = shape
        self.params = params
        self.state: SwarmState = initial_state(shape, params.robots, params.seed)
        world = shape.world
        self._radius, self._size = world.radius, world.size
        self._shape = shape.mask.ravel().copy()
        self._wall = world.wall_mask().ravel()
        self._nbrs = world.neighbour_offsets()
        self._solid = world.dims == 3
        n, cells = params.robots, world.patch_count
        self._scratch = Scratch(
            head=np.full(cells, -1, dtype=np.int32),
            nxt=np.empty(n, dtype=np.int32),
            best=np.full(cells, -1, dtype=np.int64),
            outcome=np.empty(n, dtype=np.int8),
            last_ids=np.empty(n, dtype=np.int64),
        )
        self._moves = moves_for(n, self._solid)  # the decisions of the last tick, by position
        self._rules = rules_of(params)
        self._moving = self.state.moving_ids()
        self._m = int(self._moving.size)
        self._decided = 0
        self._rows = np.zeros((1024, len(METRIC_COLUMNS)), dtype=np.int64)
        self._nrows = 0
        self.losses: list[tuple[int, int]] = []  #: (tick, robots removed at its end), in tick order
        self._leaving: dict[int, np.ndarray] = {}  # tick -> robots that leave at its end on a world shard (leave)
        self.last_removed = np.empty(0, dtype=np.int64)  #: ids removed at the end of the last tick
        s = self.state
        self._set_kernel_args(params.robots)
        counts = s.counts()
        self._localized = int(counts[RobotState.SEED] + counts[RobotState.LOCALIZED])
        self.outcome: Outcome | None = None
        code, self._m = close_tick(
            self._moving,
            self._m,
            s.state,
            0,
            self._localized,
            int(counts[RobotState.MOVING_INSIDE]),
            int(counts[RobotState.MOVING_OUTSIDE]),
            int(counts[RobotState.WALKING]),
            shape.patches,
            params.robots,
            params.max_ticks,
            self._rows[0],
        )
        self._record(0, 1, code)

    def _set_kernel_args(self, alive: int) -> None:
        """What the kernels take, by name (:mod:`swarm_ros.core.darr_niazi.kernel_state`), with ``alive`` robots not
        removed."""
        self._alive = alive
        self._robots = robots_of(self.state)
        self._grid = grid_of(self.shape, self.state, self._shape, self._wall, self._nbrs)
        self._end = End(int(self.shape.patches), int(alive), int(self.params.max_ticks))

    # -- reading ----------------------------------------------------------------
    @property
    def tick(self) -> int:
        return self.state.tick

    @property
    def done(self) -> bool:
        return self.outcome is not None

    @property
    def metrics(self) -> TickMetrics:
        """Metrics at the end of the current tick."""
        return TickMetrics(*self._rows[self._nrows - 1].tolist())

    def progress(self) -> tuple[int, int, dict[str, str]]:
        """The patches localized on so far, the shape's patches, and the tick and the robots moving (simulate's
        progress bar)."""
        return progress_of(self.metrics, self.shape.patches)

    def cell_map(self) -> CellMap:
        """The shape's patches, and those a localized robot stands on (the graph's maps)."""
        mask = self.shape.mask
        return self.shape.world.cell_map(mask, self.state.occupancy.reshape(mask.shape) >= 0)

    @property
    def history(self) -> np.ndarray:
        """Metrics of every tick so far, tick 0 first: int64 array, columns ``METRIC_COLUMNS`` (read-only)."""
        view = self._rows[: self._nrows]
        view.flags.writeable = False
        return view

    def empty_curve(self) -> np.ndarray:
        """(tick, the shape's empty patches) of every tick so far, as floats (an experiment's curves)."""
        return self.history[:, [0, METRIC_COLUMNS.index("empty_patches")]].astype(float)

    def moving_ids(self) -> np.ndarray:
        """Ids of the robots that decide at the next tick, ascending (a copy)."""
        return self._moving[: self._m].copy()

    def last_joins(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(robot ids, claimed patch or -1, :class:`JoinOutcome`) of the robots that decided last tick."""
        n, sc = self._decided, self._scratch
        return sc.last_ids[:n].copy(), self._moves.claim[:n].copy(), sc.outcome[:n].copy()

    def last_decisions(self) -> Decisions:
        """The decisions applied in the last tick (ids in the order applied): claims and the poses decided."""
        n, mv = self._decided, self._moves
        solid = {"z": mv.z[:n].copy(), "pitch": mv.pitch[:n].copy()} if self._solid else {}
        return Decisions(
            tick=self.tick,
            ids=self._scratch.last_ids[:n].copy(),
            claim=mv.claim[:n].copy(),
            x=mv.x[:n].copy(),
            y=mv.y[:n].copy(),
            heading=mv.heading[:n].copy(),
            **solid,
        )

    # -- advancing --------------------------------------------------------------
    def step(self) -> TickMetrics:
        """Advance one tick with every robot in this process."""
        self._run_compiled(1)
        return self.metrics

    def run(self, max_ticks: int | None = None, on_tick: Callable[[Simulation], None] | None = None) -> Outcome | None:
        """Run until the end, or for at most ``max_ticks`` more ticks; return the outcome (None if still going).

        With ``on_tick``, it is called after every tick (and ticks run one compiled call each);
        without it, many ticks run per compiled call.
        """
        left = float("inf") if max_ticks is None else max_ticks
        while self.outcome is None and left > 0:
            if on_tick is None:
                chunk = min(left, _CHUNK)
                if self._failure_pending():  # stop at the failure tick's end
                    chunk = min(chunk, self.params.fail_tick - self.tick)
                left -= self._run_compiled(int(chunk))
            else:
                self._run_compiled(1)
                left -= 1
                on_tick(self)
        return self.outcome

    def apply(self, decisions: Decisions) -> TickMetrics:
        """Advance one tick with decisions made elsewhere (the world's half of a tick).

        ``decisions`` must hold exactly one decision for every moving robot, made for the
        next tick (in any order, e.g. concatenated from several batches).

        Raises:
            ContractError: wrong tick, or the ids are not exactly the moving robots.
        """
        self._check_running()
        if decisions.tick != self.tick + 1:
            raise ContractError(f"decisions are for tick {decisions.tick}, the world is at tick {self.tick}")
        m = self._m
        if decisions.ids.size != m or not np.array_equal(np.sort(decisions.ids), self._moving[:m]):
            raise ContractError("decisions must cover every moving robot exactly once")
        joined, inside, outside, walking = self._resolve(decisions, m)
        self._localized += joined
        self._decided = m
        self._m = compact_moving(self._moving, m, self.state.state)
        self._reserve(1)
        code, self._m = close_tick(
            self._moving,
            self._m,
            self.state.state,
            decisions.tick,
            self._localized,
            inside,
            outside,
            walking,
            self.shape.patches,
            self._alive,
            self.params.max_ticks,
            self._rows[self._nrows],
        )
        self._record(1, 1, code)
        self._after_tick()
        return self.metrics

    def _resolve(self, decisions: Decisions, applied: int) -> tuple[int, int, int, int]:
        """The lottery of every patch ``decisions`` claim, and the moves of its first ``applied`` robots
        (:func:`~swarm_ros.core.darr_niazi.arbitration.resolve_kernel`): the counts of those after the tick."""
        mv, sc, m = self._moves, self._scratch, decisions.ids.size
        if self._solid and (decisions.z is None or decisions.pitch is None):
            raise ContractError("decisions in a 3D world need z and pitch")
        sc.last_ids[:m] = decisions.ids
        mv.claim[:m] = decisions.claim
        mv.x[:m], mv.y[:m], mv.heading[:m] = decisions.x, decisions.y, decisions.heading
        if self._solid:
            mv.z[:m], mv.pitch[:m] = decisions.z, decisions.pitch
        return resolve_kernel(
            sc.last_ids[:m],
            mv,
            self._robots,
            self._grid,
            self._rules,
            decisions.tick,
            sc.best,
            self._localized,
            self.shape.patches,
            sc.outcome,
            applied,
        )

    def remove(self, ids: np.ndarray) -> int:
        """Take robots out of the world at the end of the current tick (failures, a lost process).

        A removed robot frees the patch it held, if it was localized (the frontier
        follows), and no longer decides, is sensed or is counted; the remaining robots
        can refill the patch (self-repair). The current tick's metrics and the end check
        are redone. Returns how many robots were removed (robots already removed, or an
        ended run, count 0).
        """
        s = self.state
        ids = np.unique(np.asarray(ids, dtype=np.int64))
        if self.outcome is not None or ids.size == 0:
            self.last_removed = np.empty(0, dtype=np.int64)
            return 0
        if ids[0] < 0 or ids[-1] >= s.robots:
            raise ContractError(f"robot ids must be in [0, {s.robots - 1}]")
        ids = self._take_out(ids)
        counts = s.counts()
        self._m = compact_moving(self._moving, self._m, s.state)
        code, self._m = close_tick(
            self._moving,
            self._m,
            s.state,
            self.tick,
            self._localized,
            int(counts[RobotState.MOVING_INSIDE]),
            int(counts[RobotState.MOVING_OUTSIDE]),
            int(counts[RobotState.WALKING]),
            self.shape.patches,
            self._alive,
            self.params.max_ticks,
            self._rows[self._nrows - 1],
        )
        self.outcome = OUTCOME_OF_CODE[code]
        return int(ids.size)

    def _take_out(self, ids: np.ndarray) -> np.ndarray:
        """Robots ``ids`` (ascending) leave the world at the end of the tick: those not removed yet, which it
        returns, are; a localized one frees its patch (the frontier follows)."""
        s = self.state
        ids = ids[s.state[ids] != RobotState.REMOVED]
        for i in ids.tolist():
            if s.state[i] in _STATIONARY_LOCALIZED:
                z = s.z[i] if s.z is not None else 0.0
                vacate(
                    cell_index(s.x[i], s.y[i], z, self._solid, self._radius, self._size),
                    s.occupancy,
                    s.frontier,
                    s.frontier_blocks,
                    self._shape,
                    self._nbrs,
                    self._size,
                )
                self._localized -= 1
        s.state[ids] = RobotState.REMOVED
        self.last_removed = ids
        if ids.size:
            self.losses.append((self.tick, int(ids.size)))
        self._set_kernel_args(self._alive - int(ids.size))
        return ids

    @property
    def removed(self) -> int:
        """Robots removed so far."""
        return self.params.robots - self._alive

    # -- a central world's run (core.strips.CentralRun) ------------------------
    columns = METRIC_COLUMNS

    @property
    def grid(self) -> StripGrid:
        """The world's patch columns (a robot's is its nearest patch's); a decision reads the robots within
        :func:`~swarm_ros.core.darr_niazi.legality.halo` columns of its own, and two robots can claim one patch from
        up to twice a claim's :func:`~swarm_ros.core.darr_niazi.legality.reach` apart (a column of rounding each)."""
        rivals = 2 * (math.ceil(reach(self.params, self.shape.world.dims)) + 1)
        return StripGrid(-self._radius - 0.5, 1.0, self._size, "patches", halo(self.params.vision_radius), rivals)

    @property
    def robots(self) -> Poses | Poses3D:
        """Every robot's pose and state (the state's own arrays)."""
        return poses_of(self.state)

    def deciding(self, among: np.ndarray | None = None) -> np.ndarray:
        """The robots that decide the next tick, ascending: the moving ones (of ``among``, ascending, if given)."""
        if among is None:
            return self.moving_ids()
        return among[IS_MOVING[self.state.state[among]]]

    @staticmethod
    def seen_by_all(state: np.ndarray) -> np.ndarray:
        """Which robots every batch sees, by their ``state``: the stationary ones (a robot finds the frontier
        anywhere, from the localized ones)."""
        return ~IS_MOVING[state]

    def settle(self, decided: list[tuple[np.ndarray, Decided | Decided3D]]) -> Outcome | None:
        """Advance one tick with each robot batch's (ids, decisions): :meth:`apply` of them all."""
        self.apply(Decisions.concatenate([Decisions.of(self.tick + 1, ids, d) for ids, d in decided]))
        return self.outcome

    def load(self, tick: int, robots: Poses | Poses3D, history: np.ndarray, outcome: Outcome | None = None) -> None:
        """Take a state this run reached elsewhere: every robot as at ``tick``, the metrics of every tick up to it
        and the outcome (None: going on). The occupancy and the frontier follow from the robots, as a robot batch's
        view rebuilds them (:meth:`~swarm_ros.core.darr_niazi.swarm_view.SwarmView.load`), and the losses from the
        metrics (a tick's removals, failures and a lost batch's robots alike, as one loss).

        Raises:
            ContractError: robots that cannot be a state of the run (two on a patch, one off the shape).
        """
        from swarm_ros.core.darr_niazi.swarm_view import SwarmView  # (it imports the state's kernels, as this does)

        view, pose = SwarmView(self.shape, self.params.robots), robots._asdict()
        state = pose.pop("state")
        view.load(tick, np.arange(self.params.robots), state, **pose)
        self.state = view.state
        rows = np.asarray(history, dtype=np.int64)
        self._rows, self._nrows = rows.copy(), rows.shape[0]
        gone = self.params.robots - rows[:, _STATIONARY] - rows[:, _MOVING]  # removed by each tick's end
        self.losses = [(int(rows[t, 0]), int(gone[t] - gone[t - 1])) for t in np.flatnonzero(np.diff(gone) > 0) + 1]
        self._moving = self.state.moving_ids()
        self._m, self._decided = int(self._moving.size), 0
        counts = self.state.counts()
        self._localized = int(counts[RobotState.SEED] + counts[RobotState.LOCALIZED])
        self._set_kernel_args(self.params.robots - int(counts[RobotState.REMOVED]))
        self.outcome = outcome

    def saved(self) -> dict[str, np.ndarray]:
        """Every robot and the metrics of every tick so far: all a restarted world needs to go on exactly."""
        return {**{f"robot_{name}": a for name, a in self.robots._asdict().items()}, "history": self.history}

    def restore(self, tick: int, arrays: dict[str, np.ndarray]) -> None:
        """Go on from :meth:`saved`'s ``arrays`` of ``tick``, a run still going.

        Raises:
            KeyError, ContractError: arrays that are not a save of a run of these parameters.
        """
        mine = self.robots
        saved = [arrays[f"robot_{name}"] for name in mine._fields]
        if any(a.shape != b.shape or a.dtype != b.dtype for a, b in zip(saved, mine)):
            raise ContractError("a save of other robots than the run's")
        history = arrays["history"]
        if history.shape != (tick + 1, len(METRIC_COLUMNS)):
            raise ContractError(f"{history.shape[0]} metrics rows for tick {tick}")
        self.load(tick, type(mine)(*(a.copy() for a in saved)), history)

    # -- a world shard's run (core.central_shards.ShardedRun) ------------------
    def counts(self, ids: np.ndarray) -> np.ndarray:
        """Robots ``ids``' share of the next tick's counts (summed over the shards: :meth:`close_shard`): the
        localized, those moving inside, outside and walking, and of these the ones failing at the tick's end."""
        state = self.state.state
        here = np.bincount(state[ids], minlength=STATE_COUNT)
        failing = np.zeros(STATE_COUNT, dtype=np.int64)
        if self._fails_at(self.tick + 1):
            failing = np.bincount(state[np.intersect1d(self._failing(self.tick + 1), ids)], minlength=STATE_COUNT)
        localized = here[RobotState.SEED] + here[RobotState.LOCALIZED]
        return np.array([localized, *here[_COUNTED], *failing[_COUNTED]], dtype=np.int64)

    def settle_shard(
        self,
        own: np.ndarray,
        decided: Decided | Decided3D,
        halo: np.ndarray,
        halo_decided: Decided | Decided3D,
        present: np.ndarray,
    ) -> np.ndarray:
        """A world shard's half of the next tick (:mod:`swarm_ros.core.central_shards`): ``own`` its deciding robots
        and ``halo`` its peers' within its rivals' columns (ascending each, with their decisions). The lottery of
        every patch claimed, and its own robots' moves, as :meth:`apply`'s. Returns its robots that localized or fail
        at the tick's end: every shard holds every stationary robot (:meth:`seen_by_all`)."""
        self._check_running()
        joined = type(decided)(*(np.concatenate(f) for f in zip(decided, halo_decided)))
        self._resolve(Decisions.of(self.tick + 1, np.concatenate([own, halo]), joined), own.size)
        stopped = self.state.state[own] == RobotState.LOCALIZED
        if self._fails_at(self.tick + 1):
            stopped |= np.isin(own, self._failing(self.tick + 1))
        return own[stopped]

    def close_shard(self, shared: np.ndarray, rows: Poses | Poses3D, counts: np.ndarray) -> Outcome | None:
        """Close the next tick on a world shard, as every shard does alike: the robots that localized (among
        ``shared``, ascending, and their ``rows``) hold their patches; the tick's metrics and end follow from ``counts``
        (:meth:`counts`, summed over the shards), then the scheduled failures, as :meth:`apply`'s (``shared`` has
        the moving robots that fail too). The outcome."""
        s, tick, localized = self.state, self.tick + 1, RobotState.LOCALIZED
        theirs = shared[(rows.state == localized) & (s.state[shared] != localized)]  # (its own hold theirs already)
        for name, a in rows._asdict().items():
            getattr(s, name)[shared] = a
        for i in theirs.tolist():
            z = s.z[i] if s.z is not None else 0.0
            p = cell_index(s.x[i], s.y[i], z, self._solid, self._radius, self._size)
            occupy(p, i, s.occupancy, s.frontier, s.frontier_blocks, self._shape, self._nbrs, self._size)
        self._localized = int(counts[0])
        self._reserve(1)
        self._record(1, 1, self._end_shard(tick, counts[1:4], self._rows[self._nrows]))
        if self.outcome is None and self._fails_at(tick):
            self._take_out(self._failing(tick))
            self._leaving.pop(tick, None)
            code = self._end_shard(tick, counts[1:4] - counts[4:7], self._rows[self._nrows - 1])
            self.outcome = OUTCOME_OF_CODE[code]
        return self.outcome

    def _end_shard(self, tick: int, moving: np.ndarray, row: np.ndarray) -> int:
        """The end of ``tick`` on a shard, ``moving`` robots inside, outside and walking (its metrics into ``row``);
        robots left over separate (each shard marks those it holds)."""
        code, _ = end_tick(tick, self._localized, *(int(c) for c in moving), self.shape.patches, self._alive,
                           self.params.max_ticks, row)  # fmt: skip
        if code == END_EXTRAS:
            self.state.state[IS_MOVING[self.state.state]] = RobotState.SEPARATED
        return int(code)

    # -- bookkeeping ------------------------------------------------------------
    def leave(self, tick: int, ids: np.ndarray) -> None:
        """Robots ``ids`` leave the world at the end of ``tick`` on a world shard, as the scheduled failures do (a
        batch lost for good: :meth:`remove` at that tick's end in one world); every shard is told alike."""
        self._leaving[tick] = np.union1d(self._leaving.get(tick, ids[:0]), ids)

    def _fails_at(self, tick: int) -> bool:
        """Whether robots fail or leave at the end of ``tick``."""
        return (self.params.failures > 0 and tick == self.params.fail_tick) or tick in self._leaving

    def _failing(self, tick: int) -> np.ndarray:
        """The robots that fail or leave at the end of ``tick``, ascending."""
        leaving = self._leaving.get(tick, np.empty(0, dtype=np.int64))
        return np.union1d(failing_robots(self.params), leaving) if tick == self.params.fail_tick else leaving

    def _failure_pending(self) -> bool:
        return self.params.failures > 0 and self.tick < self.params.fail_tick

    def _after_tick(self) -> None:
        """Scheduled failures (``params.fail_fraction`` at the end of ``params.fail_tick``)."""
        self.last_removed = np.empty(0, dtype=np.int64)
        if self._fails_at(self.tick) and self.outcome is None:
            self.remove(self._failing(self.tick))

    def _check_running(self) -> None:
        if self.outcome is not None:
            raise ContractError(f"the run has ended ({self.outcome}) at tick {self.tick}")

    def _reserve(self, rows: int) -> None:
        need = self._nrows + rows
        if need > self._rows.shape[0]:
            grown = np.zeros((max(need, 2 * self._rows.shape[0]), self._rows.shape[1]), dtype=np.int64)
            grown[: self._nrows] = self._rows[: self._nrows]
            self._rows = grown

    def _run_compiled(self, limit: int) -> int:
        self._check_running()
        self._reserve(limit)
        n, self._m, self._localized, self._decided, code = run_kernel(
            self._moving,
            self._robots,
            self._grid,
            self._rules,
            self._scratch,
            self._moves,
            self._end,
            self._rows[self._nrows :],
            self._m,
            self.tick,
            self._localized,
            limit,
        )
        self._record(n, n, code)
        self._after_tick()
        return n

    def _record(self, ticks: int, rows: int, code: int) -> None:
        self.state.tick += ticks
        self._nrows += rows
        self.outcome = OUTCOME_OF_CODE[code]
