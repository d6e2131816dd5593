"""What the world's :class:`~swarm_ros.protocol.lockstep.Lockstep` says about the run (its /swarm/status), and
how it notices a silent process (the fallback to liveliness): two views of its state, kept apart from the
state machine itself."""

from __future__ import annotations

import numpy as np

from swarm_ros.core.metrics import METRIC_COLUMNS, Outcome
from swarm_ros.core.state import RobotState
from swarm_ros.protocol.plan import MONITOR
from swarm_ros.protocol.status import RUNNING, STARTING, RunFailed, Status, restarts_text
from swarm_ros.protocol.world_port import DROWNED_S, FIRST_STALL_S, STALL_S, STILL_S


def status_of(ls, note: str = "") -> Status:
    """The run's state now: outcome, the last published tick and its counts, restarts and lost processes."""
    tick = max(ls.published_tick, 0)
    sim, warn = ls.sim, bool(note or ls.lost or ls.down_since or ls.monitor_down_since is not None)
    if not ls.started:
        outcome, message = STARTING, "waiting for robot batches"
    elif ls.ended_at is not None:
        outcome = sim.outcome.value
        message = f"{outcome} at tick {tick}"
        warn = warn or sim.outcome not in (Outcome.COMPLETE, Outcome.COMPLETE_WITH_EXTRAS)
    else:
        outcome, message = RUNNING, note or RUNNING
    values: dict[str, object] = {"rules": sim.params.ruleset.label, "robots": sim.params.robots}
    if ls.started:
        m = sim.history[min(tick, sim.tick)]
        values.update({key: int(m[METRIC_COLUMNS.index(key)]) for key in ("localized", "moving", "walking")})
        values["startup_seconds"] = f"{ls.startup_seconds:.3f}"
    if ls.ended_at is not None:
        values["separated"] = int((sim.state.state == RobotState.SEPARATED).sum())
        values["wall_seconds"] = f"{ls.ended_at - ls.start_time:.3f}"
    values["restarts"] = restarts_text(ls.restarts)
    values["rejected_messages"] = ls.rejections.total
    values["rejected"] = ls.rejections.text()
    values["lost"] = ",".join(ls.lost)
    values["waiting_for"] = ",".join([ls.batch_names[k] for k in sorted(ls.down_since)]
                                     + [MONITOR] * (ls.monitor_down_since is not None))
    return Status(tick=tick, outcome=outcome, message=message, warn=warn, values=values)


def check_stalls(ls, now: float) -> None:
    """The fallback to liveliness (a process lost before DDS matched its liveliness topic): a batch
    whose robots have not decided, or a monitor that has not reported, for ``STALL_S`` is lost.
    Before the first decisions or report, while discovery may still be going on, the limit is
    ``FIRST_STALL_S``. One whose liveliness holds is not lost for its silence (its messages may be
    drowned by a flood): it is waited for, and after ``DROWNED_S`` the run fails.

    Whatever the liveliness says, a run that has not moved (no tick published, no report) for
    ``STILL_S`` fails: liveliness that comes and goes (a transport that has stopped delivering)
    would otherwise keep the rules above from ever firing.

    Raises:
        RunFailed: a batch or the monitor alive but silent for ``DROWNED_S``; the run still for ``STILL_S``.
    """
    if not ls.started or ls.sim.done:
        return
    if now - ls.moved_at >= STILL_S:
        waiting = ", ".join(ls.batch_names[k] for k in sorted(ls.down_since)) or "no lost process"
        raise RunFailed(f"the run has not moved for {STILL_S:g} s at tick {ls.sim.tick} (waiting for: {waiting}; "
                        f"messages dropped: {ls.rejections.text() or 'nothing'}): its messages do not get through")
    if ls.queued:
        limit = STALL_S if ls.monitor_tick >= 0 else FIRST_STALL_S
        if ls.window and now - ls.progress_at >= limit:
            if not ls.monitor_alive:
                ls.monitor_down(f"no metrics for {limit:g} s")
            elif now - ls.progress_at >= DROWNED_S:
                _drowned(ls, "the monitor's metrics")
        return
    limit = STALL_S if ls.sim.tick > 0 else FIRST_STALL_S
    if now - ls.progress_at < limit:
        return
    moving = ls.sim.moving_ids()
    missing = np.setdiff1d(moving[~ls.decided[moving]], ls.pending)
    silent = np.unique(ls.hosts(missing)).tolist()
    for k in silent:
        if k not in ls.live:
            ls.lose_batch(k, f"no decisions for {limit:g} s")
    alive = [ls.batch_names[k] for k in silent if k in ls.live]
    if not alive:
        ls.progress_at = now
    elif now - ls.progress_at >= DROWNED_S:
        _drowned(ls, f"the decisions of {', '.join(alive)}")


def _drowned(ls, what: str) -> None:
    dropped = ls.rejections.text() or "nothing"
    raise RunFailed(f"{what} did not arrive for {DROWNED_S:g} s at tick {ls.sim.tick}, though the process is "
                    f"alive: its messages do not get through, or it hangs (messages dropped: {dropped})")
