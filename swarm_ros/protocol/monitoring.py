"""The monitor's side of the run as a plain class: no rclpy, no files, an injectable clock.

:class:`MonitorCore` counts the run from the world's rows: it keeps a :class:`~swarm_ros.core.replica.Replica`
of the swarm, counts each tick with the in-process engine's own functions
(:func:`~swarm_ros.core.metrics.tick_metrics`, :func:`~swarm_ros.core.metrics.outcome_of`), feeds the
recording, keeps what the world's status says, and decides when the run may be written and whether the
world and it agree on the outcome. The monitor node (:mod:`swarm_ros.nodes.monitor`) feeds it messages
(as :class:`~swarm_ros.protocol.cdr.Cloud` views and status values) and does the rest through a
:class:`MonitorPort`: the bag, the metrics message, the readers. A restarted monitor replays its bag
through the same calls inside :meth:`MonitorCore.replay`. Unit tests drive it with a fake port and
clock (test/test_monitoring.py), as test/test_lockstep.py drives the world's :class:`Lockstep`.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Protocol

import numpy as np

from swarm_ros.core.errors import Rejected, RunFailed
from swarm_ros.core.metrics import METRIC_COLUMNS, Outcome, TickMetrics, outcome_of, tick_metrics
from swarm_ros.core.params import RunParams
from swarm_ros.core.replica import Replica
from swarm_ros.core.run_result import RunRecord
from swarm_ros.core.shapes import Shape
from swarm_ros.core.state import STATE_COUNT, RobotState, has_repeats
from swarm_ros.protocol import checks
from swarm_ros.protocol.cdr import Cloud
from swarm_ros.protocol.checks import apply_robots, checked_robots
from swarm_ros.protocol.plan import WORLD
from swarm_ros.protocol.status import WorldReport, restart_event

PARTS_AHEAD = 1024  #: ticks ahead of the count for which world shards' parts are kept (the world window is 128)
STATUS_WAIT = 5.0  #: seconds to wait for the world's outcome after the monitor saw the end (and the reverse)
BAG_WAIT = 1.0  #: seconds to wait, after the end, for the last tick's decisions to reach the bag

_LOCALIZED, _MOVING = METRIC_COLUMNS.index("localized"), METRIC_COLUMNS.index("moving")
_REMOVED = int(RobotState.REMOVED)


class MonitorPort(Protocol):
    """What a :class:`MonitorCore` asks of its node. Never called while it replays a bag."""

    def tick_counted(
        self, tick: int, metrics: TickMetrics, occupancy: np.ndarray, first: bool, changed: bool
    ) -> None: ...  # the tick's messages into the bag, durable, then its metrics out
    def decisions_taken(self, tick: int) -> None: ...  # the decisions message being handled, into the bag
    def take_missed(self) -> int: ...  # hand over what waits in the readers; how many messages


class Recording(Protocol):
    """The part of :class:`~swarm_ros.artifacts.rerun_recording.Recorder` the monitor uses."""

    @property
    def closed(self) -> bool: ...

    every: int

    def metrics(self, rows: list) -> None: ...
    def robots(self, state, force: bool = False) -> None: ...
    def event(self, tick: int, text: str) -> None: ...
    def outcome(self, outcome: str, final: TickMetrics) -> None: ...
    def close(self) -> None: ...


class MonitorCore:
    """The run as the monitor counts it (see the module's docstring)."""

    def __init__(
        self,
        shape: Shape,
        params: RunParams,
        world_radius: int,
        port: MonitorPort,
        recorder: Recording | None,
        logger,
        incarnation: int = 0,
        clock: Callable[[], float] = time.monotonic,
        shards: int = 1,
    ) -> None:
        self.shape, self.params, self.world_radius, self.port, self.recorder, self.log, self.clock = (
            shape,
            params,
            world_radius,
            port,
            recorder,
            logger,
            clock,
        )
        self.incarnation = incarnation  # 0: the first monitor process of the run
        self.shards = shards  # world processes: each tick's rows come in this many parts (world shards)
        self.parts: dict[int, dict[str, np.ndarray]] = {}  # tick -> sender -> rows, until all its parts are in
        self.replica = Replica(shape, params.robots)
        self.rows: list[TickMetrics] = []  # the metrics of every tick counted, in order
        self.losses: list[tuple[int, int]] = []  # (tick, robots removed), seen as rows turning 'removed'
        self.removed = 0
        self.outcome: Outcome | None = None
        self.world = WorldReport()  # what the world's status said: restarts, its clock, its drops, the outcome
        self.world_end: tuple[float, int] | None = None  # (clock(), tick) when the world's outcome came
        self.started_at: float | None = None  # clock() at the first tick counted
        self.ended_at: float | None = None  # clock() at the last
        self.wall = 0.0
        self.decided_rows: dict[int, int] = {}  # tick -> decision rows seen
        self.decided_by: set[tuple[int, str]] = set()  # (tick, sender) of the decisions messages seen
        self.replaying = False  # taking the bag of the process before this one
        self.resumed_at = 0  # the tick it went on from

    # -- messages ---------------------------------------------------------------------
    def robots(self, msg: Cloud, sender: str = "") -> None:
        """The world's rows of a tick (with world shards, ``sender``'s part of them): counted, recorded, and (not
        replaying) made durable and reported, once every part of the tick is in.

        Raises:
            Rejected: malformed, out of range, or not the world's next rows; nothing was taken.
            RunFailed: rows the checks passed that the replica could not take (a gap in the checks), or world
                shards whose parts of a tick overlap.
        """
        if self.outcome is not None:
            return
        tick, rows = checked_robots(self.replica, msg, self.world_radius, part=self.shards > 1)
        if tick <= self.replica.tick:
            return  # again (a late-matched reader's history, a restarted world's last ticks)
        if self.shards == 1:
            self._count(tick, rows)
            return
        if tick > self.replica.tick + PARTS_AHEAD:
            raise Rejected("future tick", f"tick {tick}; the monitor has counted up to {self.replica.tick}")
        self.parts.setdefault(tick, {})[sender] = rows  # a shard's restarted process sends the same again
        while self.outcome is None and len(self.parts.get(self.replica.tick + 1, ())) == self.shards:
            tick = self.replica.tick + 1
            joined = np.concatenate(list(self.parts.pop(tick).values()))  # in no order: nothing below needs one
            if has_repeats(joined["id"]):
                raise RunFailed(f"tick {tick}: the world shards' parts hold a robot twice")
            self._count(tick, joined)

    def _count(self, tick: int, rows: np.ndarray) -> None:
        """Count a tick's rows (checked), whole."""
        apply_robots(self.replica, tick, rows)
        if self.started_at is None:
            self.started_at = self.clock()
        counts = np.bincount(self.replica.state.state, minlength=STATE_COUNT)
        metrics = tick_metrics(tick, counts, self.shape.patches)
        removed, removed_before = int(counts[_REMOVED]), self.removed
        self.rows.append(metrics)
        if not self.replaying:
            joined = len(self.rows) < 2 or metrics[_LOCALIZED] != self.rows[-2][_LOCALIZED]
            self.port.tick_counted(
                tick, metrics, self.replica.state.occupancy, len(self.rows) == 1, joined or removed > removed_before
            )
        if removed > removed_before:
            self.losses.append((tick, removed - removed_before))
            self.removed = removed
        p = self.params
        self.outcome = outcome_of(metrics, self.shape.patches, p.robots - removed, p.max_ticks)
        if self.recorder is not None:
            self.recorder.metrics([metrics])
            self.recorder.robots(self.replica.state, force=self.outcome is not None)
        if self.outcome is not None:  # its CPU so far, per tick, without writing the run (scripts/bench_scale.py)
            self.ended_at = self.clock()
            self.wall = self.ended_at - self.started_at
            self.log.info(f"last tick, {tick}: {self.outcome.value} ({time.process_time():.2f} s of CPU)")

    def decisions(self, msg: Cloud, sender: str = "") -> None:
        """A tick's applied decisions (with world shards, ``sender``'s): counted (the bag is whole once the last
        tick's are in, :meth:`bag_complete`).

        Raises:
            Rejected: malformed or out of range; nothing was taken.
        """
        tick, rows = checks.decision_message(msg, self.params.robots, self.shape.dims)
        if (tick, sender) in self.decided_by and not self.replaying:
            return  # recorded already (a restarted world sends the last ticks again)
        self.decided_by.add((tick, sender))
        self.decided_rows[tick] = self.decided_rows.get(tick, 0) + rows.size
        if not self.replaying:
            self.port.decisions_taken(tick)

    def status(self, values: dict[str, str], tick: int, sender: str = WORLD) -> None:
        """One status message of the world's, or of world shard ``sender``'s (its values, its stamp's tick)."""
        for at, node in self.world.update(values, sender):
            self.log.warn(f"{node} was restarted at tick {at}")
            if self.recorder is not None and not self.recorder.closed:
                self.recorder.event(at, restart_event(at, node))
        if self.world.outcome is not None and self.world_end is None:
            self.world_end = (self.clock(), tick)

    # -- the clock --------------------------------------------------------------------
    def bag_complete(self) -> bool:
        """Whether the last tick's decisions are in: they may arrive after the world's last rows."""
        last = self.replica.tick
        if last <= 0 or len(self.rows) < last:
            return True
        return self.decided_rows.get(last, 0) >= self.rows[last - 1][_MOVING]

    def due(self, bag: bool) -> bool:
        """Whether the run may be written now (its recording is then closed): it ended, the world's outcome came
        and agrees (or did not come within :data:`STATUS_WAIT`), and with a ``bag``, the last decisions are in
        (or did not come within :data:`BAG_WAIT`).

        Raises:
            RunFailed: the world reports another outcome; or it ended the run and the rows never came.
        """
        now = self.clock()
        if self.outcome is None:
            self._check_world_end(now)
            return False
        assert self.ended_at is not None  # set with the outcome
        if self.world.outcome is None and now - self.ended_at < STATUS_WAIT:
            return False
        if bag and not self.bag_complete() and now - self.ended_at < BAG_WAIT:
            return False
        missed = self.port.take_missed()
        if missed:
            self.log.warn(
                f"{missed} messages were still in the readers, not handed over by the executor; handled "
                f"before writing the run"
            )
        if self.world.outcome is not None and self.world.outcome != self.outcome.value:
            raise RunFailed(
                f"the world reports '{self.world.outcome}', the monitor counted "
                f"'{self.outcome.value}' at tick {self.replica.tick}"
            )
        if self.recorder is not None:  # closed only now: the world's last status may add restart events
            self.recorder.outcome(self.outcome.value, self.rows[-1])
            self.recorder.close()
        return True

    def _check_world_end(self, now: float) -> None:
        """Fail, rather than wait forever, when the world has ended the run but this count has not: the robots'
        last messages never came (a process that is not under ``swarm-ros run`` or ``ros2 launch`` has nobody
        else to stop it)."""
        if self.world_end is None or now - self.world_end[0] < STATUS_WAIT:
            return
        self.port.take_missed()
        if self.outcome is None:
            raise RunFailed(
                f"the world ended the run ('{self.world.outcome}') at tick {self.world_end[1]}, but the "
                f"robots' messages reached the monitor only up to tick {self.replica.tick} within "
                f"{STATUS_WAIT:g} s"
            )

    # -- the end ----------------------------------------------------------------------
    def record(self, rejected: int, outcome: Outcome | None = None) -> RunRecord:
        """The run's record as counted (``outcome``: another than the count's, for a run stopped before its end);
        ``rejected``: the messages the monitor dropped."""
        wall = self.wall if self.outcome is not None else self.clock() - (self.started_at or self.clock())
        return self.world.record(
            self.shape,
            self.params,
            self.replica.state,
            self.rows,
            outcome or self.outcome,
            wall,
            self.losses,
            rejected,
            monitor=(self.incarnation, self.resumed_at),
        )

    def close_recording(self, stopped: bool) -> None:
        """On the way out of a run stopped before it was written: the recording is closed, marked ``interrupted``
        (``stopped``: Ctrl-C or orphaned; or the run ended and the world had not confirmed it) or ``failed``."""
        if self.recorder is None or self.recorder.closed:
            return
        if self.rows:
            how = "interrupted" if stopped or self.outcome is not None else "failed"
            self.recorder.outcome(how, self.rows[-1])
        self.recorder.close()

    # -- a restarted monitor ----------------------------------------------------------
    @contextmanager
    def replay(self) -> Iterator[None]:
        """Messages taken inside this are the process before's, from its bag: counted and recorded, never
        reported or written to the bag again."""
        self.replaying = True
        try:
            yield
        finally:
            self.replaying = False

    def replayed(self, metrics: list[tuple[int, ...]]) -> None:
        """The bag's replay is over; ``metrics``: the metrics messages it held, which must be the rows counted.

        Raises:
            RunFailed: they are not.
        """
        if [tuple(r) for r in self.rows] != [tuple(m) for m in metrics]:
            raise RunFailed("the bag of the monitor before this one holds other metrics than its rows give")
        self.resumed_at = max(self.replica.tick, 0)
