"""A world process lost at any tick goes on from its checkpoint (swarm_ros.protocol.checkpoint, Lockstep.restore),
driven through the lockstep with a fake port and clock, as test_lockstep.py does: the run after a restore is the
in-process engine's, tick for tick, whatever tick the world was lost at and however far the write had got."""

from __future__ import annotations

import numpy as np
import pytest
from lockstep_fakes import MAX_TICKS, ROBOTS, LockstepRun

from swarm_ros.core.errors import RunFailed
from swarm_ros.core.metrics import METRIC_COLUMNS
from swarm_ros.protocol.checkpoint import Checkpoint
from swarm_ros.protocol.lockstep import Lockstep
from swarm_ros.protocol.plan import MONITOR, batch_name
from swarm_ros.protocol.shard_save import ShardSaver
from swarm_ros.protocol.world_port import LOSS_CONFIRM_S, Policy

pytestmark = pytest.mark.unit


def _saver(r: LockstepRun, path) -> ShardSaver:
    return ShardSaver(path, r.params, r.ls.shard.plan, 0, r.ls.policy.monitor_window + 2, 2)


def _with_checkpoint(r: LockstepRun, path) -> Checkpoint:
    """The world's save at ``path``; its checkpoint (the mapped file)."""
    saver = _saver(r, path)
    saver.create()
    r.port.saver = saver
    assert saver.checkpoint is not None
    return saver.checkpoint


def _restarted(r: LockstepRun, path) -> Lockstep:
    """A new world process: a fresh lockstep restored from the save at ``path``; replaces ``r``'s."""
    saver = _saver(r, path)
    saved = saver.restore()
    assert saved is not None
    r.port.saver = saver
    r.port.ticks.clear()
    r.port.snapshots.clear()
    r.ls = r.make(r.ls.policy)
    r.ls.restore(saved, 1)
    return r.ls


@pytest.mark.parametrize("lost_at", [0, 1, 57, "end"])
def test_a_world_restored_from_its_checkpoint_runs_on_as_the_engine(tmp_path, lost_at):
    r = LockstepRun(batches=2)
    _with_checkpoint(r, tmp_path / "ck")
    r.start()
    ref = r.engine()
    if lost_at == "end":
        r.run()
        lost_at = r.ls.sim.tick
    else:
        r.run(ticks=lost_at)
    assert r.ls.sim.tick == lost_at
    ls = _restarted(r, tmp_path / "ck")
    assert ls.sim.tick == lost_at and ls.restarts == [(lost_at, "world")]
    assert r.port.snapshots == [(0, lost_at), (1, lost_at)], "every batch gets the saved tick"
    # the ring's ticks go out again (two with no monitor: a batch may have missed the last)
    assert r.port.ticks == list(range(max(0, lost_at - 1), lost_at + 1))
    r.run()
    assert np.array_equal(ls.sim.history, ref.history) and ls.sim.outcome == ref.outcome
    assert np.array_equal(ls.sim.state.x, ref.state.x) and np.array_equal(ls.sim.state.state, ref.state.state)
    assert ls.status().values["restarts"] == f"{lost_at}:world"
    ls.poll()
    assert ls.finished


def test_a_write_cut_off_at_any_step_restores_a_whole_tick(tmp_path):
    """The header's steps: killed before ``ready`` the tick before is restored; after it, the tick itself."""
    r = LockstepRun(batches=1)
    ck = _with_checkpoint(r, tmp_path / "ck")
    r.start()
    r.run(ticks=5)
    ref_state = r.ls.sim.state.state.copy()
    head = ck.header
    # killed after 'ready' of tick 5, before the rows went into the robots: the slot's rows are copied again
    ck.rows["x"] = -1.0
    head[6] = 5  # ready
    head[7] = 4  # done
    slot, rows, _ = ck._slot(5)
    changed = rows[: slot[1]]["id"]  # the robots whose rows changed in tick 5
    again = Checkpoint.open(tmp_path / "ck", ROBOTS, MAX_TICKS, len(METRIC_COLUMNS)).saved()
    assert again is not None and again.tick == 5 and changed.size and (again.robots["x"][changed] != -1.0).all()
    # killed while writing tick 6's slot ('writing' 6, 'ready' 5): tick 5 is what there is
    head[5], head[6], head[7] = 6, 5, 5
    saved = Checkpoint.open(tmp_path / "ck", ROBOTS, MAX_TICKS, len(METRIC_COLUMNS)).saved()
    assert saved.tick == 5 and saved.history.shape == (6, len(METRIC_COLUMNS))
    assert sorted(saved.ring) == [4, 5]
    assert np.array_equal(saved.history, r.ls.sim.history)
    del ref_state


