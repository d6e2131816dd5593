"""What a finished run leaves behind, whichever engine ran it: the data a run directory is written from."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from swarm_ros.core.engine import Simulation
from swarm_ros.core.metrics import Outcome, TickMetrics
from swarm_ros.core.params import RunParams
from swarm_ros.core.shapes import Shape
from swarm_ros.core.state import SwarmState


@dataclass(frozen=True)
class RunRecord:
    """What a finished run leaves behind, whichever engine ran it.

    Attributes:
        shape, params: what was run.
        state: the swarm at the last tick.
        history: metrics of every tick, tick 0 first (int64, columns ``METRIC_COLUMNS``).
        outcome: how the run ended.
        summary: the summary.json record (:func:`swarm_ros.core.metrics.run_summary`).
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
        summary = sim.summary(wall_seconds=wall_seconds, stopped=stopped)
        return RunRecord(shape=sim.shape, params=sim.params, state=sim.state, history=sim.history,
                         outcome=Outcome(summary["outcome"]), summary=summary)
