"""The world's side of a central world's run in the ROS 2 graph, as plain code (no rclpy): tick 0, each settled tick
sent within the monitor's reach and ``tick_rate``, the records, checkpoints, status and the end
(:class:`CentralWorld`), over the batches' side (:class:`~swarm_ros.protocol.central_lockstep.CentralLockstep`:
which batches are in, what each is sent, when a tick is settled). A central world is one process holding every
robot (:mod:`swarm_ros.core.strips`): the rubenstein algorithm's, and a plug-in's.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from swarm_ros.core.errors import Rejected, RunFailed
from swarm_ros.core.params import MAX_TICKS, auto_every
from swarm_ros.core.strips import CentralRun

from . import central_checkpoint as checkpoint
from .central_checkpoint import SAVE_TICKS, SHARD_SAVE_TICKS, save_every
from .central_lockstep import CentralLockstep
from .central_rows import Wire, metrics_rows
from .checks import Rejections, held_report
from .plan import CENTRAL_KEPT as KEPT
from .plan import MONITOR, WORLD, shard_name
from .status import RUNNING, STARTING, progress_values, restarts_of, restarts_text
from .world_port import LOSS_CONFIRM_S, STALL_S, STATUS_PERIOD, Watch

#: seconds, at most, for the last messages to be acknowledged before exiting, when the world waits for no monitor
LINGER = 5.0
_CLOCK = "clock"  #: in a checkpoint: the run's wall clock at tick 0 and its startup seconds
_RESTARTS = "restarts"  #: in a checkpoint: the restarts so far (:func:`~swarm_ros.protocol.status.restarts_text`)


def monitor_reach(window: int, every: int) -> int | None:
    """How many ticks past the last tick the monitor holds (durably, in its bag) the world may publish, with the
    world parameter ``monitor_window`` ``window`` and a record every ``every`` ticks: at least one record (the monitor
    reports a tick only once its record is in), at most ``KEPT - 2`` (the messages since stay in the topics'
    histories for a restarted monitor); None with ``window`` 0: the world does not wait for a monitor."""
    return None if window == 0 else min(max(window, every), (KEPT - 2) * every)


def check_held(values: np.ndarray, run: CentralRun) -> tuple[int, bool]:
    """The monitor's report on /swarm/held (:func:`~swarm_ros.protocol.checks.held_report`), of any tick (a restarted
    world's monitor may be past it: a checkpoint is every 1,000 ticks or so); the outcome only with the run's last.

    Raises:
        Rejected: ("held") anything else.
    """
    tick, ended = held_report(values, MAX_TICKS)
    if ended and (run.outcome is None or tick != run.tick):
        raise Rejected("held", f"the end at tick {tick}; the run is at tick {run.tick}, outcome {run.outcome}")
    return tick, bool(ended)


class CentralWorld:
    """The world node's logic, on a :class:`CentralLockstep`: tick 0 once the strips tile the grid and the monitor
    reads the run's topics; each settled tick sent unless it is past the monitor's reach (``monitor_window`` past
    the last record the monitor reports held: :func:`monitor_reach`), and at most ``tick_rate`` ticks a second if
    set; a checkpoint every :func:`save_every` ticks (1,000 or so; a world shard's, 100 or so), before the tick
    goes out; the records (every robot's row and the metrics rows since the last) every ``record_every`` ticks and
    at the end; the peers' liveliness and a still run's failure (:class:`Watch`);
    the end once the monitor holds it and every reader of the status has the outcome (with no window, once its
    readers have everything), or ``LINGER`` after it at most for what the readers still lack.
    A batch whose liveliness lapsed is waited for while the launcher restarts it (``on_batch_loss: restart`` and
    restarts left, by the incarnations it announced); otherwise, for an algorithm whose robots can be removed
    (``removes``), it is removed (:meth:`CentralLockstep.remove_batch`) unless it is back within
    :data:`~swarm_ros.protocol.world_port.LOSS_CONFIRM_S` (a new process of it confirms the loss at once), and the
    world saves a checkpoint then.

    Its port (the world node) sends what it decides: ``watch_batch(name)`` (the batch's area writers, decisions
    reader and liveliness), ``send_area(name, tick, rows, whole)`` (its whole view, or the changes),
    ``publish_record(tick, metrics_rows, robot_rows)``, ``publish_clock(tick)`` (each tick as it goes out),
    ``publish_status(tick, outcome, message, values)`` (the status's values, as the study's model's world gives
    them: ``waiting_for``, ``rejected_messages``, ``rejected``; from tick 0 ``startup_seconds`` and the run's
    progress, ten a second; at the end ``wall_seconds``), and answers ``monitor_reads()`` (the monitor reads the
    run's topics; ``monitor_seen()``: who reads them, for an error), ``delivered()`` (every reader has the last
    messages), ``told()`` (every reader of the status, each batch too, has the last status) and
    ``startup_seconds()`` (from the start of the run's command, or of this process, to now). ``rejections``: the
    messages its node dropped."""

    def __init__(
        self,
        run: CentralRun,
        wire: Wire,
        own: dict,
        port: Any,
        log: Any,
        rejections: Rejections,
        clock: Callable[[], float] = time.monotonic,
        lockstep: CentralLockstep | None = None,
        removes: bool = False,
    ) -> None:
        self.ls = lockstep or CentralLockstep(run, wire)  # a world shard's: central_shard_world.ShardLockstep
        self.ls.on_settled = self._settled
        self.port, self.log, self.rejections, self.clock = port, log, rejections, clock
        self.every = int(own["record_every"]) or auto_every(run.params)
        sharded = self.ls.shard_index is not None
        self.save_every = save_every(self.every, SHARD_SAVE_TICKS if sharded else SAVE_TICKS)
        self.reach = monitor_reach(int(own["monitor_window"]), self.every)
        self.checkpoint = Path(str(own["checkpoint"])) if own["checkpoint"] else None
        self.start_timeout = float(own["start_timeout"])
        rate = float(own.get("tick_rate", 0.0))
        self.period, self.paced_at = (1.0 / rate if rate else 0.0), 0.0  # tick_rate: a run paced to watch it live
        self.created = clock()
        self.held, self.held_end = -1, False  # the monitor's last held record, and whether it holds the outcome
        self.pending = False  # a settled tick waits for the monitor to catch up before it goes out
        self.sent_metrics = -1  # the last tick whose metrics row went out
        self.first = True  # the first tick this process publishes is still to go out
        self.watched: set[str] = set()  # the batches whose endpoints the port made
        self.waiting: list[int] = []  # batches announced before the monitor read the run's topics
        self.fresh: set[int] = set()  # batch processes that came back while a tick waited: sent it whole
        self.started_at: float | None = None  # clock() at tick 0 (a resumed world's: as its checkpoint says)
        self.started_wall = 0.0  # time.time() at tick 0, saved in the checkpoint
        self.startup = 0.0  # seconds from the start of the run's command to tick 0 (port.startup_seconds)
        self.ended_at: float | None = None
        self.status_at = 0.0  # when the last status went out
        self.finished = False
        self.watch = Watch(self.created)
        self.removes = removes and (own.get("on_batch_loss") == "remove", int(own.get("max_restarts", 0)))
        self.incarnations: dict[str, int] = {}  #: batch name -> the last incarnation it announced
        #: batch name -> the process that last announced it (its messages' nonce, :mod:`swarm_ros.protocol.tag`)
        self.processes: dict[str, str] = {}
        #: batch name -> when a new process of it announced itself, until DDS reports its liveliness (:meth:`_unseen`)
        self.unseen: dict[str, float] = {}
        #: batch name -> when its loss is confirmed, unless it is back, and why then
        self.losing: dict[str, tuple[float, str]] = {}
        index = self.ls.shard_index
        self.name = WORLD if index is None else shard_name(index)
        #: (tick, node) of each restart of this process and of its batches' (the status's ``restarts``; saved)
        self.restarts: list[tuple[int, str]] = []
        if int(own["incarnation"]):  # a restarted process: on from the last checkpoint
            self._resume(int(own["incarnation"]))

    @property
    def run(self) -> CentralRun:
        return self.ls.run

    def _resume(self, incarnation: int) -> None:
        """Go on from the checkpoint the process before saved: the run at its tick, the batches it served (their
        announcements, latched, come again and are sent their areas of that tick), and the metrics rows from the
        last record before it sent again (the monitor drops what it holds). A world shard's peers wait for it; what
        they sent it since, their topics keep (:func:`~swarm_ros.protocol.central_checkpoint.shard_kept`).

        Raises:
            RunFailed: no checkpoint to go on from, or one that is not of this run.
        """
        if self.checkpoint is None:
            raise RunFailed("a restarted world has no checkpoint to go on from (the checkpoint parameter is empty)")
        if not self.checkpoint.exists():  # tick 0 is saved before anything of it goes out: nothing did
            self.log.info("restarted before tick 0 went out: the run starts from tick 0")
            self.restarts = [(0, self.name)] * incarnation
            return
        saved = checkpoint.load(self.checkpoint, self.run)
        kept = dict(saved.kept)
        self.restarts = restarts_of(str(kept.pop(_RESTARTS, "")))
        self.restarts += [(saved.tick, self.name)] * max(1, incarnation - sum(n == self.name for _, n in self.restarts))
        for _, name in self.restarts:
            if name != self.name:
                self.incarnations[name] = self.incarnations.get(name, 0) + 1
        if _CLOCK in kept:
            self.started_wall, self.startup = (float(v) for v in kept.pop(_CLOCK))
            self.started_at = self.clock() - max(0.0, time.time() - self.started_wall)
        self.ls.resume(saved.hosts, saved.cuts, kept, before=saved.tick + self.save_every)
        self.sent_metrics = saved.tick - self.every if saved.tick else -1
        self.log.info(f"restarted: on from the checkpoint of tick {saved.tick}")

    # -- what comes in ----------------------------------------------------------------------
    def batch(self, name: str, strip: tuple[int, int], incarnation: int = 0, process: str = "") -> None:
        """Node ``name`` (its process ``incarnation``; ``process``: the nonce of that process's messages, "" for
        unknown) announced the columns ``strip`` (:meth:`CentralLockstep.announce`); a new process of a batch being
        lost confirms the loss.

        Raises:
            Rejected: a strip that does not fit the run, or a batch removed.
        """
        k = self.ls.number(name)
        if k is not None and k in self.ls.removed:
            raise Rejected("removed batch", f"{name}'s robots were removed; the world decides its strip")
        if name in self.losing and incarnation > self.incarnations.get(name, 0):
            self.losing[name] = (self.clock(), "a new process of it announced itself")
            self._remove(name)
            raise Rejected("removed batch", f"{name}'s robots were removed; the world decides its strip")
        before = self.incarnations.get(name, 0)
        self.incarnations[name] = max(incarnation, before)
        send = self.ls.announce(name, strip)
        k = self.ls.number(name)
        # a new process: a later incarnation, or one started with the same command (ros2 launch's respawn), whose
        # messages carry another nonce; an announcement heard again (latched) is not. (Not the liveliness lapse of
        # the process before: CI saw the new process announce itself before the world heard of that lapse.)
        known = self.processes.get(name)
        if process:
            self.processes[name] = process
        replaced = bool(process) and known is not None and known != process and self.ls.started
        again = incarnation - before if incarnation > before else int(replaced)
        if again:  # a new process: not the one whose liveliness lapsed; until DDS reports this one's, _unseen
            self.watch.replaced(name)  # watches it (one killed before its writer matched reports no lapse)
        if again or name not in self.watched:
            self.unseen[name] = self.clock()
        if again and (self.ls.shard_index is None or k in self.ls.mine):  # its own batches only
            self.restarts += [(max(self.run.tick, 0), name)] * again
            n = sum(r == name for _, r in self.restarts)
            self.log.warning(f"{name} is back (restart {n}) at tick {self.run.tick}; sending it its area")
        if name not in self.watched:
            self.watched.add(name)
            self.port.watch_batch(name)
        self.waiting += send
        self.log.info(f"{name}: columns {strip[0]}..{strip[1]}")

    def decisions(self, name: str, tick: int, rows: np.ndarray) -> None:
        """Node ``name``'s decisions for ``tick`` (checked as rows by the caller).

        Raises:
            Rejected: decisions that cannot be that batch's for the tick being decided.
        """
        k = self.ls.number(name)
        if self.run.outcome is not None or self.first or k is None:  # before its first tick: the process before's
            return
        if self.ls.decisions(k, tick, rows):
            self._settled()

    def _settled(self) -> None:
        self.pending = True
        self._go_on()

    def held_report(self, values: np.ndarray) -> None:
        """The monitor's report on /swarm/held (:func:`check_held`).

        Raises:
            Rejected: ("held") a report that cannot be of this run.
        """
        tick, ended = check_held(values, self.run)
        if tick > self.held or ended > self.held_end:
            self.watch.moved(self.clock())
        self.held, self.held_end = max(self.held, tick), self.held_end or ended
        self._go_on()

    def liveliness(self, name: str, alive: int, not_alive: int) -> None:
        if alive > 0:
            self.unseen.pop(name, None)
        said = self.watch.liveliness(name, alive, not_alive)
        if said is not None:
            self._heard(name, said)

    def _unseen(self, now: float) -> None:
        """A batch process that dies before DDS matched its liveliness writer has no lapse to report (CI saw a
        restarted batch killed half a second after it announced itself, under load): one whose liveliness is still
        unseen ``STALL_S`` after it announced itself, while the run has waited ``STALL_S`` for its decisions, is
        lost as if it had lapsed. (Should it be alive after all, its liveliness says so when it comes.)"""
        awaited = None
        for name, since in list(self.unseen.items()):
            if now - max(since, self.watch.moved_at) < STALL_S or name in self.watch.lapsed:
                continue
            awaited = self.ls.awaited() if awaited is None else awaited
            if name in awaited:
                del self.unseen[name]
                self.watch.unheard(name)
                self._heard(
                    name, f"{name} was lost (no liveliness and no decisions for {STALL_S:g} s): the run waits for it"
                )

    def _heard(self, name: str, said: str) -> None:
        """What the world does when peer ``name``'s liveliness lapsed or came back (``said``)."""
        if name in self.watch.lapsed:  # (a logger method picked by a conditional expression and called in an rclpy
            self.log.warning(said)  # event callback crashed the process inside rclpy, 3 runs of 3)
        else:
            self.log.info(said)
            self.losing.pop(name, None)  # back in time: a pause, not a loss
        if self.ended_at is None:
            self.status(RUNNING if self.ls.started and not self.first else STARTING, said)
        k = self.ls.number(name)
        if name in self.watch.lapsed and self.removes and k is not None and k not in self.ls.removed:
            remove, restarts = self.removes
            if remove or self.incarnations.get(name, 0) >= restarts:  # lost for good, unless back in time
                self.losing[name] = (self.clock() + LOSS_CONFIRM_S, f"not back within {LOSS_CONFIRM_S:g} s")

    def _remove(self, name: str) -> None:
        """Batch ``name`` is lost for good (``losing``): its robots are removed at the end of the next tick, the
        world decides its strip from then on, and a checkpoint says so. A world shard whose tick is half settled
        removes it once the tick is closed (the next poll)."""
        k = self.ls.number(name)
        if k is not None and self.run.outcome is None and not self.ls.can_remove():
            return
        _, why = self.losing.pop(name)
        if k is None or self.run.outcome is not None:
            return
        ids = self.ls.remove_batch(k)
        said = f"{name} lost for good ({why}): its {ids.size} robots are removed at the end of tick {self.run.tick + 1}"
        self.log.warning(said)
        self.status(RUNNING, said)
        if self.checkpoint is not None:
            self._save()
        if self.ls.ready() and not self.pending:  # its decisions were the last awaited
            if self.ls.settle():
                self._settled()

    # -- what goes out ----------------------------------------------------------------------
    def _go_on(self) -> None:
        """Send the settled tick, unless it is past the monitor's reach (then once the monitor reports more held), or
        sooner than ``tick_rate`` allows (then when :meth:`wake_in` says)."""
        if self.pending and (self.reach is None or self.run.tick <= self.held + self.reach):
            if self.period:  # tick_rate: each tick goes out at least a period after the one before
                now = self.clock()
                if now < self.paced_at:
                    return
                self.paced_at = now + self.period
            self.pending = False
            self._publish_tick()

    def wake_in(self) -> float | None:
        """Seconds until the settled tick may go out under ``tick_rate`` (the node polls by then); None: nothing
        waits for the clock."""
        if not self.period or not self.pending:
            return None
        return max(0.0, self.paced_at - self.clock())

    def _send_areas(self, batches: list[int], whole: set[int]) -> None:
        for k, (rows, entire) in self.ls.areas(batches, whole).items():
            self.port.send_area(self.ls.hosts[k], self.run.tick, rows, entire)

    def _publish_tick(self) -> None:
        run = self.run
        tick, ended = run.tick, run.outcome is not None
        self.watch.moved(self.clock())
        self.port.publish_clock(tick)
        if self.checkpoint is not None and not ended and tick % self.save_every == 0:  # before the tick goes out
            self._save()
        if ended or tick % self.every == 0:
            robots = self.ls.wire.rows(self.ls.recorded(), run.robots)
            metrics = metrics_rows(run.history[self.sent_metrics + 1 :], run.columns)
            self.port.publish_record(tick, metrics if not self.ls.shard_index else None, robots)  # shard 0's
            self.sent_metrics = tick
        if ended:
            self.ended_at = self.clock()
            said = f"the run ended at tick {tick}: {run.outcome}"
            self.status(str(run.outcome), said)
            self.log.info(said)
        else:
            self._send_areas(self.ls.mine, self.fresh)
            self.fresh = set()

    def _save(self) -> None:
        assert self.checkpoint is not None
        clock = {_CLOCK: np.array([self.started_wall, self.startup])}  # the run's, for a restarted world
        clock[_RESTARTS] = np.array(restarts_text(self.restarts))
        checkpoint.save(self.checkpoint, self.run, self.ls.hosts, self.ls.cuts, {**self.ls.kept(), **clock})

    def status(self, outcome: str, message: str) -> None:
        self.status_at = self.clock()
        values: dict[str, object] = {
            "waiting_for": ",".join(sorted(self.watch.lapsed)),
            "rejected_messages": self.rejections.total,
            "rejected": self.rejections.text(),
            "restarts": restarts_text(self.restarts),
        }
        if self.started_at is not None:
            values["startup_seconds"] = f"{self.startup:.3f}"
            values.update(progress_values(self.run.progress()))  # (its tick is the one published, or the end)
            row = self.run.history[-1]  # the tick's metrics by name, as metrics.csv has them (the status has the tick)
            values.update(
                {n: int(v) if float(v).is_integer() else v for n, v in zip(self.run.columns[1:], row[1:].tolist())}
            )
            values["robots"] = self.run.params.robots
        if self.started_at is not None and self.ended_at is not None:
            values["wall_seconds"] = f"{self.ended_at - self.started_at:.3f}"
        self.port.publish_status(self.run.tick, outcome, message, values)

    # -- between messages ---------------------------------------------------------------------
    def poll(self) -> None:
        """Tick 0 (or a resumed world's tick) once every batch is in and the monitor reads; a batch process that
        came back sent its area; the start timeout and a still run; whether the node may exit.

        Raises:
            RunFailed: the batches did not all announce themselves within ``start_timeout``, or the run is still.
        """
        now = self.clock()
        if self.ls.started and not self.first and not self.pending and self.run.outcome is None:
            self._unseen(now)  # (a tick held for the monitor awaits no batch)
        for name, (due, _) in list(self.losing.items()):
            if now >= due:
                self._remove(name)
        if self.ls.started and not self.first and not self.pending and self.ls.ready():  # every batch removed
            if self.ls.settle():
                self._settled()
        self._go_on()  # a tick held for tick_rate, due now
        if not self.first and self.ended_at is None and now - self.status_at >= STATUS_PERIOD:
            self.status(RUNNING, RUNNING)  # ten a second: the launcher's progress bar follows them
        heard = self.ls.started and all(name in self.watched for name in self.ls.hosts.values())  # resumed: all
        if self.waiting and heard and (not self.first or self.port.monitor_reads()):
            batches, self.waiting = sorted(set(self.waiting)), []
            if self.first:  # tick 0, or the checkpoint's: the robots, the metrics and the areas
                self.first = False
                if self.started_at is None:  # (a resumed world's is the run's, from its checkpoint)
                    self.started_at, self.startup = now, self.port.startup_seconds()
                    self.started_wall = time.time()
                said = f"{len(self.ls.mine)} robot batches in: tick {self.run.tick}"
                self.status(RUNNING, said)
                self.log.info(f"{said} goes out")
                self.pending = True
                self._go_on()
            elif not self.pending:  # a batch process that came back: its whole view at the current tick
                self._send_areas(batches, set(batches))
            else:  # (a tick waiting for the monitor goes to every batch when it does: to these, whole)
                self.fresh.update(batches)
        if not self.ls.started and now - self.created > self.start_timeout:
            raise RunFailed(f"robot batches did not all announce themselves within {self.start_timeout:g} s")
        if self.ls.started and self.ended_at is None and self.watch.still(now):  # for STILL_S
            unheard = [name for name in self.ls.hosts.values() if name not in self.watched]  # a resumed world's
            awaited = (unheard or [MONITOR]) if self.first or self.pending else self.ls.awaited()
            if self.first and not unheard and self.waiting:  # its first tick waits for the monitor to read
                awaited = [f"{MONITOR}, whose readers this world's ROS graph lists as {self.port.monitor_seen()}"]
            raise self.watch.failure(self.run.tick, awaited, self.rejections.text())
        if self.ended_at is not None and self.reach is not None:  # the monitor holds the end: nothing more to keep
            # and each batch has the outcome it stops on (the status of a world that exited is lost to a batch
            # that had not acknowledged it: the batch then ran on until the launcher stopped it)
            if self.held_end:
                self._finish(self.port.told(), now - self.ended_at, "the outcome in the status")
        elif self.ended_at is not None:
            self._finish(self.port.delivered(), now - self.ended_at, "the last messages")

    def _finish(self, acknowledged: bool, since_end: float, what: str) -> None:
        """Finished once every reader ``acknowledged`` ``what``, or ``LINGER`` after the end at most (saying so)."""
        self.finished = acknowledged or since_end > LINGER
        if not acknowledged and self.finished:  # a reader of a process that died, until DDS forgets it (3 s)
            self.log.warning(f"exits {LINGER:g} s after the end with {what} unacknowledged by a reader")
