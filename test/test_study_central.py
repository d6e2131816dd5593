"""The study's model as a central world's run (:mod:`swarm_ros.core.strips`): its engine gives what the central
world's graph asks of one (``Simulation`` as a ``CentralRun``), and its batches, fed only the rows the world sends
(:mod:`swarm_ros.protocol.darr_niazi.wire`), decide as the in-process engine does, in 2D and 3D, for any number of
strips and any cuts."""

from __future__ import annotations

from functools import partial

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from runs import disc_shape

from swarm_ros.core import RunParams, Shape, Simulation, World
from swarm_ros.core.darr_niazi.run_result import summary_of
from swarm_ros.core.darr_niazi.state import IS_MOVING
from swarm_ros.core.errors import ContractError, Rejected
from swarm_ros.core.strips import AreaStore, Strips, area_of, run_batched, strips_for
from swarm_ros.protocol.cdr import decode_cloud, encode_cloud
from swarm_ros.protocol.central_lockstep import CentralLockstep
from swarm_ros.protocol.checks import Rejections, cloud
from swarm_ros.protocol.darr_niazi.wire import StudyWire

pytestmark = pytest.mark.unit

DISC = disc_shape(World(radius=12), 7.0)
_STATE = ("x", "y", "heading", "state", "z", "pitch", "occupancy", "frontier", "frontier_blocks")


def _ball() -> Shape:
    world = World(6, 3)
    c = np.arange(-world.radius, world.radius + 1)
    z, y, x = np.meshgrid(c, c, c, indexing="ij")
    return Shape(name="ball", mask=np.sqrt(x * x + y * y + z * z) <= 3.5, world=world, source="test ball")


def same(a: Simulation, b: Simulation) -> bool:
    """The same run: every tick's metrics, the outcome and every array of the state."""
    if not np.array_equal(a.history, b.history) or a.outcome != b.outcome or a.tick != b.tick:
        return False
    return all(
        getattr(a.state, name) is None or np.array_equal(getattr(a.state, name), getattr(b.state, name))
        for name in _STATE
    )


def _whole(shape: Shape, params: RunParams) -> Simulation:
    sim = Simulation(shape, params)
    sim.run()
    return sim


def _batched(shape: Shape, params: RunParams, batches: int, cuts: str = "") -> Simulation:
    run = Simulation(shape, params)
    strips = strips_for(run, batches, cuts)
    wire = StudyWire(shape.dims)
    run_batched(run, [wire.batch(run, strips, k) for k in range(batches)])
    return run


@pytest.mark.parametrize("rules", ["paper", "local", "literal"])
@pytest.mark.parametrize("batches", [1, 2, 3])
def test_batches_that_see_only_their_area_and_the_stationary_robots_give_the_in_process_run(rules, batches):
    """Crowded (robots left over, separated), sparse (incomplete at the tick limit) and with failures."""
    for robots, extra in ((DISC.patches + 30, {}), (DISC.patches - 20, {"max_ticks": 400})):
        params = RunParams(robots=robots, seed=5 + batches, rules=rules, vision_radius=2.0, **extra)
        assert same(_whole(DISC, params), _batched(DISC, params, batches))
    failing = RunParams(robots=DISC.patches + 10, seed=3, rules=rules, fail_fraction=0.2, fail_tick=15)
    assert same(_whole(DISC, failing), _batched(DISC, failing, batches, "-4,3"[: 2 * batches - 2]))


def test_a_3d_run_in_batches_is_the_in_process_run():
    ball = _ball()
    params = RunParams(robots=ball.patches + 15, seed=2, vision_radius=2.0)
    assert same(_whole(ball, params), _batched(ball, params, 3))


