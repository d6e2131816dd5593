"""The world's coordination (swarm_ros.protocol.lockstep) driven by method calls, a fake port and a fake clock:
the cases the process tests cover (a batch lost before tick 0, mid-run, twice, past the restart bound; a stalled
batch that resumes; the monitor lost), in milliseconds each and with no rclpy.

The batches' decisions are what a robot-batch process computes (``Decider`` over the world's state), so a run
driven here must match the in-process engine tick for tick.
"""

from __future__ import annotations

import numpy as np
import pytest
from lockstep_fakes import ROBOTS, LockstepRun

from swarm_ros.core.errors import Rejected, RunFailed
from swarm_ros.core.regions import columns
from swarm_ros.core.state import RobotState
from swarm_ros.protocol.checks import held_report
from swarm_ros.protocol.plan import MONITOR, batch_name
from swarm_ros.protocol.world_port import (
    DECISIONS_LINGER,
    DROWNED_S,
    FIRST_STALL_S,
    LINGER,
    LOSS_CONFIRM_S,
    STALL_S,
    STILL_S,
)

pytestmark = pytest.mark.unit


def test_a_run_through_the_lockstep_is_the_engines_run_tick_for_tick():
    r = LockstepRun(batches=3)
    r.start()
    r.run()
    assert r.ls.sim.done and r.port.ticks == list(range(r.ls.sim.tick + 1))
    ref = r.engine()
    assert np.array_equal(r.ls.sim.history, ref.history) and r.ls.sim.outcome == ref.outcome
    last = r.port.statuses[-1]
    assert last.outcome == ref.outcome.value and last.values["restarts"] == ""
    done, total, words = ref.progress()  # the progress bar's values, as simulate's bar has them
    assert (last.values["progress"], last.values["progress_total"], last.values["progress_words"]) == (
        done,
        total,
        "moving",
    )
    assert str(last.values["moving"]) == words["moving"]
    r.ls.poll()
    assert r.ls.finished


def test_the_world_exits_once_its_last_messages_are_acknowledged_the_decisions_waited_for_longer():
    """The end is out once the last status, rows and tallies are acknowledged (at most LINGER) and the applied
    decisions too (at most DECISIONS_LINGER: over a slow link they lag; only a dead reader makes it wait)."""
    r = LockstepRun(batches=2)
    r.start()
    r.run()
    r.port.decisions_delivered = lambda: False  # the monitor has not acknowledged them yet
    r.ls.poll()
    assert not r.ls.finished
    r.clock.now += LINGER + 0.1
    r.ls.poll()
    assert not r.ls.finished
    r.port.decisions_delivered = lambda: True
    r.ls.poll()
    assert r.ls.finished
    r = LockstepRun(batches=2)
    r.start()
    r.run()
    r.port.delivered = r.port.decisions_delivered = lambda: False  # a reader died: never acknowledged
    r.clock.now += DECISIONS_LINGER - 0.1
    r.ls.poll()
    assert not r.ls.finished
    r.clock.now += 0.2
    r.ls.poll()
    assert r.ls.finished


def test_admission_refuses_taken_columns_new_batches_after_tick_0_and_changed_strips():
    r = LockstepRun()
    r.announce(0)
    with pytest.raises(Rejected, match="columns of another batch"):
        r.ls.announce("intruder", 0, (r.strips[0][1], r.strips[1][0]))
    assert not r.ls.started and r.ls.status().outcome == "starting"
    r.announce(1)
    assert r.ls.started and r.port.ticks == [0] and r.port.snapshots == [(0, 0), (1, 0)]
    with pytest.raises(Rejected, match="new batch after tick 0"):
        r.ls.announce("late", 0, (0, 0))
    with pytest.raises(Rejected, match="another strip than before"):
        r.ls.announce(batch_name(0), 1, r.strips[1])


