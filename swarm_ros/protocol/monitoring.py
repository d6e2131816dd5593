"""The monitor's side of the run as a plain class: no rclpy, no files, an injectable clock.

:class:`MonitorCore` counts the run from the world's rows: it keeps a :class:`~swarm_ros.core.swarm_view.SwarmView`
of the swarm, counts each tick with the in-process engine's own functions
(:func:`~swarm_ros.core.metrics.tick_metrics`, :func:`~swarm_ros.core.metrics.outcome_of`), feeds the
recording, keeps what the world's status says, and decides when the run may be written and whether the
world and it agree on the outcome. The monitor node (:mod:`swarm_ros.nodes.darr_niazi.monitor`) feeds it messages
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
from swarm_ros.core.run_result import RunRecord
from swarm_ros.core.shapes import Shape
from swarm_ros.core.state import STATE_COUNT, RobotState
from swarm_ros.core.swarm_view import SwarmView
from swarm_ros.protocol import checks
from swarm_ros.protocol.cdr import Cloud
from swarm_ros.protocol.central_monitor import STATUS_WAIT
from swarm_ros.protocol.checks import apply_robots, checked_robots, tally_values
from swarm_ros.protocol.plan import ROBOTS, TALLY, WORLD, shard_name
from swarm_ros.protocol.status import WorldReport, restart_event

PARTS_AHEAD = 1024  #: ticks ahead of the count for which world shards' parts are kept (the world window is 128)
#: seconds to wait, after the end, for the last tick's decisions to reach the bag: they go out before the tick's rows,
#: but over UDP a message of 100,000 rows was seen to come more than 1 s after them (four namespace hosts)
BAG_WAIT = 5.0

_LOCALIZED, _MOVING = METRIC_COLUMNS.index("localized"), METRIC_COLUMNS.index("moving")
_REMOVED = int(RobotState.REMOVED)


class MonitorPort(Protocol):
    """What a :class:`MonitorCore` asks of its node. Never called while it replays a bag."""

    def tick_counted(
        self,
        tick: int,
        metrics: TickMetrics,
        occupancy: np.ndarray | None,
        first: bool,
        changed: bool,
        messages: list[tuple[str, bytes]],
    ) -> None: ...  # the tick's `messages` (topic, as they came) into the bag, durable, then its metrics and held out
    # (occupancy: None when not known, at a tick whose rows did not come: record_every)
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


class HeldMessages:
    """The messages of the ticks not counted yet, as they came (tick -> (topic, sender) -> bytes): a tick's rows
    (world shards: their parts) and tallies go into the bag together once it is counted, tallies first."""

    def __init__(self, first: str) -> None:
        self.first = first  # the topic whose messages go first (a restarted monitor counts the tick from them)
        self.ticks: dict[int, dict[tuple[str, str], bytes]] = {}

    @contextmanager
    def holding(self, tick: int, last: int, key: tuple[str, str], raw: bytes) -> Iterator[None]:
        """Hold ``raw`` while the block hands it to the core (``last``: the tick counted last; one of a tick counted
        already is not held); if the core refuses it (Rejected), what it replaced is held again."""
        before = None
        if tick > last:
            self.ticks = {t: h for t, h in self.ticks.items() if t > last}
            before = self.ticks.setdefault(tick, {}).get(key)
            self.ticks[tick][key] = raw
        try:
            yield
        except Rejected:
            held = self.ticks.get(tick, {})
            if before is None:
                held.pop(key, None)
            else:
                held[key] = before
            raise

    def pop(self, tick: int) -> list[tuple[str, bytes]]:
        """(topic, message) of tick ``tick``, no longer held, :attr:`first`'s first."""
        held = self.ticks.pop(tick, {})
        return [(topic, raw) for (topic, _), raw in sorted(held.items(), key=lambda item: item[0][0] != self.first)]


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
        shards: int = 1,
        every: int = 1,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.shape, self.params, self.world_radius, self.port = shape, params, world_radius, port
        self.recorder, self.log, self.clock = recorder, logger, clock
        self.incarnation = incarnation  # 0: the first monitor process of the run
        self.shards = shards  # world processes: each tick's rows come in this many parts (world shards)
        self.parts: dict[int, dict[str, np.ndarray]] = {}  # tick -> sender -> rows, until all its parts are in
        # the world's record_every: 1, every tick's changed rows, counted here; above, the run's tally each tick
        # (from the world, or world shard 0), and every robot's row every ``every``-th tick (and the last),
        # checked against the tally
        self.every = every
        self.tallier = WORLD if shards == 1 else shard_name(0)  # the world process that sends the tallies
        self.tallies: dict[int, np.ndarray] = {}  # tick -> the run's robots by state (every > 1)
        self.held = HeldMessages(TALLY)  # the messages of the ticks not counted yet, as they came, for the bag
        self.last = -1  # the last tick counted
        self.occupancy_changed = False  # since the occupancy last went to the port (every > 1)
        self.view = SwarmView(shape, params.robots)
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
    def robots(self, msg: Cloud, sender: str = "", raw: bytes = b"") -> None:
        """The world's rows of a tick (with world shards, ``sender``'s part of them): counted, recorded, and (not
        replaying) made durable and reported, once every part of the tick is in. ``raw``: the message as it came,
        handed to the port with the tick's others once the tick is counted.

        Raises:
            Rejected: malformed, out of range, or not the world's next rows; nothing was taken.
            RunFailed: rows the checks passed that the view could not take (a gap in the checks), or world
                shards whose parts of a tick overlap.
        """
        if self.outcome is not None:
            return
        tick, rows = checked_robots(self.view, msg, self.world_radius, part=self.shards > 1)
        if tick <= self.last:
            return  # again (a late-matched reader's history, a restarted world's last ticks)
        with self.held.holding(tick, self.last, (ROBOTS, sender), raw):
            if self.shards == 1 and self.every == 1:
                self._count(tick, rows)
                return
            self._ahead(tick)
            self.parts.setdefault(tick, {})[sender] = rows  # a shard's restarted process sends the same again
            self._go_on()

    def tally(self, data, sender: str = "", raw: bytes = b"") -> None:
        """The world's tally of a tick (the run's robots by state; ``record_every`` > 1; with world shards, shard
        0's): the tick is counted once it is in (and at a tick whose rows go out, every part of those).

        Raises:
            Rejected: malformed, too far ahead, or from another world process.
            RunFailed: the world publishes the robots every other number of ticks than this monitor was told.
        """
        if self.outcome is not None:
            return
        if sender != self.tallier:
            raise Rejected("unexpected sender", f"a tally from {sender!r}: {self.tallier} sends the run's")
        tick, every, counts = tally_values(data, self.params.robots)
        if every != self.every:
            self._mismatch(every)
        if tick <= self.last:
            return
        with self.held.holding(tick, self.last, (TALLY, sender), raw):
            self._ahead(tick)
            self.tallies[tick] = counts
            self._go_on()

    def _mismatch(self, every: int) -> None:
        raise RunFailed(
            f"the world records the robots every {every} ticks and this monitor was told every {self.every}: "
            f"give the world and the monitor the same record_every"
        )

    def _ahead(self, tick: int) -> None:
        if tick > self.last + PARTS_AHEAD:
            raise Rejected("future tick", f"tick {tick}; the monitor has counted up to {self.last}")

    def _go_on(self) -> None:
        """Count every tick whose messages are all in, in order."""
        while self.outcome is None:
            tick = self.last + 1
            parts = self.parts.get(tick, {})
            if self.every == 1:  # world shards' parts of every tick's changed rows
                if len(parts) < self.shards:
                    return
                self._count(tick, self._joined(tick, parts))
                continue
            counts = self.tallies.get(tick)
            if counts is None:
                return
            ends = self._outcome(tick_metrics(tick, counts, self.shape.patches), int(counts[_REMOVED])) is not None
            recorded = tick % self.every == 0 or ends
            if recorded and len(parts) < self.shards:
                return
            if recorded:
                self._leap(tick, self._joined(tick, parts), counts)
            self.tallies.pop(tick)
            self._counted(tick, counts, recorded)

    def _joined(self, tick: int, parts: dict[str, np.ndarray]) -> np.ndarray:
        """The parts of ``tick`` in id order, as the one world sends them (the view takes them so in under half
        the time: its writes stay in cache; each part's ids ascend, the sort merges runs). RunFailed: a robot twice."""
        del self.parts[tick]
        joined = np.concatenate(list(parts.values()))
        ids = joined["id"]
        if not (ids[1:] > ids[:-1]).all():
            joined = joined[np.argsort(ids, kind="stable")]
            if (joined["id"][1:] == joined["id"][:-1]).any():
                raise RunFailed(f"tick {tick}: the world shards' parts hold a robot twice")
        return joined

    def _leap(self, tick: int, rows: np.ndarray, counts: np.ndarray) -> None:
        """Every robot's row at ``tick`` (``record_every`` > 1) into the view, which must agree with the
        tallies of the tick.

        Raises:
            RunFailed: the rows are not every robot once, cannot follow the rows before, or do not give the
                world's tallies (a world that disagrees with itself).
        """
        pose = checks.pose_of(rows)
        why = self.view.leap(tick, rows["id"], rows["state"], **pose)
        if why is not None:
            raise RunFailed(f"tick {tick}: the world's rows {why}")
        got = np.bincount(self.view.state.state, minlength=STATE_COUNT)
        if not np.array_equal(got, counts):
            raise RunFailed(
                f"tick {tick}: the world's rows hold {got.tolist()} robots by state, its tallies {counts.tolist()}"
            )

    def _outcome(self, metrics: TickMetrics, removed: int) -> Outcome | None:
        p = self.params
        return outcome_of(metrics, self.shape.patches, p.robots - removed, p.max_ticks)

    def _count(self, tick: int, rows: np.ndarray) -> None:
        """Count a tick's changed rows (checked), whole (``record_every`` 1)."""
        apply_robots(self.view, tick, rows)
        self._counted(tick, np.bincount(self.view.state.state, minlength=STATE_COUNT), True)

    def _counted(self, tick: int, counts: np.ndarray, recorded: bool) -> None:
        """Tick ``tick`` is counted: ``counts``, its robots by state; ``recorded``: the view holds it."""
        if self.started_at is None:
            self.started_at = self.clock()
        self.last = tick
        metrics = tick_metrics(tick, counts, self.shape.patches)
        removed, removed_before = int(counts[_REMOVED]), self.removed
        self.rows.append(metrics)
        joined = len(self.rows) < 2 or metrics[_LOCALIZED] != self.rows[-2][_LOCALIZED]
        self.occupancy_changed |= joined or removed > removed_before
        self.outcome = self._outcome(metrics, removed)  # (before the port hears of the tick: it reports the end)
        if not self.replaying:
            occupancy = self.view.state.occupancy if recorded else None
            changed, messages = recorded and self.occupancy_changed, self.held.pop(tick)
            self.port.tick_counted(tick, metrics, occupancy, len(self.rows) == 1, changed, messages)
        if recorded:
            self.occupancy_changed = False
        if removed > removed_before:
            self.losses.append((tick, removed - removed_before))
            self.removed = removed
        if self.recorder is not None:
            self.recorder.metrics([metrics])
            if recorded:
                self.recorder.robots(self.view.state, force=self.outcome is not None)
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
        """One status message of the world's, or of world shard ``sender``'s (its values, its stamp's tick).

        Raises:
            RunFailed: the world sends the robots every other number of ticks than this monitor was told (it
                says so before tick 0): the monitor would wait for tallies that never come, or refuse them.
        """
        every = values.get("record_every", "")
        if every.isdigit() and int(every) != self.every:
            self._mismatch(int(every))
        for at, node in self.world.update(values, sender):
            self.log.warn(f"{node} was restarted at tick {at}")
            if self.recorder is not None and not self.recorder.closed:
                self.recorder.event(at, restart_event(at, node))
        if self.world.outcome is not None and self.world_end is None:
            self.world_end = (self.clock(), tick)

    # -- the clock --------------------------------------------------------------------
    def bag_complete(self) -> bool:
        """Whether the last tick's decisions are in: they may arrive after the world's last rows."""
        last = self.last
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
        if bag and not self.bag_complete():
            self.log.warn(
                f"the last tick's decisions did not all come within {BAG_WAIT:g} s: the bag is written without "
                f"{self.rows[-2][_MOVING] - self.decided_rows.get(self.last, 0)} of them"
            )
        if self.world.outcome is not None and self.world.outcome != self.outcome.value:
            raise RunFailed(
                f"the world reports '{self.world.outcome}', the monitor counted "
                f"'{self.outcome.value}' at tick {self.last}"
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
                f"robots' messages reached the monitor only up to tick {self.last} within "
                f"{STATUS_WAIT:g} s"
            )

    # -- the end ----------------------------------------------------------------------
    def record(self, rejected: int, outcome: Outcome | None = None) -> RunRecord:
        """The run's record as counted (``outcome``: another than the count's, for a run stopped before its end);
        ``rejected``: the messages the monitor dropped. A run stopped between two ticks whose rows came
        (``record_every`` > 1) is recorded up to the last of them: its files then agree with each other (the bag
        holds the ticks counted after it)."""
        wall = self.wall if self.outcome is not None else self.clock() - (self.started_at or self.clock())
        upto = self.view.tick  # stopped after the last tick whose rows came (record_every): the run up to it
        return self.world.record(
            self.shape,
            self.params,
            self.view.state,
            self.rows[: upto + 1],
            outcome or self.outcome,
            wall,
            [(tick, n) for tick, n in self.losses if tick <= upto],
            rejected,
            monitor=(self.incarnation, self.resumed_at),
            shards=self.shards,
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
        self.resumed_at = max(self.last, 0)
