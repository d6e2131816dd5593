"""The world's checkpoint: what a restarted world process needs to go on from the last tick it sent.

The world writes it itself, into one file mapped into its memory (:mod:`mmap`), before
anything about a tick leaves the process: a SIGKILL loses nothing written to a shared file
mapping (the pages belong to the kernel's page cache, not the process), so the file holds
every tick up to the one being written. A host that loses power loses it; the graph's fault
model is a process lost, not a machine (docs/faults.md).

Layout: a header of int64s, every robot's row (:data:`~swarm_ros.protocol.rows.ROBOT_ROW`, or the 3D one,
indexed by id), the metrics of every tick, a ring of the last ``slots`` ticks' published
rows (the robots that changed, or every robot at a tick whose rows are recorded when ``record_every`` > 1, and
the decisions applied) and tallies (robots by state, when ``record_every`` > 1), so the new world can send again
the ticks a reader may have lost with the old one (the monitor may be up to ``monitor_window``
ticks behind), and one *redo* area: the rows of the tick being written that were not published (a world shard's
rows of its area's other robots; every changed row at a tick whose rows are not recorded). A tick is written in
an order that a kill at any instruction leaves recoverable: the header's ``writing``, the tick's ring slot and the
redo area, the header's ``ready``, the rows into the robots, the header's ``done``. A restore takes ``done``; if it
finds ``ready`` ahead, it copies that tick's rows (its slot's, then the redo area's) into the robots again (the
same values) and takes ``ready``. One redo area is enough: only the tick at ``ready`` can need it, and the next
tick writes it only after ``done``.

Why the redo area: the ring is ``slots`` times every robot's row, and a tick that wrote all its changed rows into
a slot of its own touched fresh pages of the file every tick (at 50,000 robots about 2 MB a tick, each page a
fault through the file system's journal: a third of the world's CPU). The redo area is rewritten every tick, its
pages stay in memory, and the ring takes only what may have to be sent again.

A world shard's file ends with the messages it sent its peers for the last ticks (``kept``): three slots,
one per tick (by tick modulo 3), each a head of byte lengths and then that tick's messages as rows, written
once, in place, at the tick's close and before its ring slot (a restore reads the two ticks up to the one it
takes, which the slot being written never is). A world alone has none.

The rest of the world's bookkeeping (batches, restarts, losses, times) changes seldom and
goes into ``<file>.json``, written whole to a temporary name and renamed.

The file holds no key and is not signed: it is the world's own, in the run's log directory,
which only the user who runs it can write (the same trust as the parameter file it starts from).
"""

from __future__ import annotations

import json
import mmap
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from swarm_ros.core.errors import RunFailed
from swarm_ros.core.state import STATE_COUNT
from swarm_ros.protocol.rows import decision_row, robot_row

MAGIC = 0x5357524D434B5035  # "SWRMCKP5": the redo area since version 5
_H_MAGIC, _H_ROBOTS, _H_SLOTS, _H_TICKS, _H_COLS, _H_WRITING, _H_READY, _H_DONE, _H_MONITOR = range(9)
_H_KEPT_CHUNKS, _H_KEPT_BYTES = 9, 10  # the kept messages' slots: messages (chunks) per tick, bytes for them
KEPT_SLOTS = 3  #: ticks of kept messages in the file: the two a restore reads, and the one being written
_HEADER = 16  # int64s
#: int64s per ring slot: tick, robot rows, applied rows, published rows (the first of the rows), the tally
_SLOT_HEAD = 4 + STATE_COUNT


@dataclass
class Saved:
    """A checkpoint as read back: the last tick it holds, every robot's row then, the metrics of ticks 0..tick,
    the newest tick the monitor had reported, the ring's ticks (tick -> (robot rows, applied rows or None,
    tally)), and the bookkeeping."""

    tick: int
    robots: np.ndarray
    history: np.ndarray
    monitor_tick: int
    ring: dict[int, tuple[np.ndarray, np.ndarray | None, np.ndarray]]
    book: dict


