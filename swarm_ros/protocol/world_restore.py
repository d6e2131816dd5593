"""A restarted world process goes on from its checkpoint (:mod:`swarm_ros.protocol.checkpoint`).

:func:`book_of` is what the lockstep writes beside the ticks when its bookkeeping changes;
:func:`restore` puts a saved tick and that bookkeeping back into a fresh :class:`Lockstep`, which then
sends what a reader may have lost with the world before: to every batch a snapshot of the
saved tick (a batch that had it ignores it), and the ticks from the one after the monitor's
last report up to the saved one, again (a reader that had them ignores them). The batches'
decisions for the next tick are in their writers' histories, which DDS hands to the new
world's readers; so are their announcements and the monitor's last metrics. The run then
goes on as if nothing had happened: a tick's decisions are a pure function of the state.
"""

from __future__ import annotations

import time

import numpy as np

from swarm_ros.core.metrics import Outcome, TickMetrics, outcome_of
from swarm_ros.core.state import RobotState
from swarm_ros.protocol.checkpoint import Saved
from swarm_ros.protocol.plan import MONITOR, WORLD
from swarm_ros.protocol.rows import pose_of

__all__ = ["Saved", "book_of", "restore"]


def book_of(ls) -> dict:
    """The lockstep's bookkeeping, as JSON data."""
    return {
        "batches": ls.batch_names,
        "strips": [list(strip) for strip in ls.hosting.strips],
        "restart_counts": ls.restart_counts,
        "incarnations": ls.incarnations,
        "restarts": [[t, n] for t, n in ls.restarts],
        "lost": ls.lost,
        "removed_batches": sorted(ls.removed_batches),
        "losses": [[t, n] for t, n in ls.sim.losses],
        "started_wall": ls.started_wall,
        "startup_seconds": ls.startup_seconds,
        "monitor_nonce": ls.monitor_nonce,
    }


def _outcome(ls, history: np.ndarray, robots: np.ndarray) -> Outcome | None:
    """The outcome after the saved tick, from its metrics (separated robots mean the shape completed with
    extras: the end check of a swarm whose left-overs are separated reads as complete)."""
    m = TickMetrics(*history[-1].tolist())
    if (robots["state"] == RobotState.SEPARATED).any():
        return Outcome.COMPLETE_WITH_EXTRAS
    alive = int((robots["state"] != RobotState.REMOVED).sum())
    return outcome_of(m, ls.sim.shape.patches, alive, ls.sim.params.max_ticks)


def restore(ls, saved: Saved, incarnation: int) -> None:
    """Put ``saved`` into ``ls`` (fresh, not started): its state and bookkeeping. The lockstep then sends
    again what readers may lack (module doc, :meth:`~swarm_ros.protocol.lockstep.Lockstep.restore`).
    ``incarnation`` counts the world's processes before this one: one killed before it wrote anything is a
    restart too, at the same tick.

    Raises:
        ValueError: the checkpoint does not make a consistent swarm, or its bookkeeping is missing.
    """
    b, rows = saved.book, saved.robots
    if "batches" not in b:
        raise ValueError("the checkpoint's bookkeeping is missing")
    tick = saved.tick
    pose = pose_of(rows)
    ls.sim.restore(tick, pose["x"], pose["y"], pose["heading"], rows["state"], saved.history,
                   [tuple(x) for x in b["losses"]], _outcome(ls, saved.history, rows), pose.get("z"), pose.get("pitch"))
    ls.batch_names = list(b["batches"])
    ls.hosting.restore(b["strips"])
    ls.restart_counts, ls.incarnations = list(b["restart_counts"]), list(b["incarnations"])
    ls.known = dict(enumerate(ls.incarnations))
    ls.restarts = [(int(t), str(n)) for t, n in b["restarts"]]
    ls.restarts += [(tick, WORLD)] * max(1, incarnation - sum(n == WORLD for _, n in ls.restarts))
    ls.lost, ls.removed_batches = list(b["lost"]), set(b["removed_batches"])
    ls.monitor_nonce = str(b["monitor_nonce"])
    ls.started, ls.restored = True, True
    ls.started_wall = float(b["started_wall"])
    ls.start_time = ls.clock() - max(0.0, time.time() - ls.started_wall)
    ls.startup_seconds = float(b["startup_seconds"])
    ls.monitor_tick = saved.monitor_tick
    if MONITOR in ls.lost:
        ls.window = 0
    for k, name in enumerate(ls.batch_names):
        ls.port.watch_batch(k, name)
    ls.save_book()
    ls.log.warn(f"world restarted: going on from tick {tick} of its checkpoint "
                f"({len(ls.batch_names)} batches, restarts so far {len(ls.restarts) - 1})")

