"""Where a restarted monitor process goes on from: the bag its process before wrote.

The monitor (:mod:`swarm_ros.nodes.central.monitor`) makes its bag durable
(:meth:`swarm_ros.ros.bag_writer.BagRecorder.durable`) before it reports a record held on
/swarm/held, and the world runs at most ``monitor_window`` past that. So the bag a killed monitor
leaves holds every record up to the last it reported, and the topics' histories (the world's last
robots and metrics messages, :data:`~swarm_ros.ros.graph.STATUS_QOS`'s statuses) hold the rest for
the new process.

A killed monitor's bag is in its hidden holder (``.<run>.bag-XXXX/bag``), or, if it was killed
while writing the run directory, in that directory's temporary one (``.<run>.tmp-XXXX/bag``).
The new process takes the longest of them, copies it into a bag of its own, and replays it
through its handlers, which check each message as they would a live one: the view, the metrics
rows and the recording come out as they were. The bag is not cut: each of its messages is whole
alone (the robots at a record tick, the metrics rows of a run of ticks, a status).
"""

from __future__ import annotations

import shutil
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from swarm_ros.artifacts.run_dir import BAG_DIR
from swarm_ros.core.errors import Rejected, RunFailed
from swarm_ros.ros import graph as msgs
from swarm_ros.ros.bag_writer import BagRecorder, unfinished_messages


@dataclass
class Resumed:
    """What a monitor process before this one left: its recorded messages up to its last metrics, in order,
    and the folders they were found in (removed once the new bag holds them)."""

    messages: list[tuple[str, int, bytes]] = field(default_factory=list)
    leftovers: list[Path] = field(default_factory=list)
    trash: list[Path] = field(default_factory=list)  #: write_run's folders for a replaced run: removed if empty
    #: the topic whose message ends a whole tick in the bag; None: each message is whole
    marker: str | None = msgs.CLOCK

    @property
    def ticks(self) -> int:
        """How much of the run it holds: its whole ticks (its messages, with no marker)."""
        return sum(self.marker in (None, topic) for topic, _, _ in self.messages)

    def remove(self) -> None:
        for folder in self.leftovers:
            shutil.rmtree(folder, ignore_errors=True)
        for folder in self.trash:  # one that holds a run directory it was replacing is left to the user
            try:
                folder.rmdir()
            except OSError:
                pass


def left_by_earlier_process(out: Path, own_holder: Path, marker: str | None = msgs.CLOCK) -> Resumed:
    """The messages a killed monitor of the run into ``out`` recorded (the longest bag it left), cut after the
    last message on ``marker``: by default /clock, which ends a tick's messages (None: not cut)."""
    best = Resumed(marker=marker)
    folders = [h for h in out.parent.glob(f".{out.name}.bag-*") if h != own_holder]
    folders += list(out.parent.glob(f".{out.name}.tmp-*"))
    best.trash = list(out.parent.glob(f".{out.name}.old-*"))
    for folder in sorted(folders):
        best.leftovers.append(folder)
        if not (folder / BAG_DIR).is_dir():
            continue
        found = unfinished_messages(folder)
        # a record's messages end with its /clock (the monitor's), and are made durable then
        if marker is not None:
            last = max((i for i, (topic, _, _) in enumerate(found) if topic == marker), default=-1)
            found = found[: last + 1]
        held = Resumed(found, marker=marker)
        if held.ticks > best.ticks:
            best.messages = found
    return best


def resume(
    bag: BagRecorder | None, out: Path, take: Callable[[str, bytes], None], marker: str | None = msgs.CLOCK
) -> int:
    """Go on from what the monitor process before this one left (the module's doc; ``marker``: the topic that
    ends a whole tick, :func:`left_by_earlier_process`): copy its messages into ``bag``, this process's, make
    them durable, then hand each to ``take`` (topic, the message as recorded), in order. Returns how many there
    were.

    Raises:
        RunFailed: the run has no bag to go on from, or it does not read back as the run.
    """
    if bag is None:
        raise RunFailed(
            "a restarted monitor goes on from the bag its process before wrote, and this run has none (bag: false)"
        )
    resumed = left_by_earlier_process(out, bag.holder, marker)
    for topic, at, data in resumed.messages:
        bag.write(topic, data, at)
    bag.durable()
    try:
        for topic, _, data in resumed.messages:
            take(topic, data)
    except Rejected as fault:
        raise RunFailed(f"the bag of the monitor before this one does not read back: {fault}") from None
    resumed.remove()
    return len(resumed.messages)
