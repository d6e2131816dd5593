"""The rubenstein algorithm's in-process engine: every robot in one process, tick after tick.

A tick: every robot not joined decides from the last tick (:func:`~.kernels.decide_kernel`),
the world settles the moves so that no two robots overlap (:func:`~.kernels.resolve_kernel`)
and writes the decisions in; then the robots that joined cover the shape pixels their discs
meet, and the tick's metrics are taken. How a run ends (:class:`~swarm_ros.core.metrics.Outcome`):

* ``complete``: every shape pixel is covered and every robot has joined;
  ``complete_with_extras``: every pixel is covered and robots are left over (they keep
  edge-following, as Kilobots would);
* ``incomplete``: pixels are left uncovered and every robot has joined, or no robot has joined
  for ``stall_ticks`` ticks since the start-up (the robots left circle the group for good);
* ``timeout``: ``max_ticks`` first.
"""

from __future__ import annotations

import math

import numpy as np

from swarm_ros.core.algorithm import check_engine
from swarm_ros.core.errors import ContractError
from swarm_ros.core.grid import CellMap
from swarm_ros.core.metrics import OUTCOME_OF_CODE, Outcome, fill_ticks
from swarm_ros.core.params import RUBENSTEIN, RUN_PARAMETER, RunParams
from swarm_ros.core.rng import STREAM_PLACE_HEADING, uniform_array
from swarm_ros.core.shapes import Shape
from swarm_ros.core.strips import StripGrid

from .layout import SEED_G, SEEDS, ShapeFrame, start_positions
from .rule import (
    JOINED,
    MOVE_INSIDE,
    MOVE_OUTSIDE,
    NEVER,
    START,
    UNKNOWN_G,
    Bitmap,
    Cells,
    Decided,
    Robots,
    Rule,
    build_cells,
    cover,
    decided_for,
)
from .ticks import (
    Tally,
    end_code,
    join_robot,
    metrics_row,
    not_joined,
    run_kernel,
    settle_shard_kernel,
    settle_tick,
)

#: metrics.csv's columns for this algorithm, one row per tick (tick 0 first)
COLUMNS = ("tick", "joined", "moving", "waiting", "covered", "joined_outside", "loc_error")
_COVERED = COLUMNS.index("covered")
CHUNK = 4096  #: ticks per call of the compiled run, at most ...
#: ... and robot-ticks per call, at most: a call runs about 0.7 s (0.38 M robot-steps a second at 1,024 robots), so
#: a run answers Ctrl-C between calls within a second (a call of 4,096 ticks of 4,000 robots took 40 s). Its cost,
#: A/B on scripts/bench_algorithms.py against calls of 4,096 ticks: 0.97-0.98x (2^19: 0.99-1.05x, but 1.4 s a call)
CHUNK_ROBOT_TICKS = 1 << 18
MARGIN = 6.0  #: the cell grid reaches this far (in d, beyond the communication range) past the shape and the pack


def robots_at_start(params: RunParams) -> Robots:
    """The robots at tick 0: the seeds joined and localized, the others in START on the pack, facing a
    seeded random heading, with no gradient and no estimate."""
    n = params.robots
    pos = start_positions(n)
    f = np.zeros(n)
    heading = 2.0 * math.pi * uniform_array(params.seed, np.arange(n, dtype=np.int64), 0, STREAM_PLACE_HEADING)
    s = Robots(
        x=pos[:, 0].copy(),
        y=pos[:, 1].copy(),
        heading=heading,
        state=np.full(n, START, dtype=np.int8),
        g=np.full(n, UNKNOWN_G, dtype=np.int64),
        ex=f.copy(),
        ey=f.copy(),
        est=np.zeros(n, dtype=np.int8),
        loc=np.zeros(n, dtype=np.int8),
        still=np.zeros(n, dtype=np.int64),
        near=np.full(n, np.inf),
        began=np.full(n, NEVER, dtype=np.int64),
        joined=np.full(n, -1, dtype=np.int64),
        waited=np.zeros(n, dtype=np.int64),
        blind=np.zeros(n, dtype=np.int64),
    )
    k = len(SEEDS)
    s.state[:k], s.g[:k], s.est[:k], s.loc[:k], s.joined[:k] = JOINED, SEED_G, 1, 1, 0
    s.ex[:k], s.ey[:k] = SEEDS[:, 0], SEEDS[:, 1]
    return s


