"""The run's state as the world announces it on /swarm/status: data every process acts on, never log text.

The ``outcome`` value is :data:`STARTING` until tick 0 goes out, :data:`RUNNING` until the run
ends, then the run's outcome (``swarm_ros.core.metrics.Outcome``). The launcher learns that
tick 0 started, and the batches and the monitor that the run ended, from it.
"""

from __future__ import annotations

import math
from collections import Counter

from swarm_ros.protocol.plan import MONITOR, WORLD

STARTING = "starting"  #: waiting for robot batches (and the monitor) before tick 0
RUNNING = "running"  #: tick 0 went out; no outcome yet
NOT_ENDED = (STARTING, RUNNING)


def has_started(outcome: str | None) -> bool:
    """Whether a status with this ``outcome`` says tick 0 went out."""
    return outcome is not None and outcome != STARTING


def has_ended(outcome: str | None) -> bool:
    """Whether a status with this ``outcome`` says the run is over."""
    return outcome is not None and outcome not in NOT_ENDED


def progress_values(progress: tuple[int, int, dict[str, str]]) -> dict[str, object]:
    """The status values of a run's progress, as ``simulate``'s bar shows it (an engine's ``progress()``: the cells
    done, all of them, and words by name): ``progress``, ``progress_total``, ``progress_words`` (the words' names,
    comma-separated) and each word but the tick (the status has its own)."""
    done, total, words = progress
    shown = {name: value for name, value in words.items() if name != "tick"}
    return {"progress": done, "progress_total": total, "progress_words": ",".join(shown), **shown}


def restarts_text(restarts: list[tuple[int, str]]) -> str:
    """The ``restarts`` value of /swarm/status: ``tick:node`` items joined by ``;``, oldest first."""
    return ";".join(f"{tick}:{node}" for tick, node in restarts)


def restart_event(tick: int, node: str) -> str:
    """The recording's line for a restart of ``node`` at ``tick``."""
    what = {
        WORLD: "a new world process went on from its checkpoint",
        MONITOR: "a new monitor process went on from its bag",
    }.get(node, "a new process took over its robots")
    return f"{node} restarted at tick {tick}: {what}"


def restarts_of(text: str) -> list[tuple[int, str]]:
    """The inverse of :func:`restarts_text`; malformed items are skipped."""
    out = []
    for item in text.split(";"):
        tick, sep, node = item.partition(":")
        if sep and tick.isdigit() and node:
            out.append((int(tick), node))
    return out


def joined_restarts(lists: list[list[tuple[int, str]]]) -> list[tuple[int, str]]:
    """The restarts of the run from what each world process listed (the world's list alone, or each world
    shard's): each lists its own batches and itself; the monitor's restarts, which every shard sees, are taken
    from the list that has the most of them. Ordered by tick, each list's order kept."""
    if len(lists) == 1:
        return list(lists[0])
    monitor = max(([r for r in one if r[1] == MONITOR] for one in lists), key=len)
    others = [r for one in lists for r in one if r[1] != MONITOR]
    return sorted(others + monitor, key=lambda r: r[0])


class WorldReport:
    """What a reader keeps of the world's status messages: restarts, the world's clock, its drops, its outcome.

    Status messages are latched and may arrive again or out of order; each kept value only grows.
    """

    def __init__(self) -> None:
        self.restarts: list[tuple[int, str]] = []  #: (tick, batch) of every restart
        self.times: dict[str, float] = {}  #: wall_seconds (tick 0 to the outcome) and startup_seconds
        self.rejected = 0  #: messages the world dropped (world shards: all of them)
        self.said: dict[str, list[tuple[int, str]]] = {}  # per sender (the world, or each world shard): its restarts
        self.dropped: dict[str, int] = {}  # per sender: the messages it dropped
        self.outcome: str | None = None  #: the run's outcome, once it ended

    def update(self, values: dict[str, str], sender: str = WORLD) -> list[tuple[int, str]]:
        """Take in one status message's values (from ``sender``: the world, or one of the world shards, whose
        reports are joined); return the restarts it adds. A sender's longer list replaces its shorter one, which
        it need not hold: a world restarted from an older checkpoint lists a batch's restart it saw again at its
        own tick."""
        restarts = restarts_of(values.get("restarts", ""))
        self.said[sender] = max(self.said.get(sender, []), restarts, key=len)  # each list only grows
        before = Counter(self.restarts)
        self.restarts = joined_restarts(list(self.said.values()))
        new = list((Counter(self.restarts) - before).elements())
        for key in ("wall_seconds", "startup_seconds"):
            try:
                seconds = float(values[key])
            except (KeyError, ValueError):
                continue
            if math.isfinite(seconds) and seconds >= 0:
                self.times[key] = max(self.times.get(key, 0.0), seconds) if sender != WORLD else seconds
        if values.get("rejected_messages", "").isdigit():
            self.dropped[sender] = max(self.dropped.get(sender, 0), int(values["rejected_messages"]))
            self.rejected = sum(self.dropped.values())
        if has_ended(values.get("outcome")):
            self.outcome = values["outcome"]
        return new