def test_the_columns_are_the_patch_columns_and_a_batch_sees_the_halo_and_every_stationary_robot():
    run = Simulation(DISC, RunParams(robots=DISC.patches + 30, seed=4, vision_radius=2.0))
    grid = run.grid
    assert (grid.nx, grid.reach, grid.unit) == (25, 2 + 5, "patches")  # the halo: vision radius + REACH
    assert np.array_equal(grid.columns(np.array([-12.0, -0.5001, -0.5, 0.49, 12.0])), [0, 11, 12, 12, 24])
    run.run(60)
    strips = Strips.cut(np.array([-3.0]), grid, 2)  # strip 0: columns 0..8 (x up to -3.5), strip 1: 9..24
    assert strips.area(0) == (0, 8 + 7) and strips.area(1) == (9 - 7, 24)
    stationary = np.flatnonzero(~IS_MOVING[run.state.state])
    assert stationary.size > 4 and np.array_equal(np.flatnonzero(run.seen_by_all(run.robots.state)), stationary)
    columns = grid.columns(run.robots.x)
    assert np.array_equal(area_of(run, strips, 0), np.union1d(np.flatnonzero(columns <= 15), stationary))


@pytest.mark.parametrize("rules", ["paper", "literal"])
def test_the_worlds_lockstep_over_the_wire_with_checked_rows_and_decisions_gives_the_in_process_run(rules):
    """Every area and every decision through a PointCloud2's bytes, checked as the graph checks them: under the paper's
    rules and the literal ones (moves of several steps), so the graph's runs need not repeat each rule set."""
    params = RunParams(robots=DISC.patches + 30, seed=9, vision_radius=2.0, rules=rules)
    run, wire = Simulation(DISC, params), StudyWire(2)
    ls = CentralLockstep(run, wire)
    start = Simulation(DISC, params)
    strips = strips_for(start, 2)
    for k in (1, 0):
        ls.announce(f"robot_batch_{k}", strips.strip(k))
    hosts = [wire.batch(start, ls.strips, k) for k in range(2)]
    stores = [AreaStore(start, ls.strips, k) for k in range(2)]
    wholes = 0
    while run.outcome is None:
        for k, (sent, whole) in ls.areas([0, 1], set()).items():
            rows = cloud(decode_cloud(encode_cloud(sent, run.tick)), wire.row, params.robots, min_rows=0)
            wire.check_rows(start, rows, run.tick)
            assert whole or stores[k].follows(run.tick)
            wholes += whole
            changed = stores[k].take(run.tick, *wire.robots_of(rows), whole)
            own, decided = hosts[k].decide(run.tick + 1, stores[k].seen, changed, stores[k].robots)
            answer = cloud(decode_cloud(encode_cloud(wire.decision_rows(own, decided), run.tick + 1)),
                           wire.decision_row, params.robots, min_rows=0)  # fmt: skip
            ls.decisions(k, run.tick + 1, answer)
    assert same(_whole(DISC, params), run) and wholes == 2  # each batch's whole view once, then the changes


def test_the_checks_refuse_rows_and_decisions_that_cannot_be_the_runs():
    params = RunParams(robots=DISC.patches + 30, seed=9, vision_radius=2.0)
    run, wire = Simulation(DISC, params), StudyWire(2)
    run.run(20)
    ids = run.moving_ids()
    rows = wire.rows(np.arange(params.robots), run.robots)
    wire.check_rows(run, rows, run.tick)
    for bad, kind in (
        (rows[::-1], "bad ids"),
        (np.concatenate([rows, rows[:1]]), "repeated robot id"),
        (_with(rows, "state", 9), "robot state out of range"),
        (_with(rows, "x", 99.0), "pose outside the world"),
    ):
        with pytest.raises(Rejected) as refused:
            wire.check_rows(run, bad, run.tick)
        assert refused.value.kind == kind
    host = wire.batch(run, strips_for(run, 1), 0)
    own, d = host.decide(run.tick + 1, np.arange(params.robots), None, run.robots)
    answer = wire.decision_rows(own, d)
    got, taken = wire.check_decisions(run, answer, run.tick + 1, ids)
    assert np.array_equal(got, ids) and np.array_equal(taken.claim, d.claim)
    with pytest.raises(Rejected, match="decisions for the batch's"):
        wire.check_decisions(run, answer[1:], run.tick + 1, ids)
    wrong = answer.copy()
    wrong["claim"][0] = 0  # a corner of the world's wall
    with pytest.raises(Rejected) as refused:
        wire.check_decisions(run, wrong, run.tick + 1, ids)
    assert refused.value.kind == "illegal decision"