def rule_of(params: RunParams) -> Rule:
    return Rule(
        comm=params.comm_range,
        gradient=params.gradient_range,
        desired=params.desired_distance,
        yield_dist=params.yield_distance,
        patience=params.yield_patience,
        step=params.step_length,
        turn=math.radians(params.turn_deg),
        noise=params.range_noise,
        gain=params.loc_gain,
        sweeps=params.loc_sweeps,
        min_angle=math.radians(params.loc_min_angle_deg),
        settle=params.loc_settle,
        settle_ticks=params.loc_settle_ticks,
        stale=params.loc_stale_ticks,
        startup=params.startup_ticks,
        seed=params.seed,
    )


def bitmap_of(frame: ShapeFrame) -> Bitmap:
    rows, cols = frame.mask.shape
    return Bitmap(frame.mask.ravel().copy(), rows, cols, frame.pixel, frame.x0, frame.y0)


def cells_for(frame: ShapeFrame, start: Robots, params: RunParams) -> Cells:
    """A cell list of side the communication range over the shape and the pack, with a margin."""
    xmin, ymin, xmax, ymax = frame.extent
    pad = params.comm_range + MARGIN
    x0 = math.floor(min(xmin, start.x.min()) - pad)
    y0 = math.floor(min(ymin, start.y.min()) - pad)
    side = params.comm_range
    nx = int(math.ceil((max(xmax, start.x.max()) + pad - x0) / side))
    ny = int(math.ceil((max(ymax, start.y.max()) + pad - y0) / side))
    return Cells(np.full(nx * ny, -1, dtype=np.int64), np.full(params.robots, -1, dtype=np.int64), x0, y0, side, nx, ny)


def anchor_capacity(comm: float) -> int:
    """The most robots that fit within ``comm`` of a robot without overlapping (a hexagonal pack's density over
    the disc of radius ``comm`` + 1/2), and some."""
    return int(math.ceil(math.pi * (comm + 0.5) ** 2 / (math.sqrt(3.0) / 2.0))) + 8


