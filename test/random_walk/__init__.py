"""A third, minimal algorithm (docs/adding_an_algorithm.md): a random walk that stops on a shape cell next to a stopped
robot, on the central world's graph as it is (``CENTRAL``). ``SWARM_ROS_ALGORITHMS=random_walk`` registers it."""

from __future__ import annotations

import numpy as np

from swarm_ros.core.algorithm import CENTRAL, Algorithm, register
from swarm_ros.core.errors import Rejected

from .engine import NAME, Batch, RandomWalk, Robots


class Wire:
    """Its rows on the wire: a robot's cell, id and state; a decision is the same row (the cell it steps to)."""

    row = decision_row = np.dtype({"names": [*"xyz", "id", "state"], "formats": ["<f4", "<f4", "<f4", "<u4", "<u1"]})
    batch = Batch
    __init__ = lambda self, dims: None  # (a grid of cells, whatever the world's dimensions)

    @staticmethod
    def rows(ids: np.ndarray, robots: Robots) -> np.ndarray:
        rows = np.zeros(ids.size, dtype=Wire.row)
        rows["id"] = ids
        rows["x"], rows["y"], rows["state"] = (a if a.size == ids.size else a[ids] for a in robots)
        return rows

    decision_rows = rows

    @staticmethod
    def robots_of(rows: np.ndarray) -> tuple[np.ndarray, Robots]:
        return rows["id"].astype(np.int64), Robots(*(rows[f].astype(t) for f, t in zip(Robots._fields, "qqb")))

    decisions_of = robots_of

    @staticmethod
    def check_rows(run: RandomWalk, rows: np.ndarray, tick: int) -> None:
        ids, (h, w) = rows["id"].astype(np.int64), run.mask.shape
        if np.any(ids >= run.params.robots) or np.any(np.diff(ids) <= 0):
            raise Rejected("bad ids", f"ids must ascend within 0..{run.params.robots - 1}")
        for f, size in (("x", w), ("y", h), ("state", 2)):
            if not np.all((rows[f] >= 0) & (rows[f] < size) & (rows[f] == np.floor(rows[f]))):
                raise Rejected("bad state", f"{f} must be a whole number in 0..{size - 1}")

    @staticmethod
    def check_decisions(run: RandomWalk, rows: np.ndarray, tick: int, own: np.ndarray) -> tuple[np.ndarray, Robots]:
        Wire.check_rows(run, rows, tick)
        ids, d = Wire.robots_of(rows)
        if not np.array_equal(ids, own):
            raise Rejected("not its robots", f"{ids.size} decisions for the batch's {own.size} robots")
        if np.any(np.abs(d.x - run.robots.x[ids]) + np.abs(d.y - run.robots.y[ids]) > 1 - d.state):
            raise Rejected("illegal", "a step other than one cell, or a stop that moves")
        return ids, d


register(Algorithm(
    name=NAME, max_ticks=20_000, bytes_per_robot=200, kernel_dir="", compile_seconds=0, run_dir_setting="walk",
    progress_unit="cell", progress_what="covered", engine="random_walk.engine:RandomWalk", wire="random_walk:Wire",
    summary="random_walk.engine:summary_of", print_summary="swarm_ros.app.darr_niazi.summary:print_summary", **CENTRAL,
    no_removal="its robots do not fail",
))  # fmt: skip