def test_decisions_are_checked_before_they_count():
    r = LockstepRun()
    r.start()
    rows = r.decide(0)
    with pytest.raises(Rejected, match="future tick"):
        r.ls.decisions(0, 2, rows)
    with pytest.raises(Rejected, match="stale tick"):
        r.ls.decisions(0, 0, rows)
    with pytest.raises(Rejected, match="not the batch's robot"):
        r.ls.decisions(1, 1, rows)
    r.ls.decisions(0, 1, rows[:1])
    with pytest.raises(Rejected, match="decided already"):
        r.ls.decisions(0, 1, rows[:1])
    bad = rows[1:2].copy()
    bad["x"] += 5.0  # five patches in one tick
    with pytest.raises(Rejected, match="illegal decision"):
        r.ls.decisions(0, 1, bad)
    assert r.ls.sim.tick == 0 and r.ls.received == 1


def test_a_batch_lost_before_tick_0_is_waited_for_then_fails_the_run_if_it_does_not_come_back():
    r = LockstepRun(restart_timeout=30.0)
    r.announce(0)
    r.ls.batch_liveliness(0, 0, 1)
    assert 0 in r.ls.down_since and r.port.statuses[-1].values["waiting_for"] == batch_name(0)
    r.clock.now += 31
    with pytest.raises(RunFailed, match="lost before the run started and did not come back within 30 s"):
        r.ls.poll()


def test_a_batch_lost_before_tick_0_that_comes_back_starts_the_run():
    r = LockstepRun()
    r.announce(0)
    r.ls.batch_liveliness(0, 0, 1)
    r.announce(0, incarnation=1)
    r.announce(1)
    assert r.ls.started and r.ls.restarts == [(0, batch_name(0))] and not r.ls.down_since
    r.run()
    assert np.array_equal(r.ls.sim.history, r.engine().history)


@pytest.mark.parametrize("losses", [1, 2])
def test_a_batch_lost_mid_run_restarts_from_a_snapshot_and_the_run_is_unchanged(losses):
    r = LockstepRun(max_restarts=3)
    r.start()
    for i in range(losses):  # lost twice in a row: at the same tick, before it decided again
        r.run(ticks=20 if i == 0 else 0)
        tick = r.ls.sim.tick
        r.ls.batch_liveliness(1, 0, 1)
        assert 1 in r.ls.down_since
        r.tick(silent=(1,))
        assert r.ls.sim.tick == tick, "the tick waits for the lost batch"
        r.announce(1, incarnation=i + 1)
        assert r.port.snapshots[-1] == (1, tick) and not r.ls.down_since
    r.run()
    assert r.ls.restarts == [(20, batch_name(1))] * losses
    assert np.array_equal(r.ls.sim.history, r.engine().history)
    assert r.port.statuses[-1].values["restarts"].count(batch_name(1)) == losses


def test_past_the_restart_bound_a_lost_batch_has_its_robots_removed_at_the_end_of_the_next_tick():
    r = LockstepRun(max_restarts=1)
    r.start()
    r.run(ticks=10)
    r.ls.batch_liveliness(1, 0, 1)
    r.announce(1, incarnation=1)
    r.run(ticks=5)
    own = r.own(1)
    r.ls.batch_liveliness(1, 0, 1)  # lost again: no restarts left, its robots removed once the loss is confirmed
    assert r.ls.lost == [] and 1 in r.ls.down_since
    r.clock.now += LOSS_CONFIRM_S + 0.1
    r.ls.poll()
    assert r.ls.lost == [batch_name(1)] and np.array_equal(r.ls.pending, own)
    tick = r.ls.sim.tick
    r.tick(silent=(1,))  # its robots stand still in this tick, then go
    assert r.ls.sim.tick == tick + 1
    assert (r.ls.sim.state.state[own] == RobotState.REMOVED).all()
    assert r.port.statuses[-1].values["lost"] == batch_name(1)
    r.run()  # the world decides for the robots that move into the lost batch's strip
    assert r.ls.sim.done and r.ls.sim.metrics.localized == ROBOTS - own.size


