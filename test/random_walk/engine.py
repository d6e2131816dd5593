"""The random walk's rule and its in-process engine (see the package)."""

from __future__ import annotations

import numpy as np

from swarm_ros.core.algorithm import check_engine
from swarm_ros.core.errors import ParameterError
from swarm_ros.core.metrics import Outcome, TickMetrics, outcome_of, tick_metrics
from swarm_ros.core.state import RobotState, frontier_blocks_of, frontier_of, initial_state

STEPS = np.array([(1, 0), (1, 1), (0, 1), (-1, 1), (-1, 0), (-1, -1), (0, -1), (1, -1)])  #: the eight directions
MOVING = (RobotState.MOVING_OUTSIDE, RobotState.MOVING_INSIDE)


def check_shape(_params, shape) -> None:
    """It walks on the plane only."""
    if shape.dims != 2:
        raise ParameterError(f"{shape.source}: the random-walk algorithm forms 2D shapes only")


class RandomWalk:
    """The engine: ``run``, ``step``, ``tick``, ``done``, ``outcome``, ``metrics``, ``history``, ``progress``."""

    def __init__(self, shape, params) -> None:
        check_engine(params.algorithm, RandomWalk)
        self.shape, self.params = shape, params
        self.state = initial_state(shape, params.robots, params.seed)
        self.outcome: Outcome | None = None
        self.losses: list[tuple[int, int]] = []  # no robot fails
        self._rng = np.random.default_rng([params.seed, 0x57A1])  # its own stream, from the run's seed
        self._rows, self._n = np.zeros((1024, len(TickMetrics._fields)), dtype=np.int64), 0
        self._append(self._metrics())

    @property
    def tick(self) -> int:
        return self.state.tick

    @property
    def done(self) -> bool:
        return self.outcome is not None

    @property
    def metrics(self) -> TickMetrics:
        return TickMetrics(*self._rows[self._n - 1].tolist())

    @property
    def history(self) -> np.ndarray:
        return self._rows[: self._n]

    def _append(self, row: TickMetrics) -> None:
        if self._n == len(self._rows):  # doubled when full: a tick's row costs O(1)
            self._rows = np.concatenate([self._rows, np.zeros_like(self._rows)])
        self._rows[self._n], self._n = row, self._n + 1

    def progress(self) -> tuple[int, int, dict[str, str]]:
        m = self.metrics
        return m.localized, self.shape.patches, {"tick": str(m.tick), "moving": str(m.moving)}

    def step(self) -> None:
        self.run(1)

    def run(self, max_ticks: int | None = None) -> Outcome | None:
        ran = 0
        while not self.done and (max_ticks is None or ran < max_ticks):
            self._tick()
            ran += 1
        return self.outcome

    def _tick(self) -> None:
        s, world = self.state, self.shape.world
        r, w = world.radius, world.size
        blocked = world.wall_mask().ravel()
        moving = np.flatnonzero(np.isin(s.state, MOVING))
        heading = self._rng.integers(0, len(STEPS), size=moving.size)
        for i, k in zip(moving.tolist(), heading.tolist()):  # in id order: a robot that stops is seen by the next
            px, py = int(np.floor(s.x[i] + 0.5)) + STEPS[k][0], int(np.floor(s.y[i] + 0.5)) + STEPS[k][1]
            if not (-r <= px <= r and -r <= py <= r):
                continue
            cell = (py + r) * w + (px + r)
            if blocked[cell] or s.occupancy[cell] >= 0:
                continue
            s.x[i], s.y[i], s.heading[i] = float(px), float(py), np.arctan2(STEPS[k][1], STEPS[k][0]) % (2 * np.pi)
            if s.frontier[cell]:  # a free shape patch next to a stopped robot: it stops here for good
                s.state[i], s.occupancy[cell] = RobotState.LOCALIZED, i
                s.frontier[:] = frontier_of(self.shape, s.occupancy)
            else:
                inside = self.shape.mask.ravel()[cell]
                s.state[i] = RobotState.MOVING_INSIDE if inside else RobotState.MOVING_OUTSIDE
        s.frontier_blocks[:] = frontier_blocks_of(s.frontier, w)
        s.tick += 1
        self._append(self._metrics())
        self.outcome = outcome_of(self.metrics, self.shape.patches, s.robots, self.params.max_ticks)

    def _metrics(self) -> TickMetrics:
        counts = np.bincount(self.state.state, minlength=len(RobotState))
        return tick_metrics(self.state.tick, counts, self.shape.patches)
