"""A world shard's save: what a restarted shard process goes on from, written at every close for the rows that
changed only.

It is the world's :class:`~swarm_ros.protocol.checkpoint.Checkpoint` (one mapped file; a tick written so that a
kill at any instruction leaves it recoverable), holding the shard's view: every robot's last row as the shard
knew it (its area's moving robots, every stationary one; ``UNKNOWN_ROW`` for one it never knew), the metrics of
every tick (which every shard holds alike), a ring of the last ticks' rows, of which the first ones of each
tick are what the shard published for the monitor, and the messages it sent its peers for the kept ticks
(claims and part rows for each shard, its counts), each tick's written once, in place, at its close and before
the tick's rows, so a save never lacks the messages of the tick it holds. Beside it, ``<file>.json``: the
lockstep's bookkeeping with the robots pending removal and every robot removed so far, written whole when it
changes.

Like the world's checkpoint, these are the shard's own files in the run's log directory, read back only by a
process of the same shard.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from swarm_ros.core.errors import Rejected, RunFailed
from swarm_ros.core.metrics import METRIC_COLUMNS
from swarm_ros.core.params import RunParams
from swarm_ros.core.regions import columns
from swarm_ros.core.shard_parts import COUNTS
from swarm_ros.core.shards import ShardPlan, ShardSaved
from swarm_ros.core.state import IS_MOVING
from swarm_ros.protocol.checkpoint import Checkpoint
from swarm_ros.protocol.rows import decision_row, decision_rows, decisions_of, pose_of
from swarm_ros.protocol.shard_exchange import KEPT_TICKS, ExchangeSaved
from swarm_ros.protocol.shard_rows import assemble, counts_data, counts_of, part_row, part_rows

UNKNOWN_ROW = 255  #: the state byte of a robot the shard never knew, in its save's rows
_LOCALIZED = METRIC_COLUMNS.index("localized")


@dataclass
class ShardSave:
    """What a restarted shard process goes on from: its exchange's save, the lockstep's bookkeeping, the robots
    pending removal, the ticks it published that the monitor may not have confirmed (tick -> rows, applied, tally),
    and the newest tick the monitor confirmed."""

    exchange: ExchangeSaved
    book: dict
    pending: np.ndarray
    ring: dict[int, tuple[np.ndarray, np.ndarray | None, np.ndarray]]
    monitor_tick: int


class ShardSaver:
    """Shard ``index``'s save files at ``path`` (see the module's docstring)."""

    def __init__(self, path: Path, params: RunParams, plan: ShardPlan, index: int, slots: int, dims: int) -> None:
        self.path, self.params, self.plan, self.index, self.dims = Path(path), params, plan, index, dims
        self.slots = slots
        self.decision, self.part = decision_row(dims), part_row(dims)
        shards, robots = plan.shards, params.robots
        # a tick's kept messages: claims to each shard, part rows to each shard, the counts. None holds a robot
        # twice (its claim or row goes to each of up to S - 1 peers), the counts at most every robot removed
        room = shards * robots * (self.decision.itemsize + self.part.itemsize) + (2 + len(COUNTS) + robots) * 8
        self.kept = (2 * shards + 1, room) if shards > 1 else (0, 0)  # a shard alone (the world) sends none
        self.checkpoint: Checkpoint | None = None

    def _args(self) -> tuple[Path, int, int, int]:
        return (self.path, self.params.robots, self.params.max_ticks, len(METRIC_COLUMNS))

    def create(self) -> None:
        """Make the files for a shard's first process (never over existing ones).

        Raises:
            RunFailed: they cannot be made.
        """
        try:
            self.checkpoint = Checkpoint(*self._args(), self.slots, self.dims, self.kept)
            self.checkpoint.create()
        except OSError as exc:
            raise RunFailed(f"checkpoint {self.path}: {getattr(exc, 'strerror', None) or exc}") from None

    def write_tick(
        self,
        tick: int,
        rows: np.ndarray,
        published: int,
        applied: np.ndarray | None,
        metrics: tuple[int, ...],
        sent: dict,
        tally: np.ndarray | None = None,
    ) -> None:
        """Save tick ``tick``: its kept messages first (``sent[tick]``, none at tick 0: those of the ticks before
        are in the file already), then the rows that changed in the shard's view (the first ``published`` of them
        its part for the monitor), the applied decisions, the tick's metrics and the tally it publishes
        (``record_every`` > 1)."""
        assert self.checkpoint is not None  # created or opened
        try:
            if tick in sent and self.kept[0]:
                claims, parts = sent[tick]
                rows_of = [decision_rows(c) for c in claims] + [part_rows(p, self.dims) for p in parts]
                self.checkpoint.write_kept(tick, [*rows_of, counts_data(parts[0])])
            self.checkpoint.write(tick, rows, applied, np.asarray(metrics, dtype=np.int64), published, tally)
        except OSError as exc:
            raise RunFailed(f"checkpoint {self.path}: {getattr(exc, 'strerror', None) or exc}") from None

    def _sent(self, tick: int) -> dict:
        """The messages kept at tick ``tick``'s close: its own and the tick's before (tick 0 has none).

        Raises:
            Rejected: the file lacks them, or they are not whole.
        """
        assert self.checkpoint is not None
        sent, shards = {}, self.plan.shards
        for t in range(max(1, tick - KEPT_TICKS + 1), tick + 1) if self.kept[0] else ():
            chunks = self.checkpoint.kept(t)
            if chunks is None:
                raise Rejected("incomplete save", f"no kept messages of tick {t}")
            claims = [decisions_of(t, c.view(self.decision)) for c in chunks[:shards]]
            counts = counts_of(chunks[-1].view(np.int64), self.params.robots, shards)
            parts = [assemble(t, self.index, c.view(self.part), counts) for c in chunks[shards:-1]]
            sent[t] = (claims, parts)
        return sent

    def save_book(self, book: dict) -> None:
        if self.checkpoint is not None:
            self.checkpoint.save_book(book)

    def monitor_reported(self, tick: int) -> None:
        if self.checkpoint is not None:
            self.checkpoint.monitor_reported(tick)

    def remove(self) -> None:
        """Remove the save's files (the run is over or stopped: no process of this shard will restart)."""
        if self.checkpoint is not None:
            self.checkpoint.remove()

    def restore(self) -> ShardSave | None:
        """Open the save a process of this shard before this one wrote; what it holds (None: no tick yet).

        Raises:
            RunFailed: the files are not a save of this run, or are incomplete.
        """
        self.checkpoint = Checkpoint.open(*self._args(), self.dims, self.kept)
        saved = self.checkpoint.saved()
        if saved is None:
            return None
        b = saved.book
        try:
            sent = self._sent(saved.tick)
            pending = np.asarray(b["pending"], np.int64)
            removals = [np.asarray(ids, np.int64) for t, ids in b["removals"] if t <= saved.tick]
        except (KeyError, ValueError, Rejected) as exc:
            raise RunFailed(f"checkpoint {self.path}: incomplete ({exc})") from None
        rows, first, last = saved.robots, *self.plan.areas[self.index]
        pose = pose_of(rows)
        state = rows["state"]
        known = state != UNKNOWN_ROW
        cols = columns(pose["x"], self.plan.radius)
        keep = np.flatnonzero(known & (~IS_MOVING[np.where(known, state, 0)] | ((cols >= first) & (cols <= last))))
        losses = [(int(t), int(n)) for t, n in b.get("losses", []) if t <= saved.tick]  # a book ahead of its tick
        removed = np.concatenate(removals) if removals else np.empty(0, np.int64)
        history = saved.history
        shard = ShardSaved(
            tick=saved.tick,
            ids=keep,
            state=state[keep].astype(np.int8),
            x=pose["x"][keep],
            y=pose["y"][keep],
            heading=pose["heading"][keep],
            z=pose["z"][keep] if "z" in pose else None,
            pitch=pose["pitch"][keep] if "pitch" in pose else None,
            history=history,
            losses=losses,
            localized=int(history[-1][_LOCALIZED]),
            alive=self.params.robots - sum(n for _, n in losses),
            removed=removed,
        )
        return ShardSave(ExchangeSaved(shard, sent), b, pending, saved.ring, saved.monitor_tick)
