"""The monitor's side of a central world's run (:mod:`swarm_ros.protocol.central_world`) as plain code: no rclpy,
no files, an injectable clock. The monitor node (:mod:`swarm_ros.nodes.central.monitor`) feeds it the world's
messages and does the rest: the bag, the report on /swarm/held, the run directory.

:class:`CentralMonitor` keeps a copy of the run (the algorithm's engine, loaded with what the world reports:
:meth:`~swarm_ros.core.strips.CentralRun.load`). It takes the metrics rows of every tick, one a tick and in order
(a restarted world sends again the ticks since its last record: they must equal those held), and the robots' rows
every ``record_every``-th tick and at the end (with world shards, each shard's robots: the record is whole once
every robot's row is in). It holds a tick once its record and its metrics are in, and the run may be written once
the world's outcome, the last record and the metrics up to it are.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np

from swarm_ros.core.errors import Rejected, RunFailed
from swarm_ros.core.metrics import Outcome

from . import checks
from .cdr import Cloud
from .central_rows import Wire, check_metrics_rows, metrics_row
from .plan import WORLD
from .status import WorldReport, has_ended, restart_event

#: seconds a monitor waits, once the world's outcome came, for the records and metrics up to it, before it fails
STATUS_WAIT = 5.0


class CentralMonitor:
    """What the monitor holds of a central world's run. ``copy``: the algorithm's engine at tick 0 (loaded as
    records come); ``shards``: the world processes whose records each hold a part of the robots; ``recorder``:
    told each record (``log(copy)``), or None."""

    def __init__(
        self,
        copy: Any,
        wire: Wire,
        shards: int = 1,
        recorder: Any = None,
        clock: Callable[[], float] = time.perf_counter,
    ) -> None:
        self.copy, self.wire, self.shards, self.recorder, self.clock = copy, wire, shards, recorder, clock
        self.robots = int(copy.params.robots)
        self.columns = tuple(copy.columns)
        self.history = np.empty((0, len(self.columns)))  #: the metrics of every tick taken, as the world sent them
        self.robots_tick = -1  #: the tick of the last whole record
        self.recorded = 0  #: the tick of the last record the recorder was told
        #: the whole records whose metrics are still on their way, (tick, robots) in order
        self.waiting: list[tuple[int, Any]] = []
        self.kept: tuple[int, Any] | None = None  #: the last whole record whose metrics are in: a stopped run's end
        self.parts: dict[int, list[np.ndarray]] = {}  #: record tick -> the world shards' rows of it so far
        self.outcome: str | None = None  #: the world's outcome, once its status reports one
        self.outcome_tick = -1
        self.outcome_at = 0.0  #: clock() as the outcome came
        self.started_at: float | None = None  #: clock() at the first metrics taken
        self.world = WorldReport()  #: what the world's (or world shards') status said: its clock, its drops
        self.restarts: list[tuple[int, str]] = []  #: (tick, node) of each restart: as the world listed them, and own

    @property
    def last_tick(self) -> int:
        """The last tick whose metrics are in (-1: none)."""
        return int(self.history[-1, 0]) if len(self.history) else -1

    def metrics(self, msg: Cloud) -> None:
        """The world's metrics rows since its last record (:func:`~swarm_ros.protocol.central_rows
        .check_metrics_rows`).

        Raises:
            Rejected: rows that are not the next ticks' (or the held ones' again), or out of bounds.
        """
        rows = checks.cloud(msg, metrics_row(self.columns), 10**9)
        history = check_metrics_rows(rows, self.history, self.columns)
        if self.started_at is None:
            self.started_at = self.clock()
        self.history = np.concatenate([self.history, history]) if len(self.history) else history
        self._record()

    def robots_record(self, msg: Cloud) -> bool:
        """A record's robots (a world shard's: its own); returns whether it was taken (False: a record held
        already, or a shard's part of one again). The copy is loaded once the record is whole.

        Raises:
            Rejected: rows out of bounds, not of the run at their tick, or of a robot the record holds already.
        """
        tick = checks.tick_stamp(msg.header)
        whole = self.robots if self.shards == 1 else 0  # a world shard's: its own robots
        rows = checks.cloud(msg, self.wire.row, self.robots, min_rows=whole)
        self.wire.check_rows(self.copy, rows, tick)
        if tick <= self.robots_tick or any(np.array_equal(p, rows) for p in self.parts.get(tick, ())):
            return False
        record = self._whole(tick, rows)
        if record is None:
            return True  # the other shards' robots of the record are still on their way
        self.robots_tick = tick
        _, robots = self.wire.robots_of(record)
        self.waiting.append((tick, robots))
        if not self._record():  # (which leaves the copy at this record: one load of the swarm, not two)
            self.copy.load(tick, robots, self.history if len(self.history) else self.copy.history)
        return True

    def _record(self) -> bool:
        """Keep each record, in order, once the metrics up to its tick are in too (they travel on another topic, and
        may lag several records, as when a restarted monitor reads the topics' histories, or as a run is stopped),
        and tell the recorder: it logs the ticks since the one before, metrics and all. (Tick 0's: logged as the
        recorder opened.) The copy is left at the last record; returns whether the recorder was told any."""
        told = False
        while self.waiting and self.waiting[0][0] <= self.last_tick:
            self.kept = tick, robots = self.waiting.pop(0)
            if self.recorder is not None and tick > self.recorded:
                self.copy.load(tick, robots, self.history[: tick + 1])
                self.recorder.log(self.copy)
                self.recorded, told = tick, True
        if told and self.recorded != self.robots_tick:  # later records wait for their metrics
            self.copy.load(self.robots_tick, self.waiting[-1][1], self.history)
        return told

    def _whole(self, tick: int, rows: np.ndarray) -> np.ndarray | None:
        """Every robot's rows of record ``tick`` once the world's (or every world shard's) are in, ascending; None
        until then.

        Raises:
            Rejected: rows of a robot the record holds already.
        """
        if self.shards == 1:
            return rows
        parts = self.parts.setdefault(tick, [])
        held = np.concatenate([p["id"] for p in parts]) if parts else np.empty(0, dtype=np.int64)
        if np.isin(rows["id"], held).any():
            raise Rejected("conflict", f"a robot's row twice in the record of tick {tick}")
        parts.append(rows)
        if held.size + rows.size < self.robots:
            return None
        self.parts = {t: p for t, p in self.parts.items() if t > tick}
        whole = np.concatenate(parts)
        return whole[np.argsort(whole["id"], kind="stable")]

    def status(self, values: dict[str, str], tick: int, sender: str = WORLD) -> None:
        """The status of the world, or of world shard ``sender`` (its values, its stamp's tick): the first outcome
        one reports is the run's."""
        for at, node in self.world.update(values, sender):
            self.restarted(at, node)
        outcome = values.get("outcome")
        if self.outcome is None and has_ended(outcome):
            self.outcome, self.outcome_tick, self.outcome_at = outcome, tick, self.clock()

    def restarted(self, tick: int, node: str) -> None:
        """A node's process was restarted at ``tick`` (as the world's status lists it, or the monitor's own): in the
        summary's ``restarts``, and an event in the recording."""
        self.restarts.append((tick, node))
        if self.recorder is not None:
            self.recorder.event(tick, restart_event(tick, node))

    def held(self) -> tuple[int, bool]:
        """What to report held once the bag holds what was taken: the last tick whose record and metrics are in,
        and whether the outcome is, at that tick."""
        tick = min(self.robots_tick, self.last_tick)
        return tick, self.outcome is not None and tick == self.outcome_tick

    def due(self) -> bool:
        """Whether the run may be written: the outcome came, and the last record and the metrics up to its tick
        (the outcome may come before them: they travel on other topics)."""
        end = self.outcome_tick
        return self.outcome is not None and self.robots_tick == end and self.last_tick == end

    def world_end_failure(self) -> RunFailed | None:
        """The failure of a run whose outcome came ``STATUS_WAIT`` seconds ago or more while its last record or
        metrics did not (lost: a monitor not under ``swarm-ros run`` or ``ros2 launch`` has nobody else to stop it);
        None while it may still wait."""
        if self.outcome is None or self.due() or self.clock() - self.outcome_at < STATUS_WAIT:
            return None
        return RunFailed(
            f"the world ended the run ('{self.outcome}') at tick {self.outcome_tick}, but the robots' messages reached "
            f"the monitor only up to tick {self.held()[0]} within {STATUS_WAIT:g} s"
        )

    def cut_at_record(self) -> bool:
        """A run stopped before its end: the copy at its last record whose metrics are in (later records' metrics
        may still be on their way), and the metrics up to it (one row a tick from tick 0), so that the files written
        of it agree on its tick; returns whether there is such a record to write."""
        if self.kept is None:
            return False
        tick, robots = self.kept
        self.history = self.history[: tick + 1]
        if tick != self.robots_tick:
            self.robots_tick, self.waiting = tick, []
            self.copy.load(tick, robots, self.history)
        return True

    def finish(self, outcome: Outcome) -> float:
        """The copy as the run directory gives it (its last record, the metrics, ``outcome``); returns the run's wall
        seconds: tick 0 to the outcome on the world's clock, as its status said, or else from the first metrics
        taken."""
        self.copy.load(self.robots_tick, self.copy.robots, self.history, outcome)
        own = self.clock() - self.started_at if self.started_at is not None else 0.0
        return self.world.times.get("wall_seconds", own)

    def graph_fields(self, rejected: int) -> dict[str, Any]:
        """What summary.json says of a run over the graph beside the algorithm's own summary (docs/usage.md), as
        the study's model's monitor says it: ``startup_seconds`` (the world's), ``rejected_messages`` (the world's
        and, ``rejected``, the monitor's), ``world_shards``, and the ``restarts`` it knows of (the launcher adds
        those it saw that are not there)."""
        return {
            "restarts": [{"tick": t, "node": n} for t, n in sorted(self.restarts, key=lambda r: r[0])],
            "startup_seconds": self.world.times.get("startup_seconds"),
            "rejected_messages": {"world": self.world.rejected, "monitor": rejected},
            "world_shards": self.shards,
        }