def test_a_checkpoint_with_no_tick_restores_nothing_and_another_runs_is_refused(tmp_path):
    r = LockstepRun(batches=1)
    _with_checkpoint(r, tmp_path / "ck")
    assert Checkpoint.open(tmp_path / "ck", ROBOTS, MAX_TICKS, len(METRIC_COLUMNS)).saved() is None
    with pytest.raises(RunFailed, match="another run"):
        Checkpoint.open(tmp_path / "ck", ROBOTS + 1, MAX_TICKS, len(METRIC_COLUMNS))
    (tmp_path / "junk").write_bytes(b"not a checkpoint at all, longer than the header" * 4)
    with pytest.raises(RunFailed, match="not a world checkpoint"):
        Checkpoint.open(tmp_path / "junk", ROBOTS, MAX_TICKS, len(METRIC_COLUMNS))
    with pytest.raises(FileExistsError):
        Checkpoint(tmp_path / "ck", ROBOTS, MAX_TICKS, len(METRIC_COLUMNS), 2).create()


def test_after_a_restore_old_decisions_and_known_processes_change_nothing(tmp_path):
    """The batches' histories hand the new world decisions it had already, and their announcements: neither is
    a rejection or a restart. A batch restarted while the world was down (a higher incarnation) is one."""
    r = LockstepRun(batches=2)
    _with_checkpoint(r, tmp_path / "ck")
    r.start()
    r.run(ticks=10)
    old = r.decide(0)  # decided for tick 11 already
    ls = _restarted(r, tmp_path / "ck")
    ls.decisions(0, 10, old)  # a tick the world before had: ignored
    r.announce(0)
    r.announce(1)
    assert ls.restarts == [(10, "world")] and r.rejections.total == 0
    ls.batch_liveliness(0, 1, 0)
    ls.batch_liveliness(1, 1, 0)
    assert ls.restarts == [(10, "world")] and ls.respawned == {}
    r.announce(1, incarnation=1)  # restarted while the world was down
    assert ls.restarts == [(10, "world"), (10, batch_name(1))] and (1, 10) in r.port.snapshots
    r.run()
    assert np.array_equal(ls.sim.history, r.engine().history)


def test_a_restored_world_sends_the_ticks_the_monitor_may_lack_again(tmp_path):
    r = LockstepRun(batches=1, monitor_window=4)
    _with_checkpoint(r, tmp_path / "ck")
    r.start()
    r.ls.monitor_liveliness(1, 0)
    r.ls.held(0, "m1")
    for _ in range(3):
        r.tick()
    assert r.port.ticks == [0, 1, 2, 3]
    r.ls.held(1, "m1")
    r.port.saver.monitor_reported(1)
    ls = _restarted(r, tmp_path / "ck")
    assert r.port.ticks == [2, 3], "from the monitor's last report on"
    assert ls.monitor_tick == 1 and ls.monitor_nonce == "m1"
    ls.monitor_liveliness(1, 0)
    ls.held(3, "m1")  # the same monitor: no restart
    assert ls.restarts == [(3, "world")]
    ls.held(3, "m2")  # a new monitor process
    assert ls.restarts == [(3, "world"), (3, MONITOR)]
    assert ls.status().values["restarts"] == "3:world;3:monitor"
    while not ls.sim.done:  # the monitor reports each tick published: the world is never held for long
        r.run()
        ls.held(ls.published_tick, "m2")
    assert np.array_equal(ls.sim.history, r.engine().history)


def test_the_bookkeeping_holds_batches_losses_and_times(tmp_path):
    r = LockstepRun(batches=2, on_batch_loss="remove")
    _with_checkpoint(r, tmp_path / "ck")
    r.start()
    r.run(ticks=3)
    lost = r.own(1)  # the moving robots in its strip
    r.ls.batch_liveliness(1, 0, 1)  # lost for good under 'remove', once the loss is confirmed
    r.clock.now += LOSS_CONFIRM_S + 0.1
    r.ls.poll()
    r.tick(silent=(1,))
    assert r.ls.lost == [batch_name(1)]
    tick = r.ls.sim.tick
    ls = _restarted(r, tmp_path / "ck")
    assert ls.lost == [batch_name(1)] and ls.removed_batches == {1}
    assert ls.sim.losses == [(tick, lost.size)] and ls.sim.removed == lost.size > 0
    assert r.port.snapshots == [(0, tick)], "no snapshot for a removed batch"
    assert ls.startup_seconds == 0.5 and ls.started_wall > 0
    r.run()
    assert ls.sim.done
    assert Policy().max_restarts == 3