def test_under_remove_a_lost_batch_is_waited_for_only_to_confirm_the_loss():
    r = LockstepRun(on_batch_loss="remove")
    r.start()
    r.run(ticks=5)
    r.ls.batch_liveliness(0, 0, 1)
    assert r.ls.lost == [] and r.port.statuses[-1].values["waiting_for"] == batch_name(0)
    r.clock.now += LOSS_CONFIRM_S - 0.1
    r.ls.poll()
    assert r.ls.lost == [], "not before LOSS_CONFIRM_S"
    r.clock.now += 0.2
    r.ls.poll()
    assert not r.ls.down_since and r.ls.lost == [batch_name(0)] and r.ls.pending.size
    r.announce(0, incarnation=1)  # a process that comes back anyway is not taken
    assert r.ls.restarts == []


@pytest.mark.parametrize("back", ["liveliness", "decisions"])
def test_under_remove_a_live_batch_that_only_seemed_lost_keeps_its_robots_and_the_run_is_unchanged(back):
    """A world starved of CPU past the liveliness lease sees a live batch lapse: its liveliness (or its
    decisions) back within LOSS_CONFIRM_S, it is a pause, and the run equals the engine's."""
    r = LockstepRun(on_batch_loss="remove")
    r.start()
    r.ls.batch_liveliness(0, 1, 0)
    r.run(ticks=5)
    r.ls.batch_liveliness(0, 0, 1)
    r.clock.now += LOSS_CONFIRM_S - 0.5
    r.ls.poll()
    if back == "liveliness":
        r.ls.batch_liveliness(0, 1, 0)
    else:
        r.tick()
    assert not r.ls.down_since
    r.clock.now += LOSS_CONFIRM_S
    r.ls.poll()
    r.run()
    assert r.ls.lost == [] and not r.ls.pending.size and r.ls.restarts == []
    assert np.array_equal(r.ls.sim.history, r.engine().history)


def test_under_remove_a_new_process_of_a_lost_batch_confirms_the_loss_at_once():
    r = LockstepRun(on_batch_loss="remove")
    r.start()
    r.run(ticks=5)
    own = r.own(0)
    r.ls.batch_liveliness(0, 0, 1)
    r.announce(0, incarnation=1)  # the process before is gone for sure
    assert r.ls.lost == [batch_name(0)] and np.array_equal(r.ls.pending, own) and r.ls.restarts == []


def test_a_stalled_batch_is_waited_for_and_counts_as_back_when_it_decides_again():
    r = LockstepRun()
    r.start()
    r.run(ticks=3)
    r.tick(silent=(0,))
    r.clock.now += STALL_S + 0.1
    r.ls.poll()
    assert 0 in r.ls.down_since and r.port.statuses[-1].values["waiting_for"] == batch_name(0)
    tick = r.ls.sim.tick
    r.tick()  # it resumes
    assert r.ls.sim.tick == tick + 1 and not r.ls.down_since and r.ls.restarts == []
    r.run()
    assert np.array_equal(r.ls.sim.history, r.engine().history)