def _with(rows: np.ndarray, field: str, value) -> np.ndarray:
    out = rows.copy()
    out[field] = value
    return out


@pytest.mark.parametrize("shape, tick", [(DISC, 0), (DISC, 25), (_ball(), 25)], ids=["2d-tick0", "2d", "3d"])
def test_a_run_saved_and_restored_or_loaded_goes_on_as_the_run_would_have(shape, tick):
    """A restarted world's checkpoint (``saved``, ``restore``; tick 0 is the one a world saves before anything of it
    goes out) and a monitor's copy (``load``)."""
    params = RunParams(robots=shape.patches + 20, seed=11, vision_radius=2.0, fail_fraction=0.1, fail_tick=40)
    whole = _whole(shape, params)
    run = Simulation(shape, params)
    run.run(tick)
    saved = {name: a.copy() for name, a in run.saved().items()}
    again = Simulation(shape, params)
    again.restore(tick, saved)
    again.run()
    assert same(whole, again)
    copy = Simulation(shape, params)
    copy.load(run.tick, run.robots, run.history)
    assert same(run, copy)
    ended = Simulation(shape, params)  # a monitor's copy at the end: the summary of the run, its losses too
    ended.load(whole.tick, whole.robots, whole.history, whole.outcome)
    assert whole.losses and summary_of(ended) == summary_of(whole)
    with pytest.raises(ContractError):
        Simulation(shape, params).restore(tick + 1, saved)  # too few rows of metrics for the tick


def _owners_agree(world, whole: Simulation) -> None:
    """Every shard has the run's metrics and outcome, and each robot's row is its owner's as in ``whole``."""
    owners = np.concatenate([w.own for w in world])
    assert np.array_equal(np.sort(owners), np.arange(whole.params.robots))
    for w in world:
        assert np.array_equal(w.run.history, whole.history) and w.run.outcome == whole.outcome
        assert all(np.array_equal(a[w.own], b[w.own]) for a, b in zip(w.run.robots, whole.robots))


@given(st.lists(st.integers(0, 60), max_size=40, unique=True).map(sorted), st.lists(st.integers(0, 60), max_size=40))
def test_a_shard_merges_the_robots_it_holds_with_those_it_took_as_union1d_does(held, took):
    """What a world shard holds after a tick (central_shards.merged): union1d's result, without sorting the whole."""
    from swarm_ros.core.strips import merged

    ours, theirs = merged(np.array(held, np.int64), np.array(took, np.int64)), np.union1d(held, took)
    assert np.array_equal(ours, theirs) and ours.dtype == np.int64


@given(st.lists(st.integers(-5, 30), max_size=40), st.booleans())
def test_has_repeats_says_whether_a_value_occurs_twice(values, ordered):
    """Increasing input takes a shortcut (the graph's rows come sorted by id); anything else is sorted first."""
    from swarm_ros.core.strips import has_repeats

    ids = np.array(sorted(values) if ordered else values, np.int64)
    assert has_repeats(ids) == (len(set(values)) < len(values))


@pytest.mark.parametrize("rules", ["paper", "local", "literal"])
@pytest.mark.parametrize("shards, batches, cuts", [(2, 2, ""), (2, 3, "-4,3"), (3, 3, "")])
def test_world_shards_of_the_study_give_the_in_process_run(rules, shards, batches, cuts):
    """S world shards (swarm_ros.core.central_shards), each holding the robots of its columns, its halo and every
    stationary robot, passing only the decisions within its rivals' reach, the robots that localized, counts and
    handovers: crowded (robots separated at the end) and with failures, as the in-process run."""
    from swarm_ros.core.central_shards import run_sharded

    for extra in ({}, {"fail_fraction": 0.2, "fail_tick": 15}):
        params = RunParams(robots=DISC.patches + 25, seed=3 + shards, rules=rules, vision_radius=2.0, **extra)
        world = run_sharded(partial(Simulation, DISC, params), StudyWire.batch, shards, batches, region_cuts=cuts)
        _owners_agree(world, _whole(DISC, params))
    wide = disc_shape(World(radius=40), 12.0)  # 81 columns: more than a shard and its halo (up to 14 columns)
    params = RunParams(robots=wide.patches + 25, seed=3 + shards, rules=rules, vision_radius=2.0)
    early = run_sharded(partial(Simulation, wide, params), StudyWire.batch, shards, batches, 10, region_cuts=cuts)
    assert max(w.present.size for w in early) < params.robots  # no shard holds the whole swarm