def test_a_shards_kept_messages_survive_a_kill_while_the_next_ticks_are_written(tmp_path):
    """A world shard's messages for its peers are written in place, a tick to a slot of three: a kill while one
    tick's are written (its slot marked unwritten) leaves the two ticks before whole; more than the file was made
    for is refused, and a checkpoint sized for other messages is another run's."""
    path, cols, kept = tmp_path / "ck", len(METRIC_COLUMNS), (3, 64)
    ck = Checkpoint(path, ROBOTS, MAX_TICKS, cols, 4, kept=kept)
    ck.create()
    ticks = {t: [np.arange(t, dtype=np.int64), np.full(2, t, np.uint8), np.empty(0, np.int32)] for t in range(1, 5)}
    for t in (1, 2, 3):
        ck.write_kept(t, ticks[t])
    again = Checkpoint.open(path, ROBOTS, MAX_TICKS, cols, kept=kept)
    for t in (1, 2, 3):
        got = again.kept(t)
        assert got is not None and [g.tobytes() for g in got] == [a.tobytes() for a in ticks[t]]
    at = again.kept_at + (4 % 3) * again.kept_slot  # tick 4 goes where tick 1 was: killed half way through it
    again.map[at : at + 8].view(np.int64)[0] = -1
    assert again.kept(4) is None and again.kept(1) is None
    assert again.kept(2) is not None and again.kept(3) is not None
    assert again.kept(0) is None  # never written
    with pytest.raises(RunFailed, match="exceed"):
        again.write_kept(5, [np.zeros(9, np.int64), np.zeros(0), np.zeros(0)])  # 72 bytes in room for 64
    with pytest.raises(RunFailed, match="exceed"):
        again.write_kept(5, [np.zeros(1)])  # one message of three
    with pytest.raises(RunFailed, match="another run"):
        Checkpoint.open(path, ROBOTS, MAX_TICKS, cols, kept=(3, 65))
    with pytest.raises(RunFailed, match="another run"):
        Checkpoint.open(path, ROBOTS, MAX_TICKS, cols)


def test_a_ticks_unpublished_rows_go_to_the_redo_area_and_a_kill_after_ready_copies_them_again(tmp_path):
    """A tick's published rows go into its ring slot (what may be sent again), the others into the one redo area,
    rewritten every tick (so the ring's pages are touched only by what is published). Killed after ``ready``, a
    restore copies both into the robots; the ring gives only the published rows; a tick with none published
    leaves its slot's rows untouched."""
    path, cols = tmp_path / "ck", len(METRIC_COLUMNS)
    ck = Checkpoint(path, ROBOTS, MAX_TICKS, cols, 4)
    ck.create()
    rows = np.zeros(ROBOTS, dtype=ck.row)
    rows["id"] = np.arange(ROBOTS)
    metrics = np.zeros(cols, np.int64)

    def tick(t: int, published: int) -> np.ndarray:
        out = rows.copy()
        out["x"] = t + out["id"] / 1000  # every row new at every tick
        ck.write(t, out, None, metrics, published=published)
        return out

    tick(0, -1)
    second = tick(1, 7)  # 7 rows published, the rest unpublished
    assert np.array_equal(ck.rows, second)
    head, slot, _ = ck._slot(1)
    assert (int(head[1]), int(head[3])) == (ROBOTS, 7)
    assert np.array_equal(slot[:7], second[:7]) and np.array_equal(ck.redo[: ROBOTS - 7], second[7:])
    untouched = ck._slot(2)[1].copy()  # the slot tick 2 takes: written by no tick yet
    third = tick(2, 0)
    assert np.array_equal(ck._slot(2)[1], untouched), "no row published: the slot's rows are not written"
    # killed after 'ready' of tick 2, before (or while) its rows went into the robots
    ck.rows["x"] = -1.0
    ck.header[7] = 1  # done: tick 1
    saved = Checkpoint.open(path, ROBOTS, MAX_TICKS, cols).saved()
    assert saved is not None and saved.tick == 2
    assert np.array_equal(saved.robots, third), "the redo area's rows are the tick's too"
    assert saved.ring[1][0].size == 7 and saved.ring[2][0].size == 0 and saved.ring[0][0].size == ROBOTS