def test_the_world_waits_for_the_monitor_within_its_window_and_for_a_lost_one_up_to_restart_timeout():
    r = LockstepRun(monitor_window=2)
    r.start()
    assert not r.ls.started, "no tick 0 before the monitor is there"
    r.ls.monitor_liveliness(1, 0)
    assert r.ls.started
    r.run(ticks=6)
    # published up to the window; the next tick applied and held, and the one after not applied while it waits
    assert r.port.ticks == [0, 1] and r.ls.sim.tick == 2, "published up to the window, the next one held"
    r.ls.held(1)
    assert r.port.ticks == [0, 1, 2, 3] and r.ls.sim.tick == 3, "tick 3 went on from the decisions in already"
    r.run(ticks=3)
    assert r.port.ticks == [0, 1, 2, 3] and r.ls.sim.tick == 4, "tick 4 held for the monitor"
    r.clock.now += STALL_S + 0.1  # no metrics since, but alive: waited for (a flood may drown its metrics)
    r.ls.poll()
    assert r.ls.lost == [] and r.port.ticks == [0, 1, 2, 3]
    r.ls.monitor_liveliness(0, 1)  # its liveliness lapsed: waited for, up to restart_timeout, the queue held
    assert r.ls.lost == [] and r.ls.status().values["waiting_for"] == MONITOR and r.port.ticks == [0, 1, 2, 3]
    r.ls.monitor_liveliness(1, 0)  # a new process (or it was only slow): waited for no longer
    assert r.ls.monitor_down_since is None and r.ls.status().values["waiting_for"] == ""
    r.ls.monitor_liveliness(0, 1)
    r.clock.now += r.ls.policy.restart_timeout + 0.1
    r.ls.poll()  # not back in time: lost, the queue goes out, and the run goes on
    # tick 4 goes out, and tick 5, whose decisions were in already
    assert r.ls.lost == [MONITOR] and r.ls.window == 0 and r.port.ticks == list(range(6))
    r.run(ticks=1)
    assert r.port.ticks == list(range(7))
    r.ls.monitor_liveliness(1, 0)  # it was only slow
    assert r.ls.lost == [] and r.ls.window == 2


def test_the_monitors_held_report_is_checked_against_the_ticks_published():
    """/swarm/held, every algorithm's backpressure: ``[tick, ended]``, the tick one the world published (or -1)."""
    assert held_report(np.array([-1, 0]), 5) == (-1, False)
    assert held_report(np.array([5, 1]), 5) == (5, True)
    for values in ([5], [1, 0, 0], [-2, 0], [6, 0], [0, 2], [0, -1]):
        with pytest.raises(Rejected, match="held"):
            held_report(np.array(values), 5)


@pytest.mark.parametrize("who", ["monitor", "batch"])
def test_a_live_process_whose_messages_do_not_come_is_never_lost_and_the_run_fails_loudly(who):
    """Its liveliness holds, its messages do not arrive (drowned by a flood, or it hangs): waited for, never
    lost or removed, and after DROWNED_S the run fails."""
    if who == "monitor":
        r = LockstepRun(monitor_window=2)
        r.start()
        r.ls.monitor_liveliness(1, 0)
        r.run(ticks=6)  # the world waits for the monitor after tick 1, and holds tick 2
        what = "the monitor's held reports did not arrive for 60 s at tick 2"
    else:
        r = LockstepRun(on_batch_loss="remove")
        r.start()
        r.ls.batch_liveliness(0, 1, 0)
        r.run(ticks=3)
        r.tick(silent=(0,))
        what = "the decisions of robot_batch_0 did not arrive for 60 s at tick 3"
    for _ in range(int(DROWNED_S) - 1):  # a poll every second, as the node's timer does
        r.clock.now += 1.0
        r.ls.poll()
    assert r.ls.lost == [] and not r.ls.down_since and not r.ls.pending.size
    assert r.port.ticks == ([0, 1] if who == "monitor" else [0, 1, 2, 3])
    r.clock.now += 1.5
    with pytest.raises(RunFailed, match=f"{what}, though the process is alive"):
        r.ls.poll()


def test_a_run_that_does_not_move_fails_whatever_the_liveliness_says():
    """Every batch's liveliness comes and goes (a transport that has stopped delivering: their decisions never
    come): each lapse is a loss waited for, each return ends the wait, so the rules above never fire; after
    STILL_S without a tick the run fails all the same."""
    r = LockstepRun()
    r.start()
    r.ls.batch_liveliness(0, 1, 0)
    r.ls.batch_liveliness(1, 1, 0)
    r.run(ticks=3)
    seconds = 0.0
    while seconds < STILL_S - 1:
        for k in (0, 1):  # lapsed at this poll, back before the next
            r.ls.batch_liveliness(k, 0, 1)
        r.clock.now += 1.0
        seconds += 1.0
        r.ls.poll()
        for k in (0, 1):
            r.ls.batch_liveliness(k, 1, 0)
    assert r.ls.sim.tick == 3 and r.ls.lost == []
    r.clock.now += 1.5
    with pytest.raises(RunFailed, match=f"the run has not moved for {STILL_S:g} s at tick 3"):
        r.ls.poll()


