"""What a finished run of the study's model leaves behind, whichever engine ran it: its summary and the data a run
directory is written from. Both engines build its summary here (:func:`summarize`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from swarm_ros.core.darr_niazi.engine import Simulation
from swarm_ros.core.darr_niazi.metrics import TickMetrics, run_summary
from swarm_ros.core.darr_niazi.state import RobotState, SwarmState
from swarm_ros.core.errors import ContractError
from swarm_ros.core.metrics import INPROCESS, Outcome
from swarm_ros.core.params import RunParams
from swarm_ros.core.shapes import Shape


def summarize(
    *,
    shape: Shape,
    params: RunParams,
    state: SwarmState,
    final: TickMetrics,
    outcome: Outcome,
    engine: str,
    wall_seconds: float,
    losses=(),
    restarts=(),
    overhead=None,
    rejected=None,
    graph=None,
    history=None,
) -> dict:
    """The summary.json record of a run, from either engine (fields:
    :func:`swarm_ros.core.darr_niazi.metrics.run_summary`)."""
    return run_summary(
        shape=shape.name,
        shape_patches=shape.patches,
        params=params.as_dict(),
        engine=engine,
        outcome=outcome,
        final=final,
        separated=int((state.state == RobotState.SEPARATED).sum()),
        world_radius=shape.world.radius,
        wall_seconds=wall_seconds,
        losses=losses,
        restarts=restarts,
        overhead=overhead,
        rejected=rejected,
        mesh_scale=shape.mesh_scale,
        shape_scale=shape.scale,
        graph=graph,
        history=history,
    )


def summary_of(sim: Simulation, wall_seconds: float = 0.0, stopped: Outcome | None = None) -> dict:
    """The record of an in-process run. A run that has not ended needs ``stopped``, the outcome to record
    instead (``Outcome.INTERRUPTED``); its record describes the run up to the current tick."""
    outcome = sim.outcome or stopped
    if outcome is None:
        raise ContractError("the run has not ended yet")
    return summarize(
        shape=sim.shape,
        params=sim.params,
        state=sim.state,
        final=sim.metrics,
        outcome=outcome,
        engine=INPROCESS,
        wall_seconds=wall_seconds,
        losses=sim.losses,
        history=sim.history,
    )


@dataclass(frozen=True)
class RunRecord:
    """What a finished run leaves behind, whichever engine ran it.

    Attributes:
        shape, params: what was run.
        state: the swarm at the last tick.
        history: metrics of every tick, tick 0 first (int64, columns ``METRIC_COLUMNS``).
        outcome: how the run ended.
        summary: the summary.json record (:func:`swarm_ros.core.darr_niazi.metrics.run_summary`).
    """

    shape: Shape
    params: RunParams
    state: SwarmState
    history: np.ndarray
    outcome: Outcome
    summary: dict

    @property
    def final(self) -> TickMetrics:
        return TickMetrics(*self.history[-1].tolist())

    @staticmethod
    def of(sim: Simulation, wall_seconds: float, stopped: Outcome | None = None) -> RunRecord:
        """The record of an in-process run: finished, or ``stopped`` (interrupted) at its current tick."""
        summary = summary_of(sim, wall_seconds=wall_seconds, stopped=stopped)
        return RunRecord(
            shape=sim.shape,
            params=sim.params,
            state=sim.state,
            history=sim.history,
            outcome=Outcome(summary["outcome"]),
            summary=summary,
        )
