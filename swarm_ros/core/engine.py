"""The simulation: the world's state, one tick at a time, and the fast in-process engine.

A tick has two halves. Robots decide from the state at the end of the last tick
(:func:`swarm_ros.core.rules.decide`, any batch of robots, anywhere); the world
applies all decisions at once (:meth:`Simulation.apply`), then counts, checks for the
end of the run and, if the shape is complete with robots left over, separates them.
:meth:`Simulation.step` does both halves in one compiled call for speed; a distributed
engine gathers its batches' decisions and calls :meth:`Simulation.apply`. Both share
every kernel and the same bookkeeping, so they give identical runs.

Only moving robots cost anything per tick: the cell list, the claims and the list of
moving robots are touched only where moving robots are, and the metrics are kept as
running counts.
"""

from __future__ import annotations

from collections.abc import Callable

import numba
import numpy as np

from .arbitration import resolve_kernel
from .metrics import Outcome, TickMetrics, outcome_of, run_summary, tick_metrics
from .params import RunParams
from .rules import Decisions, decide_kernel, index_build, index_clear
from .shapes import Shape
from .state import RobotState, SwarmState, initial_state

ENGINE_NAME = "inprocess"
_MOVING_OUTSIDE, _MOVING_INSIDE = int(RobotState.MOVING_OUTSIDE), int(RobotState.MOVING_INSIDE)
_LOCALIZED, _SEPARATED = int(RobotState.LOCALIZED), int(RobotState.SEPARATED)


@numba.njit(cache=True)
def _compact_moving(moving, m, state):
    """Keep the still-moving robots at the front of ``moving`` (order kept); return their count."""
    j = 0
    for k in range(m):
        i = moving[k]
        if state[i] == 1 or state[i] == 2:
            moving[j] = i
            j += 1
    return j


@numba.njit(cache=True)
def _step_kernel(moving, x, y, heading, state, shape, wall, frontier, occupancy, radius, size, vision, wiggle,
                 seed, head, nxt, best, claim, new_x, new_y, new_heading, outcome, last_ids, shape_patches,
                 m, tick, localized):
    """One whole tick for the robots ``moving[:m]``; returns (joined, inside, outside, still moving)."""
    ids = moving[:m]
    last_ids[:m] = ids
    index_build(ids, x, y, radius, size, head, nxt)
    decide_kernel(ids, x, y, heading, shape, wall, frontier, radius, size, vision, wiggle, seed, tick,
                  head, nxt, claim, new_x, new_y, new_heading)
    index_clear(ids, x, y, radius, size, head)
    joined, inside, outside = resolve_kernel(ids, claim, new_x, new_y, new_heading, x, y, heading, state,
                                             occupancy, frontier, shape, radius, size, seed, tick, best,
                                             localized, shape_patches, outcome)
    return joined, inside, outside, _compact_moving(moving, m, state)