def test_a_drowned_batch_whose_decisions_get_through_at_last_goes_on_unchanged():
    r = LockstepRun(on_batch_loss="remove")
    r.start()
    r.ls.batch_liveliness(0, 1, 0)
    r.tick(silent=(0,))
    r.clock.now += DROWNED_S - 5
    r.ls.poll()
    r.tick()  # its decisions arrive
    r.run()
    assert r.ls.lost == [] and r.ls.restarts == []
    assert np.array_equal(r.ls.sim.history, r.engine().history)


def test_a_monitor_never_seen_is_given_up_on_and_the_swarm_starts_without_it():
    r = LockstepRun(monitor_window=4)
    r.port.monitor_ready = False
    r.start()
    r.clock.now += FIRST_STALL_S + 0.1
    r.ls.poll()
    assert r.ls.started and r.ls.lost == [MONITOR] and r.ls.window == 0
    # which of the two it waited for, for a log to tell a lost liveliness event from slow discovery
    assert any("not seen within 30 s: no liveliness, not all its readers found" in line for line in r.log.lines)


def test_batches_that_never_cover_the_robots_fail_the_run_at_the_start_timeout():
    r = LockstepRun(start_timeout=5.0)
    r.announce(0)
    r.clock.now += 5.1
    with pytest.raises(RunFailed, match=f"robot batches cover .* of {r.ls.hosting.width} columns after 5 s"):
        r.ls.poll()


class RegionCheck:
    """Each batch's host as a robot-batch process runs it (:class:`StudyBatch`), fed its snapshot and region rows
    as the messages the world sends; checks after every tick that its regional view holds exactly the world's
    moving robots in its area, and every stationary robot, with the world's poses and the world's frontier."""

    def __init__(self, run: LockstepRun) -> None:
        from swarm_ros.protocol.darr_niazi.batch_host import StudyBatch

        self.run, self.seen, self.dropped = run, 0, []
        self.hosts = [
            StudyBatch(
                run.shape,
                run.params,
                {"batch": k, "batches": run.batches, "region_cuts": run.cuts, "name": batch_name(k)},
                lambda topic, fault: self.dropped.append((topic, fault)),
            )
            for k in range(run.batches)
        ]
        self.handovers = 0
        self.owner = None

    def follow(self) -> dict[int, tuple[np.ndarray, int]]:
        """What each host decided from the messages sent since the last call, by batch."""
        from swarm_ros.protocol.cdr import decode_cloud, encode_cloud

        decided = {}
        for tick, k, rows, snapshot in self.run.port.regions[self.seen :]:
            inbox = self.hosts[k].inboxes[0 if snapshot else 1]
            out = inbox.take(decode_cloud(encode_cloud(rows, tick)))
            if out is not None:
                decided[k] = out
        self.seen = len(self.run.port.regions)
        assert self.dropped == []
        self._check()
        return decided

    def _check(self) -> None:
        s = self.run.ls.sim.state
        moving = s.moving_ids()
        cols = columns(s.x[moving], self.run.shape.world.radius)
        owner = np.searchsorted([first for first, _ in self.run.strips], cols, side="right") - 1
        if self.owner is not None:
            was = self.owner[moving]
            self.handovers += int(((was >= 0) & (was != owner)).sum())
        self.owner = np.full(s.robots, -1)
        self.owner[moving] = owner
        for host in self.hosts:
            rep, (first, last) = host.view, host.view.area
            assert rep.tick == s.tick
            inside = moving[(cols >= first) & (cols <= last)]
            assert np.array_equal(rep.moving_ids(), inside)
            for name in ("x", "y", "heading", "state"):
                assert np.array_equal(getattr(rep.state, name)[inside], getattr(s, name)[inside])
            assert np.array_equal(rep.state.occupancy, s.occupancy)
            assert np.array_equal(rep.state.frontier, s.frontier)