def test_world_shards_of_a_3d_study_run_restarted_go_on_as_the_unbroken_run():
    from swarm_ros.core.central_shards import run_sharded

    ball = _ball()
    params = RunParams(robots=ball.patches + 15, seed=2, vision_radius=1.5, fail_fraction=0.1, fail_tick=30)
    make = lambda: Simulation(ball, params)
    world = run_sharded(make, StudyWire.batch, 2, 3, restarts={12: 1, 31: 0}, save_every=10)
    _owners_agree(world, _whole(ball, params))


def _lockstep_run(params: RunParams, remove_at: dict[int, int], kept_at: int = -1):
    """A central world's lockstep over the study's wire, its batches fed what it sends: batch ``remove_at[t]``
    removed (lost for good) as the world decides tick t + 1. At tick ``kept_at``, after that, the lockstep is
    replaced by one resumed from a checkpoint's ``kept``."""
    run, wire = Simulation(DISC, params), StudyWire(2)
    ls, start = CentralLockstep(run, wire), Simulation(DISC, params)
    strips = strips_for(start, 3)
    for k in range(3):
        ls.announce(f"robot_batch_{k}", strips.strip(k))
    hosts = [wire.batch(start, ls.strips, k) for k in range(3)]
    stores = [AreaStore(start, ls.strips, k) for k in range(3)]
    removed: dict[int, np.ndarray] = {}
    while run.outcome is None:
        sent = ls.areas([0, 1, 2], set())
        assert set(sent) == {0, 1, 2} - set(ls.removed)  # a removed batch is sent nothing: the world decides it
        if run.tick in remove_at:
            removed[run.tick + 1] = ls.remove_batch(remove_at[run.tick])
        if run.tick == kept_at:  # the world goes on from a checkpoint saved now, a removal pending
            kept = {name: a.copy() for name, a in ls.kept().items()}
            ls = CentralLockstep(run, wire)
            ls.resume(dict(enumerate(f"robot_batch_{k}" for k in range(3))), strips.cuts, kept)
            sent = ls.areas([0, 1, 2], {0, 1, 2})
        for k, (rows, whole) in sent.items():
            changed = stores[k].take(run.tick, *wire.robots_of(rows), whole)
            answer = wire.decision_rows(*hosts[k].decide(run.tick + 1, stores[k].seen, changed, stores[k].robots))
            if k in ls.removed:  # its process answered the area it was sent before it was removed: too late
                with pytest.raises(Rejected, match="robots were removed"):
                    ls.decisions(k, run.tick + 1, answer)
            else:
                ls.decisions(k, run.tick + 1, answer)
    return run, removed


def _with_removals(params: RunParams, removed: dict[int, np.ndarray]) -> Simulation:
    sim = Simulation(DISC, params)
    while sim.outcome is None:
        sim.step()
        if sim.tick in removed and sim.outcome is None:
            sim.remove(removed[sim.tick])
    return sim


def test_a_batch_removed_leaves_its_robots_at_the_next_ticks_end_and_the_world_decides_its_strip():
    """on_batch_loss: remove on a central world: the robots deciding in the lost batch's strip leave at the end of
    the next tick and the world decides its strip from then on, so the run is the in-process run with those robots
    removed then; a world resumed from a checkpoint's ``kept`` (a removal still to come) goes on alike."""
    params = RunParams(robots=DISC.patches + 30, seed=9, vision_radius=2.0)
    run, removed = _lockstep_run(params, {20: 1, 45: 0})
    assert [t for t in removed] == [21, 46] and all(ids.size for ids in removed.values())
    assert same(_with_removals(params, removed), run) and run.losses == [(t, ids.size) for t, ids in removed.items()]
    again, _ = _lockstep_run(params, {20: 1, 45: 0}, kept_at=20)
    assert same(run, again)