class Simulation:
    """One run of the model: shape, parameters and the swarm's state, advanced tick by tick.

    Example:
        >>> sim = Simulation(Shape.load("star"), RunParams(robots=1036, seed=7))
        >>> outcome = sim.run()

    Attributes:
        shape: the shape being formed.
        params: the run's parameters.
        state: the swarm at the end of the current tick (read it, do not write it).
        history: metrics of every tick so far, tick 0 first.
        outcome: how the run ended, or None while it goes on.
    """

    engine = ENGINE_NAME

    def __init__(self, shape: Shape, params: RunParams) -> None:
        self.shape = shape
        self.params = params
        self.state: SwarmState = initial_state(shape, params.robots, params.seed)
        world = shape.world
        self._radius, self._size = world.radius, world.size
        self._shape = shape.mask.ravel().copy()
        self._wall = world.wall_mask().ravel()
        n, cells = params.robots, world.patch_count
        self._head = np.full(cells, -1, dtype=np.int32)
        self._best = np.full(cells, -1, dtype=np.int64)
        self._nxt = np.empty(n, dtype=np.int32)
        self._claim = np.empty(n, dtype=np.int64)
        self._new_x, self._new_y, self._new_heading = np.empty(n), np.empty(n), np.empty(n)
        self._outcome = np.empty(n, dtype=np.int8)
        self._last_ids = np.empty(n, dtype=np.int64)
        self._moving = self.state.moving_ids()
        self._m = int(self._moving.size)
        self._counts = [int(c) for c in self.state.counts()]
        self._decided = 0
        s = self.state
        self._kernel_args = (
            self._moving, s.x, s.y, s.heading, s.state, self._shape, self._wall, s.frontier, s.occupancy,
            self._radius, self._size, params.vision_radius, params.wiggle_rad, params.seed, self._head,
            self._nxt, self._best, self._claim, self._new_x, self._new_y, self._new_heading, self._outcome,
            self._last_ids, shape.patches)
        self.history: list[TickMetrics] = []
        self.outcome: Outcome | None = None
        self._finish_tick()

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
        return self.history[-1]

    def moving_ids(self) -> np.ndarray:
        """Ids of the robots that decide at the next tick, ascending (a copy)."""
        return self._moving[: self._m].copy()

    def last_joins(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(robot ids, claimed patch or -1, :class:`JoinOutcome`) of the robots that decided last tick."""
        n = self._decided
        return self._last_ids[:n].copy(), self._claim[:n].copy(), self._outcome[:n].copy()

    # -- advancing --------------------------------------------------------------
    def step(self) -> TickMetrics:
        """Advance one tick with every robot in this process."""
        if self.outcome is not None:
            self._check_running()
        m = self._m
        joined, inside, outside, self._m = _step_kernel(*self._kernel_args, m, self.state.tick + 1,
                                                        self.history[-1].localized)
        return self._advance(m, joined, inside, outside)

    def apply(self, decisions: Decisions) -> TickMetrics:
        """Advance one tick with decisions made elsewhere (the world's half of a tick).

        ``decisions`` must hold exactly one decision for every moving robot, made for the
        next tick (in any order, e.g. concatenated from several batches).

        Raises:
            ValueError: wrong tick, or the ids are not exactly the moving robots.
        """
        self._check_running()
        if decisions.tick != self.tick + 1:
            raise ValueError(f"decisions are for tick {decisions.tick}, the world is at tick {self.tick}")
        m = self._m
        if decisions.ids.size != m or not np.array_equal(np.sort(decisions.ids), self._moving[:m]):
            raise ValueError("decisions must cover every moving robot exactly once")
        self._last_ids[:m] = decisions.ids
        self._claim[:m] = decisions.claim
        joined, inside, outside = resolve_kernel(
            self._last_ids[:m], self._claim, decisions.x, decisions.y, decisions.heading, self.state.x,
            self.state.y, self.state.heading, self.state.state, self.state.occupancy, self.state.frontier,
            self._shape, self._radius, self._size, self.params.seed, decisions.tick, self._best,
            self.metrics.localized, self.shape.patches, self._outcome)
        self._m = _compact_moving(self._moving, m, self.state.state)
        return self._advance(m, joined, inside, outside)

    def run(self, on_tick: Callable[[Simulation], None] | None = None) -> Outcome:
        """Step until the run ends; call ``on_tick(self)`` after every tick. Returns the outcome."""
        while self.outcome is None:
            self.step()
            if on_tick is not None:
                on_tick(self)
        return self.outcome

    # -- bookkeeping shared by step() and apply() -------------------------------
    def _check_running(self) -> None:
        if self.outcome is not None:
            raise RuntimeError(f"the run has ended ({self.outcome}) at tick {self.tick}")

    def _advance(self, decided: int, joined: int, inside: int, outside: int) -> TickMetrics:
        self._decided = decided
        self.state.tick += 1
        c = self._counts
        c[_LOCALIZED] += joined
        c[_MOVING_INSIDE] = inside
        c[_MOVING_OUTSIDE] = outside
        return self._finish_tick()

    def _finish_tick(self) -> TickMetrics:
        metrics = tick_metrics(self.state.tick, self._counts, self.shape.patches)
        outcome = outcome_of(metrics, self.shape.patches, self.params.robots, self.params.max_ticks)
        if outcome is Outcome.COMPLETE_WITH_EXTRAS:
            left = self._moving[: self._m]
            self.state.state[left] = RobotState.SEPARATED
            self._counts[_SEPARATED] += int(left.size)
            self._counts[_MOVING_INSIDE] = self._counts[_MOVING_OUTSIDE] = 0
            self._m = 0
            metrics = tick_metrics(self.state.tick, self._counts, self.shape.patches)
        self.outcome = outcome
        self.history.append(metrics)
        return metrics

    def summary(self, wall_seconds: float = 0.0) -> dict:
        """The run's record (see :func:`swarm_ros.core.metrics.run_summary`); needs a finished run."""
        if self.outcome is None:
            raise RuntimeError("the run has not ended yet")
        return run_summary(
            shape=self.shape.name, shape_patches=self.shape.patches, params=self.params.as_dict(),
            engine=self.engine, outcome=self.outcome, final=self.metrics,
            separated=self._counts[_SEPARATED], world_radius=self._radius,
            wall_seconds=wall_seconds)