@pytest.mark.parametrize(
    ("batches", "cuts", "shape"),
    [
        (1, None, "star"),
        (2, None, "star"),
        (4, None, "star"),
        (8, None, "star"),
        (3, [-20, -19], "star"),
        (2, [9], "star"),
        (3, None, "box"),
    ],
)
def test_any_partition_into_strips_gives_the_engines_run_and_each_batch_sees_exactly_its_region(batches, cuts, shape):
    """Equality for several partitions (balanced, lopsided, a one-column strip, 3D), and the routing: each
    batch's host, fed only its snapshot and region rows, sees the world where it must and decides the engine's
    run."""
    r = LockstepRun(batches=batches, cuts=cuts, shape=shape)
    check = RegionCheck(r)
    r.start()
    decided = check.follow()
    while not r.ls.sim.done:
        before = r.ls.sim.tick
        for k, (rows, tick) in decided.items():
            r.ls.decisions(k, tick, rows)
        decided = check.follow()
        assert r.ls.sim.tick == before + 1, "the hosts' decisions did not make the next tick"
    assert np.array_equal(r.ls.sim.history, r.engine().history)
    if batches > 1:
        assert check.handovers > 0, "no robot crossed a cut: the test would not test handovers"


def test_a_strip_whose_batch_is_removed_is_decided_by_the_world_even_when_only_its_robots_move():
    """No batch sends anything when every moving robot is in a removed batch's strip: the world's own ticks
    follow one another without a message to wake it (the run once stalled there)."""
    r = LockstepRun(batches=3, on_batch_loss="remove")
    check = RegionCheck(r)
    r.start()
    r.run(ticks=40)
    check.follow()
    r.ls.batch_liveliness(1, 0, 1)
    while not r.ls.sim.done:
        tick = r.ls.sim.tick
        r.tick()
        check.follow()
        assert r.ls.sim.tick > tick, "stalled"
    assert r.ls.sim.outcome.value == "incomplete" and r.ls.sim.metrics.moving == 0


def test_no_method_of_the_lockstep_is_a_base_class_stand_in():
    """Its base classes declare the lockstep's methods they call as stand-ins that raise NotImplementedError;
    the class each name resolves to must hold the real one, whatever the order of the bases."""
    import ast
    import inspect
    import textwrap

    from swarm_ros.protocol.lockstep import Lockstep

    stand_ins = []
    for name, member in inspect.getmembers(Lockstep, inspect.isfunction):
        body = ast.parse(textwrap.dedent(inspect.getsource(member))).body[0].body
        if len(body) == 1 and isinstance(body[0], ast.Raise) and "NotImplementedError" in ast.unparse(body[0]):
            stand_ins.append(name)
    assert stand_ins == []


def test_tick_rate_publishes_one_tick_a_period_and_the_run_is_unchanged():
    """``tick_rate``: a tick applied early is held until its time; the node is told when to poll (wake_in); a
    tick held for the clock is not a stall; and the run is the engine's. (A period of 1/8 s: exact in binary.)"""
    r = LockstepRun(tick_rate=8.0)
    r.start()
    assert r.port.ticks == [0] and r.ls.wake_in() is None  # tick 0 at once: nothing held
    r.tick()
    assert r.ls.sim.tick == 1 and r.port.ticks == [0], "applied, and held"
    assert r.ls.wake_in() == 0.125
    r.clock.now += 0.0625
    r.ls.poll()
    assert r.port.ticks == [0] and r.ls.wake_in() == 0.0625
    r.clock.now += 0.0625
    r.ls.poll()
    assert r.port.ticks == [0, 1] and r.ls.wake_in() is None
    published = {1: r.clock.now}
    while not r.ls.sim.done:
        r.tick()
        r.clock.now += 0.5 * r.ls.wake_in()  # polled early: nothing goes out
        r.ls.poll()
        assert r.port.ticks[-1] == r.ls.sim.tick - 1
        r.clock.now += r.ls.wake_in()
        r.ls.poll()
        published[r.port.ticks[-1]] = r.clock.now
    gaps = np.diff([published[t] for t in sorted(published)])
    assert gaps.min() == gaps.max() == 0.125
    assert not r.ls.lost and not r.ls.down_since and r.ls.monitor_down_since is None
    assert np.array_equal(r.ls.sim.history, r.engine().history)