class Checkpoint:
    """One run's world checkpoint at ``path`` (created empty, or opened to restore from)."""

    def __init__(
        self,
        path: Path,
        robots: int,
        max_ticks: int,
        columns: int,
        slots: int,
        dims: int = 2,
        kept: tuple[int, int] = (0, 0),
    ) -> None:
        """``kept``: (messages, bytes) a tick's kept messages may take (a world shard's; (0, 0): none)."""
        self.path = Path(path)
        self.kept_chunks, self.kept_bytes = kept
        self.row, self.decision = robot_row(dims), decision_row(dims)  # the rows of a world of ``dims`` dimensions
        self.record = np.dtype((np.void, self.row.itemsize))  # a robot's row as opaque bytes (fast to copy by index)
        self.robots, self.ticks, self.columns, self.slots = robots, max_ticks + 1, columns, max(slots, 2)
        self.slot_bytes = _SLOT_HEAD * 8 + robots * (self.row.itemsize + self.decision.itemsize)
        self._offsets()
        self.map = np.empty(0, dtype=np.uint8)  # the file's bytes, once created or opened

    def _offsets(self) -> None:
        self.robots_at = _HEADER * 8
        self.history_at = self.robots_at + self.robots * self.row.itemsize
        self.ring_at = self.history_at + self.ticks * self.columns * 8
        self.redo_at = self.ring_at + self.slots * self.slot_bytes
        self.kept_at = self.redo_at + self.robots * self.row.itemsize
        self.kept_slot = (1 + self.kept_chunks) * 8 + self.kept_bytes if self.kept_chunks else 0
        self.size = self.kept_at + KEPT_SLOTS * self.kept_slot

    # -- writing ----------------------------------------------------------------------
    def create(self) -> None:
        """Make the file (sparse: only what is written takes space) and map it; it holds no tick yet."""
        with open(self.path, "xb") as f:  # never over an existing file
            f.truncate(self.size)
        self._map()
        self._reserve(0, self.history_at)  # the header and the robots; the ring, tick by tick, in write()
        self._reserve(self.redo_at, self.kept_at - self.redo_at)
        h = self.header
        h[_H_ROBOTS], h[_H_SLOTS], h[_H_TICKS], h[_H_COLS] = self.robots, self.slots, self.ticks, self.columns
        h[_H_KEPT_CHUNKS], h[_H_KEPT_BYTES] = self.kept_chunks, self.kept_bytes
        h[_H_WRITING] = h[_H_READY] = h[_H_DONE] = h[_H_MONITOR] = -1
        h[_H_MAGIC] = MAGIC  # last: a header without it was cut off

    def _reserve(self, offset: int, length: int) -> None:
        """Reserve the disk blocks of ``length`` bytes at ``offset``: a write through the mapping into a block the
        file system cannot supply (a full disk) would kill the process with SIGBUS; this raises OSError instead.

        Raises:
            OSError: ENOSPC, naming the file.
        """
        if length <= 0:
            return
        try:
            os.posix_fallocate(self._fd, offset, length)  # a few microseconds where the blocks exist already
        except OSError as exc:
            raise OSError(exc.errno, exc.strerror, str(self.path)) from None

    def _map(self) -> None:
        self._fd = os.open(self.path, os.O_RDWR)  # kept for _reserve; closed with the process
        self._mmap = mmap.mmap(self._fd, self.size)
        self.map = np.frombuffer(self._mmap, dtype=np.uint8)  # a plain array: slicing a np.memmap costs more
        self.header = self.map[: _HEADER * 8].view(np.int64)
        self.rows = self.map[self.robots_at : self.history_at].view(self.row)
        self._records = self.rows.view(self.record)
        self.history = self.map[self.history_at : self.ring_at].view(np.int64).reshape(self.ticks, self.columns)
        self.redo = self.map[self.redo_at : self.kept_at].view(self.row)

    def _slot_head(self, tick: int) -> tuple[np.ndarray, int]:
        """The ring slot of ``tick``: its head (tick, robot rows, applied rows), and where its rows start."""
        at = self.ring_at + (tick % self.slots) * self.slot_bytes
        return self.map[at : at + _SLOT_HEAD * 8].view(np.int64), at + _SLOT_HEAD * 8

    def _slot(self, tick: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        head, at = self._slot_head(tick)
        robots = self.map[at : at + self.robots * self.row.itemsize].view(self.row)
        at += self.robots * self.row.itemsize
        applied = self.map[at : at + self.robots * self.decision.itemsize].view(self.decision)
        return head, robots, applied

    def write(
        self,
        tick: int,
        rows: np.ndarray,
        applied: np.ndarray | None,
        metrics: np.ndarray,
        published: int = -1,
        tally: np.ndarray | None = None,
    ) -> None:
        """Save tick ``tick``: the rows it publishes (robots that changed; at tick 0 all), the decisions it
        applied (None at tick 0, or when they are not published) and its metrics row. Call before anything
        about the tick is sent. ``published``: only the first this many rows were published (a world shard
        saves the rows of its area's other robots too; none at a tick whose rows are not recorded); -1: all. The
        published rows go into the tick's ring slot, the others into the redo area.
        ``tally``: the robots by state it publishes (``record_every`` > 1)."""
        h = self.header
        head, at = self._slot_head(tick)
        published = rows.size if published < 0 else published
        # the blocks of what this tick writes (its slot, its metrics row), before anything of it is written
        self._reserve(at - _SLOT_HEAD * 8, _SLOT_HEAD * 8 + published * self.row.itemsize)
        if applied is not None:
            self._reserve(at + self.robots * self.row.itemsize, applied.size * self.decision.itemsize)
        self._reserve(self.history_at + tick * self.columns * 8, self.columns * 8)
        h[_H_WRITING] = tick
        head[0] = -1  # the slot is being rewritten
        raw = np.ascontiguousarray(rows).view(np.uint8)  # bytes, not records: copied ten times faster
        cut = published * self.row.itemsize
        self.map[at : at + cut] = raw[:cut]
        self.map[self.redo_at : self.redo_at + raw.size - cut] = raw[cut:]
        if applied is not None:
            at += self.robots * self.row.itemsize
            raw = np.ascontiguousarray(applied).view(np.uint8)
            self.map[at : at + raw.size] = raw
        head[1], head[2], head[3] = rows.size, -1 if applied is None else applied.size, published
        head[4:] = 0 if tally is None else tally
        self.history[tick] = metrics
        head[0] = tick
        h[_H_READY] = tick
        self._records[rows["id"]] = np.ascontiguousarray(rows).view(self.record)
        h[_H_DONE] = tick

    def write_kept(self, tick: int, chunks: list[np.ndarray]) -> None:
        """Save the messages of tick ``tick`` kept for the peers (``kept``'s number of arrays, any dtype): in its
        slot, in place, before :meth:`write` of the tick. A kill while writing leaves the slot marked unwritten.

        Raises:
            RunFailed: more messages or bytes than the file was made for (a bound the caller got wrong).
        """
        raw = [np.ascontiguousarray(c).view(np.uint8).reshape(-1) for c in chunks]
        total = sum(r.size for r in raw)
        if len(raw) != self.kept_chunks or total > self.kept_bytes:
            raise RunFailed(f"checkpoint {self.path}: {len(raw)} kept messages of {total} bytes exceed its slots")
        at = self.kept_at + (tick % KEPT_SLOTS) * self.kept_slot
        head = self.map[at : at + (1 + self.kept_chunks) * 8].view(np.int64)
        self._reserve(at, head.size * 8 + total)
        head[0] = -1  # being rewritten
        at += head.size * 8
        for r in raw:
            self.map[at : at + r.size] = r
            at += r.size
        head[1:] = [r.size for r in raw]
        head[0] = tick

    def kept(self, tick: int) -> list[np.ndarray] | None:
        """The kept messages of tick ``tick`` as :meth:`write_kept` wrote them (bytes: view them as their
        dtype), or None if the file does not hold them."""
        if not self.kept_chunks:
            return None
        at = self.kept_at + (tick % KEPT_SLOTS) * self.kept_slot
        head = self.map[at : at + (1 + self.kept_chunks) * 8].view(np.int64)
        if head[0] != tick or tick < 0:
            return None
        at += head.size * 8
        chunks = []
        for length in head[1:]:
            chunks.append(self.map[at : at + int(length)].copy())
            at += int(length)
        return chunks

    def monitor_reported(self, tick: int) -> None:
        """The newest tick whose metrics the monitor reported (where a restarted world resends from)."""
        if self.map.size and tick > self.header[_H_MONITOR]:
            self.header[_H_MONITOR] = tick

    def save_book(self, book: dict) -> None:
        """Write the bookkeeping whole: to a temporary name, then renamed over the last one."""
        target = self.path.with_name(self.path.name + ".json")
        tmp = target.with_name(target.name + ".tmp")
        tmp.write_text(json.dumps(book, sort_keys=True), encoding="utf-8")
        os.replace(tmp, target)

    def remove(self) -> None:
        """Remove the checkpoint's files (the run is over, or stopped: nothing will restart from them)."""
        for path in (
            self.path,
            self.path.with_name(self.path.name + ".json"),
            self.path.with_name(self.path.name + ".json.tmp"),
        ):
            path.unlink(missing_ok=True)

    # -- reading ----------------------------------------------------------------------
    @classmethod
    def open(
        cls, path: Path, robots: int, max_ticks: int, columns: int, dims: int = 2, kept: tuple[int, int] = (0, 0)
    ) -> Checkpoint:
        """Map the checkpoint a world before this process wrote at ``path``, to restore from and go on writing
        (made again, empty, if that world was killed while making it); ``kept`` as the process before made it.

        Raises:
            RunFailed: the file is not a checkpoint of a run of this size.
        """
        path = Path(path)
        raw = np.fromfile(path, dtype=np.int64, count=_HEADER)
        if raw.size == _HEADER and not raw.any():  # killed in create(), before the header: it holds nothing
            path.unlink()
            ck = cls(path, robots, max_ticks, columns, 2, dims, kept)
            ck.create()
            return ck
        if raw.size < _HEADER or raw[_H_MAGIC] != MAGIC:
            raise RunFailed(f"{path} is not a world checkpoint")
        if (int(raw[_H_ROBOTS]), int(raw[_H_TICKS]), int(raw[_H_COLS])) != (robots, max_ticks + 1, columns):
            raise RunFailed(f"{path} is the checkpoint of another run ({int(raw[_H_ROBOTS])} robots)")
        if (int(raw[_H_KEPT_CHUNKS]), int(raw[_H_KEPT_BYTES])) != kept:
            raise RunFailed(f"{path} is the checkpoint of another run (room for other kept messages)")
        ck = cls(path, robots, max_ticks, columns, int(raw[_H_SLOTS]), dims, kept)
        if path.stat().st_size != ck.size:
            raise RunFailed(f"{path} is not a whole world checkpoint")
        ck._map()
        return ck

    def saved(self) -> Saved | None:
        """What the checkpoint holds, or None if no tick yet (the world before died before tick 0)."""
        h = self.header
        tick = int(h[_H_DONE])
        if h[_H_READY] > tick:  # killed while copying the ready tick's rows into the robots: copy them again
            tick = int(h[_H_READY])
            head, rows, _ = self._slot(tick)
            for part in (rows[: head[3]], self.redo[: head[1] - head[3]]):
                self.rows[part["id"]] = part
            h[_H_DONE] = tick
        h[_H_WRITING] = tick
        if tick < 0:
            return None
        ring = {}
        for t in range(max(0, tick - self.slots + 1), tick + 1):
            head, rows, applied = self._slot(t)
            if head[0] == t:
                ring[t] = (rows[: head[3]].copy(), None if head[2] < 0 else applied[: head[2]].copy(), head[4:].copy())
        try:
            book = json.loads(self.path.with_name(self.path.name + ".json").read_text(encoding="utf-8"))
        except (OSError, ValueError):
            book = {}
        return Saved(
            tick=tick,
            robots=np.array(self.rows),
            history=np.array(self.history[: tick + 1]),
            monitor_tick=int(h[_H_MONITOR]),
            ring=ring,
            book=book,
        )
