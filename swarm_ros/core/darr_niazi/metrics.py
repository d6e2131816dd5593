"""The study's model's metrics and termination, defined once for both engines and every consumer.

Per tick (``metrics.csv``): stationary (seeds, localized and separated robots), localized
(seeds included), inside (robots wandering on a shape patch), moving (wandering or
walking), empty shape patches, and walking (robots heading for a frontier patch under
``join: walk``). Per run (``summary.json``): outcome, convergence tick (the tick the run
ended), localized, unlocalized, separated, empty patches, and convergence rate: robots
that joined per tick, ``(localized - 4) / convergence_tick`` (0 at tick 0).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from swarm_ros.core.metrics import (
    END_COMPLETE,
    END_EXTRAS,
    END_INCOMPLETE,
    END_TIMEOUT,
    OUTCOME_OF_CODE,
    RUNNING,
    Outcome,
    fill_ticks,
)
from swarm_ros.core.params import DARR_NIAZI, RUN_PARAMETERS

SEEDS = 4


class TickMetrics(NamedTuple):
    """One row of ``metrics.csv``; counts of robots or patches at the end of ``tick``."""

    tick: int
    stationary: int
    localized: int
    inside: int
    moving: int
    empty_patches: int
    walking: int


METRIC_COLUMNS: tuple[str, ...] = TickMetrics._fields


def progress_of(m: TickMetrics, patches: int) -> tuple[int, int, dict[str, str]]:
    """A run's progress at the tick of ``m``, as its progress bars show it: the patches localized on, the shape's
    ``patches``, and the tick and the robots moving."""
    return m.localized, patches, {"tick": str(m.tick), "moving": str(m.moving)}


_LOCALIZED = METRIC_COLUMNS.index("localized")


# metric_values and end_code are plain Python here, so that a reader of metrics (the launcher's progress,
# the monitor) needs no numba; engine.py compiles the same functions for its kernels.
def metric_values(tick, localized, inside, outside, walking, separated, shape_patches):
    """The :class:`TickMetrics` fields, in order, from running counts (``localized`` includes seeds)."""
    return (
        tick,
        localized + separated,
        localized,
        inside,
        inside + outside + walking,
        shape_patches - localized,
        walking,
    )


def end_code(localized, moving, tick, shape_patches, robots, max_ticks):
    """The run's end code at this tick (``RUNNING`` if it goes on): complete, then incomplete, then timeout."""
    if localized == shape_patches:
        return END_COMPLETE if robots == shape_patches else END_EXTRAS
    if moving == 0:
        return END_INCOMPLETE
    if tick >= max_ticks:
        return END_TIMEOUT
    return RUNNING


def tick_metrics(tick: int, counts: Sequence[int] | np.ndarray, shape_patches: int) -> TickMetrics:
    """Metrics from the number of robots in each :class:`RobotState` (``counts[code]``, codes in order;
    removed robots, code 5, count nowhere)."""
    seed, outside, inside, localized, separated, _removed, walking = (int(c) for c in counts[:7])
    return TickMetrics(*metric_values(tick, seed + localized, inside, outside, walking, separated, shape_patches))


def outcome_of(metrics: TickMetrics, shape_patches: int, robots: int, max_ticks: int) -> Outcome | None:
    """The run's outcome if it ends at this tick, else None (``robots``: those not removed)."""
    return OUTCOME_OF_CODE[end_code(metrics.localized, metrics.moving, metrics.tick, shape_patches, robots, max_ticks)]


def convergence_rate(final: TickMetrics) -> float:
    """Robots that joined the shape per tick over the run."""
    return (final.localized - SEEDS) / final.tick if final.tick > 0 else 0.0


def _filled(history, shape_patches: int) -> tuple[int | None, int | None]:
    """:func:`fill_ticks` of a metrics history (rows of ``METRIC_COLUMNS``; none: never)."""
    h = np.asarray(history if history is not None else []).reshape(-1, len(METRIC_COLUMNS))
    return fill_ticks(h[:, 0], h[:, _LOCALIZED], shape_patches)


def run_summary(
    *,
    shape: str,
    shape_patches: int,
    params: dict,
    engine: str,
    outcome: Outcome,
    final: TickMetrics,
    separated: int,
    world_radius: int,
    wall_seconds: float,
    losses: Sequence[tuple[int, int]] = (),
    restarts: Sequence[tuple[int, str]] = (),
    overhead: dict[str, float | None] | None = None,
    rejected: dict[str, int] | None = None,
    mesh_scale: float = 1.0,
    shape_scale: int = 1,
    graph: dict[str, int | None] | None = None,
    history=None,
) -> dict:
    """The per-run record written to ``summary.json`` (and one row of an experiment).

    ``losses`` are (tick, robots) of robot removals (failures, lost processes);
    ``restarts`` are (tick, node) of robot-batch processes restarted (ROS graph only);
    ``unlocalized`` counts the robots still in the world that did not localize;
    ``overhead`` (ROS graph only) adds ``startup_seconds`` and ``shutdown_seconds``, placed
    after ``wall_seconds``; ``rejected`` (ROS graph only) the messages the world and the
    monitor dropped as malformed or illegal, as ``rejected_messages``; ``mesh_scale`` and ``shape_scale`` are
    fields only where they are not 1 (a mesh shape at another scale, a 2D shape upscaled), so that other summaries
    keep their fields;
    ``graph`` (ROS graph only) how it ran: ``processes`` (robot batches K, null where no launcher said) and
    ``world_shards``. ``history`` (every tick's metrics) gives ``fill_50_tick`` and ``fill_90_tick``, the first
    ticks at whose end half and 90% of the shape's patches were filled (null: never), and ``coverage`` is the
    share filled at the end: the times and accuracy the two algorithms are compared on.
    """
    robots = params["robots"]
    lost = sum(k for _, k in losses)
    return {
        "shape": shape,
        "shape_patches": shape_patches,
        **({"mesh_scale": mesh_scale} if mesh_scale != 1.0 else {}),
        **({"shape_scale": shape_scale} if shape_scale != 1 else {}),
        **{
            p.name: robots if p.name == "robots" else world_radius if p.name == "world_radius" else params[p.name]
            for p in RUN_PARAMETERS
            if p.name != "shape" and p.recorded and p.algorithm in ("", params.get("algorithm", DARR_NIAZI))
        },  # every run parameter of the run's algorithm, as declared
        "engine": engine,
        "outcome": outcome.value,
        "convergence_tick": final.tick,
        "localized": final.localized,
        "unlocalized": robots - lost - final.localized,
        "separated": separated,
        "empty_patches": final.empty_patches,
        "coverage": round(final.localized / shape_patches, 6),
        **dict(
            zip(
                ("fill_50_tick", "fill_90_tick"),
                _filled(history, shape_patches),
            )
        ),
        "convergence_rate": round(convergence_rate(final), 6),
        "wall_seconds": round(wall_seconds, 3),
        **{key: None if value is None else round(value, 3) for key, value in (overhead or {}).items()},
        **({"rejected_messages": dict(rejected)} if rejected is not None else {}),
        **(graph or {}),
        "lost_robots": lost,
        "losses": [{"tick": t, "robots": k} for t, k in losses],
        "restarts": [{"tick": t, "node": node} for t, node in restarts],
    }