def test_a_tick_late_for_its_rate_goes_out_at_once_and_the_next_keeps_the_rate():
    r = LockstepRun(tick_rate=8.0)
    r.start()
    r.clock.now += 0.375  # the batches took long: the tick is late
    r.tick()
    assert r.port.ticks == [0, 1], "late: published as soon as it is applied"
    r.tick()
    assert r.port.ticks == [0, 1] and r.ls.wake_in() == 0.125, "one period later, no burst"


def test_a_batch_alive_but_silent_is_sent_its_snapshot_again_each_stall_period():
    """The rows a batch decides from may never reach it (a restarted world's snapshot once did not, in CI): while
    it is alive and silent the world sends the current tick's snapshot again, once a STALL_S, and the run goes on
    unchanged once it decides."""
    r = LockstepRun()
    r.start()
    r.run(ticks=4)
    r.ls.batch_liveliness(1, 1, 0)
    tick, sent = r.ls.sim.tick, len(r.port.snapshots)
    r.tick(silent=(1,))
    r.clock.now += STALL_S - 0.1
    r.ls.poll()
    assert len(r.port.snapshots) == sent, "not before STALL_S"
    r.clock.now += 0.2
    r.ls.poll()
    r.ls.poll()
    assert r.port.snapshots[sent:] == [(1, tick)], "once"
    r.clock.now += STALL_S
    r.ls.poll()
    assert r.port.snapshots[sent:] == [(1, tick), (1, tick)] and r.ls.lost == [] and not r.ls.down_since
    r.tick()  # it decides at last
    r.run()
    assert r.ls.restarts == [] and np.array_equal(r.ls.sim.history, r.engine().history)


def test_a_silent_batch_is_found_among_robots_the_world_decides_and_a_removed_batch_is_never_waited_for():
    """The moving robots in a removed batch's strip are the world's to decide: while another batch is silent
    they are not 'missing', and the removed batch, alive again (a stalled process resumed), is neither waited
    for nor blamed. The silent batch gets the tick's snapshot again, and is the one a failure names."""
    r = LockstepRun(batches=3, on_batch_loss="remove")
    r.start()
    for k in range(3):
        r.ls.batch_liveliness(k, 1, 0)
    r.run(ticks=20)
    r.ls.batch_liveliness(1, 0, 1)  # stalled: lost, then removed once the loss is confirmed
    r.clock.now += LOSS_CONFIRM_S + 0.1
    r.ls.poll()
    assert 1 in r.ls.removed_batches
    r.run(ticks=2)
    for _ in range(300):  # until robots walk into the removed strip, decided by the world
        if r.own(1).size and r.own(0).size:
            break
        r.run(ticks=1)
    r.ls.batch_liveliness(1, 1, 0)  # resumed: alive again, its robots removed for good
    r.tick(silent=(0,))  # batch 0's decisions do not come
    tick = r.ls.sim.tick
    assert r.own(1).size and r.own(0).size, "the test needs robots in the removed strip and in the silent one"
    snapshots = len(r.port.snapshots)
    r.clock.now += STALL_S + 0.1
    r.ls.poll()
    assert r.port.snapshots[snapshots:] == [(0, tick)], "the silent batch's snapshot again, and only its"
    r.clock.now += DROWNED_S
    with pytest.raises(RunFailed, match=f"the decisions of {batch_name(0)} did not arrive"):
        r.ls.poll()