@pytest.mark.parametrize("shards, restarts", [(2, {}), (3, {22: 0, 47: 2})])
def test_world_shards_remove_a_batch_lost_for_good_as_one_world_does(shards, restarts):
    """on_batch_loss: remove with world shards: the shard of the lost batch tells every shard, with its shared rows,
    the robots that leave at the end of the next tick (counted as failing), so the run is the one world's with those
    robots removed then; a shard restarted from a save before the removal removes them again, alike."""
    from swarm_ros.core.central_shards import run_sharded

    params = RunParams(robots=DISC.patches + 30, seed=9, vision_radius=2.0)
    _, removed = _lockstep_run(params, {20: 1, 45: 0})  # what one central world removes, and when
    whole = _with_removals(params, removed)
    make = partial(Simulation, DISC, params)
    world = run_sharded(make, StudyWire.batch, shards, 3, removals={20: 1, 45: 0}, restarts=restarts, save_every=10)
    _owners_agree(world, whole)
    assert all(w.run.losses == whole.losses for w in world) and len(whole.losses) == 2


def test_a_shards_robots_that_leave_are_checked_as_its_peers_own():
    """The counts message of a peer shard carries, after its counts, the robots that leave at the tick's end: ids
    of the run, ascending, none of them this shard's own robots, or the message is dropped."""
    from swarm_ros.core.central_shards import CentralShard
    from swarm_ros.protocol.central_shard_world import ShardLockstep

    class Port:
        def __getattr__(self, name):
            return lambda *args: None  # the messages to its peers: not looked at here

    params = RunParams(robots=DISC.patches + 30, seed=9, vision_radius=2.0)
    run, wire = Simulation(DISC, params), StudyWire(2)
    ls = ShardLockstep(CentralShard(run, strips_for(run, 2), 0, 2), wire, port=Port())
    none, counts = wire.rows(np.empty(0, dtype=np.int64), run.robots), run.counts(np.empty(0, dtype=np.int64))
    mine, theirs = ls.shard.own[-1], np.setdiff1d(np.arange(params.robots), ls.shard.own)[:3]
    for values, kind in [
        (counts[1:], "bad number"),
        (np.concatenate([counts, [mine]]), "bad ids"),
        (np.concatenate([counts, theirs[::-1]]), "bad ids"),
        (np.concatenate([counts, [params.robots]]), "bad ids"),
    ]:
        with pytest.raises(Rejected) as refused:
            ls.shared(1, 1, none, values)
        assert refused.value.kind == kind
    ls.shared(1, 1, none, np.concatenate([counts, theirs]))
    assert ls.exchange.inbox[("shared", 1)][1][3].tolist() == theirs.tolist()