class RubensteinRun:
    """A run of the rubenstein algorithm in one process (a :class:`~swarm_ros.core.strips.CentralRun`: the graph's
    world holds one, its strips' columns the cell list's).

    Attributes:
        shape, params: what is run; frame: the shape in the seeds' frame.
        robots: the robots' arrays (:class:`~.kernels.Robots`), as at the end of ``tick``.
        covered: per shape pixel (the frame's flat bitmap), 1 once a joined robot's disc meets it.
        outcome: how the run ended, or None while it goes on.
    """

    columns = COLUMNS

    def __init__(self, shape: Shape, params: RunParams) -> None:
        check_engine(params.algorithm, RubensteinRun)
        self.shape, self.params = shape, params
        self.frame = ShapeFrame.of(shape, params.pixel_size)
        self.robots = robots_at_start(params)
        self.rule = rule_of(params)
        self.bitmap = bitmap_of(self.frame)
        self.cells = cells_for(self.frame, self.robots, params)
        self.grid = StripGrid(self.cells.x0, self.cells.side, self.cells.nx, "d")
        self.covered = np.zeros(self.bitmap.mask.size, dtype=np.uint8)
        self.tick = 0
        self.outcome: Outcome | None = None
        self._out = decided_for(params.robots)
        self._granted = np.zeros(params.robots, dtype=np.uint8)
        self._slot = np.full(params.robots, -1, dtype=np.int64)
        cap = anchor_capacity(params.comm_range)
        self._anchors = (np.empty(cap), np.empty(cap), np.empty(cap))
        self._tally = Tally(np.zeros(1, np.int64), np.zeros(1), np.zeros(1, np.int64))
        self._end = (len(SEEDS), params.stall_ticks, params.max_ticks)
        row = np.empty((1, len(COLUMNS)))
        for k in range(len(SEEDS)):
            join_robot(k, self.robots, self.bitmap, self.covered, self._tally, len(SEEDS), 0)
        metrics_row(0, self.robots, self.covered, self._tally, len(SEEDS), row[0])
        self._rows: list[np.ndarray] = [row]

    # -- reading ---------------------------------------------------------------------------------------------
    done = property(lambda self: self.outcome is not None)
    pixels = property(lambda self: self.frame.pixels)  #: the shape's

    @property
    def history(self) -> np.ndarray:
        """Every tick's metrics row (``COLUMNS``), tick 0 first."""
        if len(self._rows) > 1:
            self._rows = [np.concatenate(self._rows)]
        return self._rows[0]

    @property
    def metrics(self) -> dict[str, float]:
        return dict(zip(COLUMNS, self._rows[-1][-1].tolist()))

    def empty_curve(self) -> np.ndarray:
        """(tick, the shape's uncovered pixels) of every tick so far (an experiment's curves)."""
        h = self.history
        return np.stack([h[:, 0], self.pixels - h[:, _COVERED]], axis=1)

    def progress(self) -> tuple[int, int, dict[str, str]]:
        """The shape's pixels covered so far, all its pixels, and the tick and the robots joined (simulate's
        progress bar)."""
        m = self.metrics
        return int(m["covered"]), self.pixels, {"tick": str(self.tick), "joined": str(int(m["joined"]))}

    def cell_map(self) -> CellMap:
        """The shape's pixels, and those a joined robot's disc meets (the graph's maps)."""
        b = self.bitmap
        return CellMap(b.mask.reshape(b.rows, b.cols), self.covered.reshape(b.rows, b.cols) > 0, b.pixel, (b.x0, b.y0))

    # -- running ---------------------------------------------------------------------------------------------
    def step(self) -> None:
        """Advance one tick."""
        self.run(1)

    def run(self, max_ticks: int | None = None) -> Outcome | None:
        """Run to the end, or ``max_ticks`` more ticks; the outcome, or None if the run goes on."""
        if self.outcome is not None:
            raise ContractError(f"the run has ended ({self.outcome}) at tick {self.tick}")
        while self.outcome is None and (max_ticks is None or max_ticks > 0):
            chunk = max(1, min(CHUNK, CHUNK_ROBOT_TICKS // self.params.robots))
            limit = chunk if max_ticks is None else min(chunk, max_ticks)
            rows = np.empty((limit, len(COLUMNS)))
            ticks, code = run_kernel(
                self.robots,
                self.rule,
                self.bitmap,
                self.cells,
                self._out,
                self._granted,
                self._slot,
                *self._anchors,
                self.covered,
                self._tally,
                rows,
                self.tick,
                limit,
                self._end,
            )
            self.tick += ticks
            self._rows.append(rows[:ticks])
            self.outcome = OUTCOME_OF_CODE[code]
            if max_ticks is not None:
                max_ticks -= ticks
        return self.outcome

    def load(self, tick: int, robots: Robots, history: np.ndarray, outcome: Outcome | None = None) -> None:
        """Take a state this run reached elsewhere (the graph's world, for its monitor): every robot as at
        ``tick``, the metrics of every tick up to it, and the outcome (None: going on). The pixels covered
        are those the joined robots' discs meet, as the run marked them."""
        for mine, theirs in zip(self.robots, robots):
            mine[:] = theirs
        self.tick, self.outcome, self._rows = tick, outcome, [history]
        self.covered[:] = 0
        for i in np.flatnonzero(self.robots.state == JOINED):
            cover(self.robots.x[i], self.robots.y[i], self.bitmap, self.covered)

    def saved(self) -> dict[str, np.ndarray]:
        """Everything a restarted world needs to go on from this tick exactly: every robot, the pixels covered,
        the running counts and the metrics of every tick so far (a checkpoint, :meth:`restore`)."""
        arrays = {f"robot_{name}": values for name, values in self.robots._asdict().items()}
        arrays.update({f"tally_{name}": values for name, values in self._tally._asdict().items()})
        return {**arrays, "covered": self.covered, "history": self.history}

    def restore(self, tick: int, arrays: dict[str, np.ndarray]) -> None:
        """Go on from :meth:`saved`'s ``arrays`` of ``tick``, a run still going, so the ticks after it are the ones
        the run would have had.

        Raises:
            KeyError, ContractError: arrays that are not a save of a run of these parameters.
        """
        for name, mine in self.robots._asdict().items():
            mine[:] = _same_shape(arrays[f"robot_{name}"], mine)
        for name, count in self._tally._asdict().items():
            count[:] = _same_shape(arrays[f"tally_{name}"], count)
        self.covered[:] = _same_shape(arrays["covered"], self.covered)
        history = arrays["history"]
        if history.shape != (tick + 1, len(COLUMNS)):
            raise ContractError(f"{history.shape[0]} metrics rows for tick {tick}")
        self.tick, self.outcome, self._rows = tick, None, [history.copy()]

    def deciding(self, among: np.ndarray | None = None) -> np.ndarray:
        """The robots that decide the next tick: every one not joined, ascending (of ``among``, ascending, if
        given)."""
        if among is None:
            return _deciding(self.robots.state)
        return among[self.robots.state[among] != JOINED]

    @staticmethod
    def seen_by_all(state: np.ndarray) -> np.ndarray:
        """None: a robot reads only the robots within its communication range."""
        return np.zeros(state.shape, dtype=bool)

    def counts(self, ids: np.ndarray) -> np.ndarray:
        """Robots ``ids``' share of the tick's counts: joined, moving, waiting (a world shard's, summed over the
        shards: :meth:`close_shard`)."""
        state = self.robots.state[ids]
        moving = np.count_nonzero((state == MOVE_OUTSIDE) | (state == MOVE_INSIDE))
        joined = np.count_nonzero(state == JOINED)
        return np.array([joined, moving, ids.size - joined - moving], dtype=np.int64)

    def settle_shard(
        self, own: np.ndarray, decided: Decided, halo: np.ndarray, halo_decided: Decided, present: np.ndarray
    ) -> np.ndarray:
        """A world shard's half of the next tick (:mod:`swarm_ros.core.central_shards`): ``own`` its deciding
        robots and ``halo`` its halo's (the peers' batches decided them), each ascending, with their decisions;
        ``present``: every robot it holds, where it stands. Settles its own robots' moves against every robot
        present, as :meth:`settle` does, and applies them. Returns the ids of its robots that joined: their rows
        change what every shard shares (the pixels covered, the running counts: :meth:`close_shard`)."""
        deciding = np.concatenate([own, halo])
        for out, mine, theirs in zip(self._out, decided, halo_decided):
            out[: deciding.size] = np.concatenate([mine, theirs])
        settle_shard_kernel(
            present, deciding, own.size, self.robots, self.rule, self.cells, self._out, self._granted, self._slot,
            self.tick + 1,
        )  # fmt: skip
        return own[self.robots.state[own] == JOINED]

    def close_shard(self, joined: np.ndarray, rows: Robots, counts: np.ndarray) -> Outcome | None:
        """Close the next tick on a world shard, as every shard does alike: the robots ``joined`` (ascending, their
        ``rows`` as they joined) cover their pixels and enter the running counts in id order, as :meth:`settle`
        takes them, and the tick's metrics are those ``counts`` (joined, moving, waiting, summed over the shards)
        and the shared state give. Returns the outcome, None while the run goes on."""
        tick, (seeds, stall, max_ticks) = self.tick + 1, self._end
        s = self.robots
        for k, i in enumerate(joined.tolist()):
            s.x[i], s.y[i], s.ex[i], s.ey[i] = rows.x[k], rows.y[k], rows.ex[k], rows.ey[k]
            join_robot(i, s, self.bitmap, self.covered, self._tally, seeds, tick)
        others, covered = int(counts[0]) - seeds, int(self.covered.sum())
        error = self._tally.error[0] / others if others > 0 else 0.0
        row = np.array([[tick, *counts.tolist(), covered, self._tally.outside[0], error]], dtype=float)
        self.tick += 1
        self._rows.append(row)
        code = end_code(
            tick, int(counts[0]), s.state.size, covered, int(self.bitmap.mask.sum()), self._tally.last_join[0],
            self.rule.startup, stall, max_ticks,
        )  # fmt: skip
        self.outcome = OUTCOME_OF_CODE[code]
        return self.outcome

    def settle(self, decided: list[tuple[np.ndarray, Decided]]) -> Outcome | None:
        """Advance one tick with decisions made elsewhere (robot batches, :mod:`swarm_ros.core.strips`): ``decided``
        holds each batch's ids and decisions (position k robot ``ids[k]``'s), which between them must hold every
        robot not joined exactly once. The world's half of the tick is :meth:`run`'s, so the result is the same.

        Raises:
            ContractError: the run has ended, or the decisions miss a robot, repeat one or hold a joined one.
        """
        if self.outcome is not None:
            raise ContractError(f"the run has ended ({self.outcome}) at tick {self.tick}")
        ids = np.concatenate([p[0] for p in decided]) if decided else np.empty(0, dtype=np.int64)
        mine = _deciding(self.robots.state)
        order = np.argsort(ids, kind="stable")
        if ids.size != mine.size or not np.array_equal(ids[order], mine):
            raise ContractError(f"tick {self.tick + 1}: the decisions are not one for each robot not joined")
        for field, out in zip(zip(*(p[1] for p in decided)), self._out):
            out[: mine.size] = np.concatenate(field)[order]
        row = np.empty((1, len(COLUMNS)))
        build_cells(np.arange(self.params.robots), self.robots.x, self.robots.y, self.cells)
        code = settle_tick(
            mine,
            self.robots,
            self.rule,
            self.bitmap,
            self.cells,
            self._out,
            self._granted,
            self._slot,
            self.covered,
            self._tally,
            row[0],
            self.tick + 1,
            self._end,
        )
        self.tick += 1
        self._rows.append(row)
        self.outcome = OUTCOME_OF_CODE[code]
        return self.outcome


def _same_shape(saved: np.ndarray, mine: np.ndarray) -> np.ndarray:
    if saved.shape != mine.shape or saved.dtype != mine.dtype:
        raise ContractError(f"an array of {saved.shape} {saved.dtype}, expected {mine.shape} {mine.dtype}")
    return saved


def _deciding(state: np.ndarray) -> np.ndarray:
    """The robots that decide a tick: every one not joined, ascending."""
    ids = np.empty(state.size, dtype=np.int64)
    return ids[: not_joined(state, ids)]


HOLE_SAMPLES = 8  #: a hole pixel's area is sampled at this many points along each side


def hole_filled(run: RubensteinRun) -> float:
    """The share of the area of the shape's holes (:attr:`ShapeFrame.holes`) under a joined robot's disc, 0 for
    a shape with no hole: the study's point against this algorithm is that it cannot leave a hole empty. Robots
    joined on a hole's rim, their centres on its edge, fill a band of it; only robots inside fill more. The area
    is sampled at ``HOLE_SAMPLES`` x ``HOLE_SAMPLES`` points a pixel, each filled when within 1/2 of a centre."""
    from scipy.spatial import cKDTree

    frame, s = run.frame, run.robots
    rows, cols = np.nonzero(frame.holes)
    joined = s.state == JOINED
    if rows.size == 0 or not joined.any():
        return 0.0
    offsets = (np.arange(HOLE_SAMPLES) + 0.5) / HOLE_SAMPLES * frame.pixel
    px = (frame.x0 + cols * frame.pixel)[:, None, None] + offsets[None, None, :]
    py = (frame.y0 + rows * frame.pixel)[:, None, None] + offsets[None, :, None]
    points = np.column_stack([a.ravel() for a in np.broadcast_arrays(px, py)])
    distance, _ = cKDTree(np.column_stack((s.x[joined], s.y[joined]))).query(points, distance_upper_bound=0.5)
    return float(np.count_nonzero(np.isfinite(distance)) / points.shape[0])


def summary_of(run: RubensteinRun, wall_seconds: float, stopped: Outcome | None = None) -> dict:
    """The summary.json record of a rubenstein run: what was run, how it ended, and the comparison's metrics
    (time: the end tick, ticks to 50% and 90% of the pixels covered; accuracy: the share of pixels covered,
    robots joined outside the shape, the share of its holes' area filled, the joined robots' mean localization
    error in d)."""
    outcome = run.outcome or stopped
    if outcome is None:
        raise ContractError("the run has not ended yet")
    m, history = run.metrics, run.history
    return {
        "shape": run.shape.name,
        "shape_pixels": run.pixels,
        **({"shape_scale": run.shape.scale} if run.shape.scale != 1 else {}),  # (an upscaled shape's only)
        **{k: v for k, v in run.params.as_dict().items() if RUN_PARAMETER[k].algorithm in ("", RUBENSTEIN)},
        "world_radius": run.shape.world.radius,  # the grid the shape was read into
        "engine": "inprocess",
        "outcome": str(outcome),
        "convergence_tick": run.tick,
        **dict(zip(("fill_50_tick", "fill_90_tick"), fill_ticks(history[:, 0], history[:, _COVERED], run.pixels))),
        "coverage": m["covered"] / run.pixels,
        "joined": int(m["joined"]),
        "joined_outside": int(m["joined_outside"]),
        "hole_filled": hole_filled(run),
        "loc_error": m["loc_error"],
        "wall_seconds": wall_seconds,
    }


def compile_kernels() -> None:
    """The rubenstein algorithm's kernels into numba's cache (core.kernels): a few ticks of a small run."""
    from swarm_ros.core.grid import World

    RubensteinRun(Shape.load("rectangle", World()), RunParams(robots=50, algorithm=RUBENSTEIN)).run(max_ticks=5)