def _world_with_a_loss(tmp_path, policy: str, restarts: int, then: str):
    """A central world of the study's model over a fake port and clock, its three batches fed what it sends; batch 1's
    liveliness lapses as tick 21 is decided and it answers no more, and then ``then``: ``"wait"`` (nothing comes back
    within the loss's confirmation), ``"back"`` (it is alive again within it) or ``"new"`` (a new process of it
    announces itself); or it only stops answering: ``"silent"``, its liveliness never seen (a process that died
    before DDS matched its writer), or ``"mute"``, its liveliness holding throughout. Returns the world and its
    log."""
    from central_fakes import Log, WorldPort

    from swarm_ros.protocol.central_batch import CentralBatch
    from swarm_ros.protocol.central_world import CentralWorld
    from swarm_ros.protocol.world_port import LOSS_CONFIRM_S

    params = RunParams(robots=DISC.patches + 30, seed=9, vision_radius=2.0)
    port, log, now = WorldPort(), Log(), [0.0]
    own = {"record_every": 1, "monitor_window": 0, "start_timeout": 60.0, "incarnation": 0, "tick_rate": 0.0}
    own.update(checkpoint=str(tmp_path / "world.npz"), on_batch_loss=policy, max_restarts=restarts)
    port.clock = lambda: now[0]
    world = CentralWorld(
        Simulation(DISC, params), StudyWire(2), own, port, log, Rejections(log), port.clock, None, True
    )
    names = [f"robot_batch_{k}" for k in range(3)]
    own_of = {name: {"batch": k, "batches": 3, "region_cuts": "", "name": name} for k, name in enumerate(names)}
    hosts = {name: CentralBatch(DISC, params, own_of[name], _no_drop) for name in names}
    for name, host in hosts.items():
        world.batch(name, host.strip)
        if then == "mute":
            world.liveliness(name, 1, 0)
    world.poll()
    sent, lost = 0, False
    while world.ended_at is None and now[0] < (200 if then == "mute" else 100):
        now[0] += 0.01
        while sent < len(port.areas):
            name, tick, rows, whole = port.areas[sent]
            sent += 1
            if tick == 20 and name == "robot_batch_1" and not lost:
                lost = True
                if then not in ("silent", "mute"):
                    world.liveliness(name, 0, 1)
            if name == "robot_batch_1" and lost and then != "back":
                continue  # it answers no more
            world.decisions(
                name, *hosts[name].inboxes[0 if whole else 1].take(decode_cloud(encode_cloud(rows, tick)))[::-1]
            )
        if lost and then == "back" and now[0] > LOSS_CONFIRM_S / 2:
            world.liveliness("robot_batch_1", 1, 0)
        if lost and then == "new" and not world.ls.removed:
            with pytest.raises(Rejected, match="robots were removed"):
                world.batch("robot_batch_1", hosts["robot_batch_1"].strip, 1)
        world.poll()
    return world, log


def _no_drop(topic: str, fault: Rejected) -> None:
    raise AssertionError(f"{topic}: {fault}")


@pytest.mark.parametrize(
    "policy, restarts, then",
    [("remove", 3, "wait"), ("restart", 0, "wait"), ("remove", 3, "new"), ("restart", 0, "silent")],
)
def test_a_world_removes_a_batch_lost_for_good_and_the_run_is_the_in_process_one_with_its_robots_removed(
    tmp_path, policy, restarts, then
):
    """on_batch_loss: remove, or no restarts left: a batch whose liveliness lapsed and that is not back within
    LOSS_CONFIRM_S (or whose new process announced itself: the loss confirmed at once) is removed, and so is one
    never seen alive that the run waited STALL_S for; a checkpoint says so; the world decides its strip, and the run
    is the in-process run with its robots removed."""
    from swarm_ros.protocol import central_checkpoint

    world, log = _world_with_a_loss(tmp_path, policy, restarts, then)
    run = world.run
    (tick, count), *more = run.losses
    assert not more and tick == 21 and any("robot_batch_1 lost for good" in line for line in log.lines)
    gone = np.flatnonzero(run.state.state == 5)
    assert gone.size == count and same(_with_removals(run.params, {21: gone}), run)
    saved = central_checkpoint.load(tmp_path / "world.npz", Simulation(DISC, run.params))
    assert saved.kept["removed"].tolist() == [1]


def test_a_batch_alive_but_mute_is_never_removed_and_the_run_fails_once_still(tmp_path):
    """A batch whose liveliness holds is not lost for its silence, whatever the policy (its messages may be drowned
    by a flood): the world waits, and fails the run once it has not moved for STILL_S."""
    from swarm_ros.core.errors import RunFailed

    with pytest.raises(RunFailed, match="has not moved for 120 s at tick 20 .waiting for: robot_batch_1;"):
        _world_with_a_loss(tmp_path, "remove", 0, "mute")


@pytest.mark.parametrize("policy, restarts, then", [("remove", 3, "back"), ("restart", 3, "wait")])
def test_a_batch_back_within_the_confirmation_or_with_restarts_left_is_waited_for(tmp_path, policy, restarts, then):
    """Back within LOSS_CONFIRM_S, a lapse was a pause; under restart with restarts left, the world waits (the
    launcher starts the batch again): nothing is removed."""
    world, _ = _world_with_a_loss(tmp_path, policy, restarts, then)
    assert world.run.losses == [] and not world.ls.removed
