"""The rubenstein algorithm split among robot batches by strips of its cell grid (swarm_ros.core.strips), and the
central world's graph code (swarm_ros.protocol.central_world) over it:
K batches, each sent only its area's robots, give the in-process engine's run byte for byte."""

import types

import numpy as np
import pytest
from central_fakes import Log, WorldPort

from swarm_ros.core import Shape, World
from swarm_ros.core.errors import ContractError, ParameterError, Rejected
from swarm_ros.core.metrics import Outcome
from swarm_ros.core.params import RunParams, Settings
from swarm_ros.core.rubenstein.batch import RubensteinBatch
from swarm_ros.core.rubenstein.rule import JOINED, Robots
from swarm_ros.core.rubenstein.run import RubensteinRun
from swarm_ros.core.strips import AreaFeed, AreaStore, Strips, area_of, run_batched, strips_for
from swarm_ros.protocol.cdr import decode_cloud, encode_cloud
from swarm_ros.protocol.central_batch import CentralBatch
from swarm_ros.protocol.central_lockstep import CentralLockstep
from swarm_ros.protocol.central_world import monitor_reach
from swarm_ros.protocol.checks import Rejections
from swarm_ros.protocol.rubenstein.rows import (
    RubensteinWire,
    check_rubenstein_rows,
    decided_of_rows,
    robots_of_rows,
    rubenstein_rows,
)

pytestmark = pytest.mark.unit

#: where most runs here stop (outcome timeout): past the start-up's 200 ticks, with robots joined and crossing strips;
#: the square's whole run is some 5,000 ticks, which test_two_batches_give_the_in_process_run_to_its_end runs
TICKS = 800


def square(side: int) -> Shape:
    return Shape.from_grid(np.ones((side, side), dtype=bool), World(), name=f"square{side}", source="test")


def batched(run: RubensteinRun, batches: int, max_ticks: int | None = None) -> Strips:
    """Run ``run`` with its decisions made by ``batches`` RubensteinBatch es; the strips."""
    strips = strips_for(run, batches)
    run_batched(run, [RubensteinBatch(run, strips, k) for k in range(batches)], max_ticks)
    return strips


def same(a: RubensteinRun, b: RubensteinRun) -> bool:
    return (
        a.tick == b.tick
        and a.outcome == b.outcome
        and all(np.array_equal(x, y) for x, y in zip(a.robots, b.robots))
        and np.array_equal(a.history, b.history)
        and np.array_equal(a.covered, b.covered)
    )


def test_two_batches_give_the_in_process_run_to_its_end():
    """With range noise, to the outcome complete; K = 1 and 4 are the lockstep's test below (stopped at TICKS)."""
    batches = 2
    params = RunParams(40, algorithm="rubenstein", seed=5, range_noise=0.04)
    whole, split = RubensteinRun(square(6), params), RubensteinRun(square(6), params)
    whole.run()
    batched(split, batches)
    assert whole.outcome is not None and same(whole, split)


@pytest.mark.parametrize("batches", [4, 7])
def test_k_batches_give_the_in_process_star_while_robots_cross_strips(batches):
    shape, params = Settings(shape="star", algorithm="rubenstein", robots=150, seed=2).resolve()
    whole, split = RubensteinRun(shape, params), RubensteinRun(shape, params)
    whole.run(1500)
    strips = batched(split, batches, 1500)
    assert strips.batches == batches and same(whole, split)
    assert (whole.robots.state == JOINED).sum() > 4  # robots left the pack and joined: some crossed strips


@pytest.mark.parametrize("shards, batches", [(2, 2), (3, 4)])
def test_world_shards_each_holding_its_columns_and_a_halo_give_the_in_process_run(shards, batches):
    """S world shards (swarm_ros.core.central_shards), each holding only the robots of its columns and one column
    either side, passing only border decisions, joins, counts and handovers: every shard's metrics are the run's,
    each robot's row its owner's, and no shard holds the whole swarm."""
    from swarm_ros.core.central_shards import run_sharded

    params = RunParams(40, algorithm="rubenstein", seed=5, range_noise=0.04)
    whole = RubensteinRun(square(6), params)
    whole.run(TICKS)
    world = run_sharded(lambda: RubensteinRun(square(6), params), RubensteinBatch, shards, batches, TICKS)
    owners = np.concatenate([w.own for w in world])
    assert np.array_equal(np.sort(owners), np.arange(40))
    for w in world:
        assert np.array_equal(w.run.history, whole.history)
        assert all(np.array_equal(a[w.own], b[w.own]) for a, b in zip(w.run.robots, whole.robots))
    assert (whole.robots.state == JOINED).sum() > 4 and min(w.present.size for w in world) < 40


def test_world_shards_send_their_batches_a_whole_view_once_then_the_changes(monkeypatch):
    """A shard holds only what lies within its reach; a robot that leaves it comes with the row that puts it outside,
    so its batches are sent their whole view once and then only the changes, as one world's are, and the run is
    still the one world's (a restarted shard sends its batches their whole views again)."""
    from swarm_ros.core.central_shards import run_sharded

    sent: list[bool] = []
    send = AreaFeed.send

    def spy(feed, *args, **kwargs):
        out = send(feed, *args, **kwargs)
        sent.extend(whole for _, whole in out.values())
        return out

    monkeypatch.setattr(AreaFeed, "send", spy)
    params = RunParams(40, algorithm="rubenstein", seed=5, range_noise=0.04)
    whole = RubensteinRun(square(6), params)
    whole.run(300)
    world = run_sharded(lambda: RubensteinRun(square(6), params), RubensteinBatch, 2, 3, 300, restarts={150: 1})
    assert all(np.array_equal(w.run.history, whole.history) for w in world)
    # the 3 batches' whole views at tick 0, and shard 1's 2 batches' again as it came back (from its save of tick 140);
    # all else changes: every batch a tick, and shard 1's two again for the ticks after its save
    assert sent.count(True) == 3 + 2 and sent.count(False) >= 3 * 299


@pytest.mark.parametrize("shards, restarts", [(2, {1: 0, 37: 1, 91: 0}), (3, {41: 1, 42: 2, 201: 1})])
def test_a_restarted_world_shard_goes_on_from_its_save_and_the_run_is_the_unbroken_one(shards, restarts):
    """A shard restarted from its last save, given again what its peers sent it since, decides those ticks again:
    every shard's metrics and robots are the one world's. Restarted as it was to decide tick 91 (or 41, 201), it
    had not saved tick 90 yet: it goes on from tick 80, as far behind as it can be (its peers sent it tick 91's);
    restarted before its first save, it starts from tick 0."""
    from swarm_ros.core.central_shards import run_sharded

    params = RunParams(40, algorithm="rubenstein", seed=5, range_noise=0.04)
    whole = RubensteinRun(square(6), params)
    whole.run(400)
    make = lambda: RubensteinRun(square(6), params)
    world = run_sharded(make, RubensteinBatch, shards, 4, 400, restarts=restarts, save_every=10)
    for w in world:
        assert np.array_equal(w.run.history, whole.history)
        assert all(np.array_equal(a[w.own], b[w.own]) for a, b in zip(w.run.robots, whole.robots))


def test_a_world_shard_serves_its_batches_only_and_refuses_a_strip_that_is_no_batchs():
    """World shard 1 of 2 over 4 batches admits batches 2 and 3: another shard's batch's announcement is not its
    concern (not dropped), a strip of no batch is, and the run starts once its own batches are in."""
    from swarm_ros.core.central_shards import CentralShard
    from swarm_ros.protocol.central_shard_world import ShardLockstep

    run = RubensteinRun(square(6), RunParams(40, algorithm="rubenstein", seed=5))
    strips = strips_for(run, 4)
    ls = ShardLockstep(CentralShard(run, strips, 1, 2), RubensteinWire, port=None)
    assert ls.mine == [2, 3] and ls.shard_index == 1
    assert ls.announce("robot_batch_0", strips.strip(0)) == [] and not ls.hosts  # shard 0's
    with pytest.raises(Rejected, match="no batch's strip"):
        ls.announce("robot_batch_9", (0, strips.strip(1)[1]))
    assert ls.announce("robot_batch_3", strips.strip(3)) == [] and not ls.started
    assert ls.announce("robot_batch_2", strips.strip(2)) == [2, 3] and ls.started
    with pytest.raises(Rejected, match="announced the strip of robot_batch_3"):
        ls.announce("robot_batch_7", strips.strip(3))
    assert ls.announce("robot_batch_2", strips.strip(2)) == [2]  # a batch's process again
    assert (
        set(ls.recorded()) <= set(ls.shard.present)
        and ls.own(2).size + ls.own(3).size == ls.shard.own.size - (run.robots.state[ls.shard.own] == JOINED).sum()
    )


def test_strips_share_the_robots_at_the_start_and_an_area_is_its_strip_and_one_column_either_side():
    start = np.array([0, 0, 0, 1, 1, 2, 5, 5, 9, 9, 9, 9])  # each robot's cell column at tick 0
    strips = Strips.balanced(start, 12, 3)
    assert strips.cuts.tolist() == [0, 2, 6, 12]  # 5, 3 and 4 robots: no cut can share 12 more evenly
    assert [strips.strip(k) for k in range(3)] == [(0, 1), (2, 5), (6, 11)]
    assert [strips.area(k) for k in range(3)] == [(0, 2), (1, 6), (5, 11)]
    assert Strips.balanced(np.full(9, 2), 5, 3).cuts.tolist() == [0, 3, 4, 5]  # one column each at least
    with pytest.raises(ParameterError, match="processes must be between 1 and the 15 cell columns, got 16"):
        Strips.balanced(start, 15, 16)
    shape, params = Settings(shape="star", algorithm="rubenstein", robots=1024).resolve()
    held = [area.size for area in (own_at_start(RubensteinRun(shape, params), 4, k) for k in range(4))]
    assert sum(held) == 1020 and max(held) < 2 * min(held), held  # the pack is shared, by whole columns


def own_at_start(run: RubensteinRun, batches: int, k: int) -> np.ndarray:
    strips = strips_for(run, batches)
    column = run.grid.columns(run.robots.x)
    return np.flatnonzero(strips.in_strip(column, k) & (run.robots.state != JOINED))


def test_a_batch_reads_only_its_area_and_decides_only_its_strip():
    """What a batch holds outside its area (here: garbage) changes nothing it decides; it decides for exactly the
    robots not joined whose cell lies in its strip."""
    shape, params = Settings(shape="star", algorithm="rubenstein", robots=150, seed=2).resolve()
    run = RubensteinRun(shape, params)
    run.run(1500)
    strips = strips_for(run, 4)
    k = 1  # half its area is the pack's edge, its strip's robots leaving it
    ids = area_of(run, strips, k)
    clean, dirty = RubensteinBatch(run, strips, k), RubensteinBatch(run, strips, k)
    rng = np.random.default_rng(0)
    garbage = Robots(*(rng.integers(-5, 5, a.size).astype(a.dtype) for a in run.robots))
    for a, b in zip(garbage, run.robots):
        a[ids] = b[ids]
    own, decided = clean.decide(run.tick + 1, ids, None, run.robots)
    own2, decided2 = dirty.decide(run.tick + 1, ids, None, garbage)
    assert np.array_equal(own, own2) and all(np.array_equal(a, b) for a, b in zip(decided, decided2))
    column = np.clip(np.floor((run.robots.x - run.cells.x0) / run.cells.side), 0, run.cells.nx - 1)
    first, last = strips.strip(k)
    expected = np.flatnonzero((column >= first) & (column <= last) & (run.robots.state != JOINED))
    assert own.size > 0 and np.array_equal(own, expected) and ids.size < params.robots


def test_the_world_refuses_parts_that_miss_or_repeat_a_robot():
    run = RubensteinRun(square(6), RunParams(40, algorithm="rubenstein", seed=1))
    strips = strips_for(run, 2)
    hosts = [RubensteinBatch(run, strips, k) for k in range(2)]
    parts = []
    for k, host in enumerate(hosts):
        ids = area_of(run, strips, k)
        parts.append(host.decide(1, ids, None, run.robots))
    with pytest.raises(ContractError, match="not one for each robot not joined"):
        run.settle(parts[:1] if parts[1][0].size else parts[1:])
    with pytest.raises(ContractError, match="not one for each robot not joined"):
        run.settle([*parts, parts[0] if parts[0][0].size else parts[1]])
    assert run.tick == 0
    run.settle(parts)
    assert run.tick == 1


def test_the_batches_give_the_in_process_run_through_the_wire_rows():
    """Every robot and decision passed as the rows the graph sends (RUBENSTEIN_ROW, RUBENSTEIN_DECISION_ROW), checked as
    a node checks them: the run is still the in-process one, with range noise, to the end."""
    params = RunParams(40, algorithm="rubenstein", seed=3, range_noise=0.04, max_ticks=TICKS)
    whole, split = RubensteinRun(square(6), params), RubensteinRun(square(6), params)
    whole.run()
    strips = strips_for(split, 3)
    hosts = [RubensteinBatch(split, strips, k) for k in range(3)]
    while split.outcome is None:
        tick, parts = split.tick + 1, []
        for k, host in enumerate(hosts):
            rows = rubenstein_rows(area_of(split, strips, k), split.robots)
            check_rubenstein_rows(rows, params.robots, split.tick)
            own, decided = host.decide(tick, *from_rows(split, strips, k, rows))
            answer = rubenstein_rows(own, decided)
            check_rubenstein_rows(answer, params.robots, tick)
            parts.append(decided_of_rows(answer))
        split.settle(parts)
    assert same(whole, split)


@pytest.mark.parametrize(
    "field,value,kind",
    [
        ("id", 40, "bad ids"),
        ("state", 5, "bad state"),
        ("est", 2, "bad state"),
        ("x", np.nan, "bad number"),
        ("ey", np.inf, "bad number"),
        ("near", -1.0, "bad number"),
        ("g", -2, "bad number"),
        ("began", 99, "bad number"),
        ("joined", 3, "bad state"),
        ("loc", 2, "bad state"),
        ("heading", np.nan, "bad number"),
        ("near", np.nan, "bad number"),
        ("waited", -2, "bad number"),
        ("blind", 51, "bad number"),
    ],
)
def test_a_hostile_row_is_rejected_by_kind(field, value, kind):
    run = RubensteinRun(square(6), RunParams(40, algorithm="rubenstein", seed=1))
    run.run(50)
    rows = rubenstein_rows(np.arange(40), run.robots)
    check_rubenstein_rows(rows, 40, 50)  # as sent: taken
    rows[field][-1] = value
    with pytest.raises(Rejected) as caught:
        check_rubenstein_rows(rows, 40, 50)
    assert caught.value.kind == kind


def test_rows_with_several_faults_are_rejected_for_the_first_check_that_fails():
    """The compiled check finds every fault in one pass; it names the one the documented order checks first,
    wherever in the rows the faults lie."""
    run = RubensteinRun(square(6), RunParams(40, algorithm="rubenstein", seed=1))
    run.run(50)
    rows = rubenstein_rows(np.arange(40), run.robots)
    rows["x"][3], rows["state"][20], rows["id"][39] = np.nan, 7, 38  # a number, a state, then a repeated id
    with pytest.raises(Rejected) as caught:
        check_rubenstein_rows(rows, 40, 50)
    assert str(caught.value) == "bad ids: ids must ascend within 0..39"
    rows["id"][39] = 39
    with pytest.raises(Rejected) as caught:
        check_rubenstein_rows(rows, 40, 50)
    assert caught.value.kind == "bad state"


def test_the_wire_rows_name_the_gradient_and_estimate_and_round_trip_the_sentinels():
    run = RubensteinRun(square(6), RunParams(40, algorithm="rubenstein", seed=1))
    rows = rubenstein_rows(np.arange(40), run.robots)
    assert {"x", "y", "z", "g", "ex", "ey", "state"} <= set(rows.dtype.names)
    assert rows["g"][-1] == -1 and rows["began"][-1] == -1  # unknown gradient, never began: -1 on the wire
    ids, back = robots_of_rows(rows)
    assert np.array_equal(ids, np.arange(40))
    assert all(np.array_equal(a, b) and a.dtype == b.dtype for a, b in zip(run.robots, back))


def lockstep_run(params: RunParams, batches: int, region_cuts: str = "") -> tuple[RubensteinRun, CentralLockstep]:
    """The graph's exchange without ROS: the world's lockstep, and batches as a robot-batch process runs them
    (:class:`CentralBatch`), each sent only its area as the message the world sends (each announcing its
    strip, in reverse order: the world numbers them from the west)."""
    run = RubensteinRun(square(6), params)
    ls = CentralLockstep(run, RubensteinWire)
    own = {"batches": batches, "region_cuts": region_cuts}
    hosts = [
        CentralBatch(run.shape, params, {**own, "batch": k, "name": f"robot_batch_{k}"}, _no_drop)
        for k in range(batches)
    ]
    for k in reversed(range(batches)):
        sent = ls.announce(f"robot_batch_{k}", hosts[k].strip)
    assert sent == list(range(batches)) and ls.started
    while run.outcome is None:  # each batch's whole view at tick 0, then each tick's changes
        for k, (rows, whole) in ls.areas(list(range(batches)), set()).items():
            inbox = hosts[k].inboxes[0 if whole else 1]
            topic = "area" if whole else "changes"
            assert inbox.topic == f"/swarm/rubenstein/{topic}/robot_batch_{k}"
            assert whole == (run.tick == 0)
            decided = inbox.take(decode_cloud(encode_cloud(rows, run.tick)))
            assert decided is not None
            settled = ls.decisions(k, decided[1], decided[0])
            assert settled == (k == batches - 1)
    return run, ls


def from_rows(run: RubensteinRun, strips: Strips, k: int, rows: np.ndarray) -> tuple:
    """What batch k decides from, given the rows of its whole view: (seen, changed, every robot's arrays)."""
    store = AreaStore(run, strips, k)
    changed = store.take(run.tick, *robots_of_rows(rows), True)
    return store.seen, changed, store.robots


def _no_drop(topic: str, fault: Rejected) -> None:
    raise AssertionError(f"{topic}: {fault}")


@pytest.mark.parametrize("batches", [1, 2, 4])
def test_the_worlds_lockstep_with_checked_decisions_gives_the_in_process_run(batches):
    params = RunParams(40, algorithm="rubenstein", seed=6, max_ticks=TICKS, range_noise=0.05)
    whole = RubensteinRun(square(6), params)
    whole.run()
    run, _ = lockstep_run(params, batches)
    assert same(whole, run)


def test_region_cuts_cut_the_strips_where_they_say_and_the_run_is_still_the_in_process_one():
    """``region_cuts`` are x positions in d: strip k starts at the cell column holding cut k - 1 (here the grid's 10
    columns, 3.5 d wide, span x = -16 to 19); a cut count or place that leaves a strip without a column is refused."""
    params = RunParams(40, algorithm="rubenstein", seed=6, max_ticks=TICKS, range_noise=0.05)
    whole = RubensteinRun(square(6), params)
    whole.run()
    run, ls = lockstep_run(params, 3, "-9,5")
    assert ls.cuts.tolist() == [0, 2, 6, 10] and same(whole, run)
    cells = whole.cells
    assert (cells.x0, cells.side, cells.nx) == (-16, 3.5, 10)
    with pytest.raises(ParameterError, match="^region_cuts gives 1 cuts; 3 batches need 2$"):
        strips_for(whole, 3, "5")
    for cuts in ("-9,-8", "-30", "19"):
        with pytest.raises(ParameterError, match=r"leave a strip with no cell column \(the grid's 10 columns, 3.5 d"):
            strips_for(whole, cuts.count(",") + 2, cuts)


def decisions_of_batch_0(run: RubensteinRun, ls: CentralLockstep) -> np.ndarray:
    host = RubensteinBatch(run, ls.strips, 0)
    own, decided = host.decide(run.tick + 1, area_of(run, ls.strips, 0), None, run.robots)
    return rubenstein_rows(own, decided)


def _set(field, how):
    def change(rows):
        rows[field] = how(rows)
        return rows

    return change


def join_at_7(rows):
    inside = np.flatnonzero(rows["state"] == 3)[:1]
    rows["state"][inside], rows["joined"][inside] = 4, 7
    return rows


@pytest.mark.parametrize(
    "change,kind",
    [
        (_set("x", lambda r: r["x"] + 0.01 * r["moves"]), "illegal: a move other than one step"),  # off the heading
        (_set("y", lambda r: r["y"] + 0.01 * (1 - r["moves"])), "illegal: a move other than one step"),  # no move
        (_set("heading", lambda r: (r["heading"] + 0.3) % 6.28), "illegal: a turn other"),  # beyond the rule's
        (_set("state", lambda r: np.where(r["state"] < 2, r["state"] + 2, r["state"])), "illegal: a state that skips"),
        (join_at_7, "illegal: a joining tick"),  # joins, at another tick than this
        (_set("began", lambda r: np.where(r["began"] >= 0, r["began"] - 1, r["began"])), "illegal: a tick the robot"),
        (_set("began", lambda r: np.where(r["state"] < 2, 5, r["began"])), "illegal: a tick the robot"),  # not begun
        (lambda r: r[:-1], "not its robots"),  # a robot left out
    ],
)
def test_the_world_rejects_decisions_out_of_the_rules_bounds(change, kind):
    run = RubensteinRun(square(6), RunParams(40, algorithm="rubenstein", seed=6, max_ticks=TICKS))
    run.run(600)  # robots are edge-following by now
    ls = CentralLockstep(run, RubensteinWire)
    ls.announce("robot_batch_0", (0, run.cells.nx - 1))
    rows = decisions_of_batch_0(run, ls)
    moving = rows[rows["moves"] == 1]
    assert moving.size > 0
    bad = change(rows.copy())
    with pytest.raises(Rejected) as caught:
        ls.decisions(0, run.tick + 1, bad)
    assert str(caught.value).startswith(kind) and not ls.decided
    with pytest.raises(Rejected, match="stale tick"):
        ls.decisions(0, run.tick + 2, rows)
    assert ls.decisions(0, run.tick + 1, rows) and run.tick == 601


def test_announcements_that_do_not_fit_the_run_are_rejected():
    """A strip outside the grid, one that overlaps another's, a node's second strip before the start; after it, a
    strip or a node that is not one of the run's batches. The run starts once the strips tile the grid."""
    ls = CentralLockstep(RubensteinRun(square(6), RunParams(40, algorithm="rubenstein")), RubensteinWire)
    last = ls.run.cells.nx - 1
    assert last >= 3
    assert ls.announce("robot_batch_0", (0, 1)) == [] and not ls.started
    before = [("robot_batch_1", (1, last)), ("robot_batch_1", (-1, 0)), ("robot_batch_1", (2, last + 1))]
    before += [("robot_batch_0", (0, 2)), ("robot_batch_1", (3, 2))]
    for name, strip in before:
        with pytest.raises(Rejected, match="^strip"):
            ls.announce(name, strip)
    assert ls.announce("robot_batch_2", (3, last)) == [] and not ls.started  # a gap: column 2 is no one's
    assert ls.announce("robot_batch_1", (2, 2)) == [0, 1, 2] and ls.started
    assert ls.hosts == {0: "robot_batch_0", 1: "robot_batch_1", 2: "robot_batch_2"}
    assert ls.cuts.tolist() == [0, 2, 3, last + 1] and ls.number("robot_batch_2") == 2 and ls.number("x") is None
    assert ls.announce("robot_batch_1", (2, 2)) == [1]  # a restarted batch: its own area again
    for name, strip in [("robot_batch_1", (0, 1)), ("other", (2, 2)), ("robot_batch_3", (0, last))]:
        with pytest.raises(Rejected, match="no batch's strip"):
            ls.announce(name, strip)


@pytest.mark.parametrize(
    "label, data, kind",
    [("robot_batch_1/2", [3, 5], None), ("x y", [3, 5], "batch name"), ("/swarm/x", [3, 5], "batch name"),
     ("robot_batch_1", [3], "strip"), ("robot_batch_1", [5, 3], "strip"), ("robot_batch_1", [3, 10], "strip")],
)  # fmt: skip
def test_an_announcement_is_read_whole_or_rejected_before_the_world_takes_its_name(label, data, kind):
    """What the world node reads of a /swarm/batches message (checks.announcement): a name the world makes topics
    of must be a node name, and the strip two columns of the grid, before CentralWorld.batch sees either."""
    from types import SimpleNamespace

    from swarm_ros.protocol.checks import announcement

    msg = SimpleNamespace(layout=SimpleNamespace(dim=[SimpleNamespace(label=label)]), data=data)
    if kind is None:
        assert announcement(msg, 10) == ("robot_batch_1", 2, (3, 5))
    else:
        with pytest.raises(Rejected, match=f"^{kind}"):
            announcement(msg, 10)


def test_a_world_checkpoint_round_trips_and_the_resumed_run_goes_on_as_the_unbroken_one(tmp_path):
    """Saved at a tick and resumed in a fresh run, the run continues exactly as the one never broken, to its end;
    a file that is not a checkpoint, or is another run's, fails in one line."""
    from swarm_ros.core.errors import RunFailed
    from swarm_ros.protocol import central_checkpoint as checkpoint

    params = RunParams(40, algorithm="rubenstein", seed=6, max_ticks=TICKS, range_noise=0.05)
    whole = RubensteinRun(square(6), params)
    whole.run(600)
    path = tmp_path / "world.checkpoint"
    checkpoint.save(path, whole, {0: "robot_batch_0", 1: "robot_batch_1"}, np.array([0, 2, whole.cells.nx]))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["world.checkpoint"]  # no temporary file left
    fresh = RubensteinRun(square(6), params)
    saved = checkpoint.load(path, fresh)
    assert (saved.tick, saved.hosts) == (600, {0: "robot_batch_0", 1: "robot_batch_1"})
    assert saved.cuts.tolist() == [0, 2, whole.cells.nx]
    whole.run()
    fresh.run()
    assert same(whole, fresh) and whole.outcome is not None
    path.write_bytes(b"not a checkpoint")
    with pytest.raises(RunFailed, match="does not read"):
        checkpoint.load(path, fresh)
    other = RubensteinRun(square(6), RunParams(30, algorithm="rubenstein"))
    checkpoint.save(path, other, {}, np.array([0, other.cells.nx]))
    with pytest.raises(RunFailed, match="is not of this run"):
        checkpoint.load(path, fresh)
    with pytest.raises(RunFailed, match="found no checkpoint"):
        checkpoint.load(tmp_path / "none", fresh)


def test_a_world_shards_checkpoint_holds_its_robots_and_another_shards_is_refused(tmp_path):
    """A world shard saves the robots it holds beside the run; resumed, it holds them again and its exchanges go on
    from the saved tick. Another shard's checkpoint (its batches and robots) fails in one line."""
    from swarm_ros.core.central_shards import CentralShard, take
    from swarm_ros.core.errors import RunFailed
    from swarm_ros.protocol import central_checkpoint as checkpoint
    from swarm_ros.protocol.central_shard_world import ShardLockstep

    params = RunParams(40, algorithm="rubenstein", seed=6, max_ticks=TICKS)
    whole = RubensteinRun(square(6), params)
    whole.run(300)
    strips = strips_for(whole, 4)
    shard = ShardLockstep(CentralShard(whole, strips, 1, 2), RubensteinWire, port=None)
    shard.resume({2: "robot_batch_2", 3: "robot_batch_3"}, strips.cuts, {"present": shard.shard.present})
    path = tmp_path / "world.checkpoint.1"
    checkpoint.save(path, whole, shard.hosts, strips.cuts, shard.kept())
    fresh = RubensteinRun(square(6), params)
    again = ShardLockstep(CentralShard(fresh, strips, 1, 2), RubensteinWire, port=None)
    saved = checkpoint.load(path, fresh)
    again.resume(saved.hosts, saved.cuts, saved.kept, before=400)
    assert np.array_equal(again.shard.present, shard.shard.present) and again.exchange.tick == 301
    assert again.started and again.mine == [2, 3] and again.hosts == shard.hosts
    # what a batch sent the process before comes again from its topic's history, of ticks settled in the checkpoint
    # or past it, up to the process before's next save: no fault; past that, a fault
    none = np.zeros(0, dtype=RubensteinWire.decision_row)
    assert again.decisions(2, 300, none) is False and again.decisions(2, 400, none) is False and again.decided == {}
    with pytest.raises(Rejected, match="stale tick"):
        again.decisions(2, 401, none)
    assert again.decisions(2, 301, none) is False and 2 in again.decided  # the tick being decided: taken
    sent: list[str] = []
    again.port = types.SimpleNamespace(**{f"send_{w}": lambda *_, w=w: sent.append(w) for w in ("border", "rows")})
    assert again.decisions(3, 301, none) is False and sent == ["border"]  # with its peer now, not settled yet
    assert again.decisions(2, 301, none) is False and again.decided == {}  # again (history and anew): a repeat
    # its peer's border and shared rows in, the shard's run is at tick 301 while it waits for its peer's rows to close
    # it. Decisions for tick 302 were not asked for yet: the process before's (up to its next save) are no fault, and
    # none is kept
    again.port.send_shared = lambda *_: sent.append("shared")
    none_ids = np.zeros(0, dtype=np.int64)
    again.exchange.border(0, 301, none_ids, take(again.exchange.decided_, slice(0, 0)))
    again.exchange.shared(0, 301, none_ids, take(again.run.robots, none_ids), np.zeros(3, np.int64), none_ids)
    assert again.run.tick == 301 and again.exchange.tick == 301 and sent == ["border", "shared", "rows"]
    assert again.decisions(2, 302, none) is False and again.decisions(3, 400, none) is False and again.decided == {}
    again.before = -1  # a process that was not restarted: decisions it did not ask for are a fault
    with pytest.raises(Rejected, match="decisions for tick 302; the shard is settling tick 301"):
        again.decisions(2, 302, none)
    assert again.decided == {}
    other = ShardLockstep(CentralShard(RubensteinRun(square(6), params), strips, 0, 2), RubensteinWire, port=None)
    with pytest.raises(RunFailed, match="not of this shard"):
        other.resume(saved.hosts, saved.cuts, saved.kept)
    with pytest.raises(RunFailed, match="not of this run"):
        again.resume(saved.hosts, saved.cuts, {"present": np.array([5, 3])})


def test_metrics_rows_a_restarted_world_sends_again_are_taken_once_and_must_equal_those_held():
    from swarm_ros.core.rubenstein.run import COLUMNS
    from swarm_ros.protocol.central_rows import check_metrics_rows
    from swarm_ros.protocol.central_rows import metrics_rows as rows_of

    def metrics_rows(history):
        return rows_of(history, COLUMNS)

    run = RubensteinRun(square(6), RunParams(40, algorithm="rubenstein", seed=6, max_ticks=TICKS))
    run.run(100)
    history = run.history
    held = history[:61]
    again = metrics_rows(history[41:81])  # ticks 41..80: 20 held, 20 new
    assert np.array_equal(check_metrics_rows(again, held, COLUMNS), history[61:81])
    assert check_metrics_rows(metrics_rows(history[:61]), held, COLUMNS).shape == (0, history.shape[1])  # all held
    changed = again.copy()
    changed["covered"][0] += 1
    with pytest.raises(Rejected, match="conflict"):
        check_metrics_rows(changed, held, COLUMNS)
    with pytest.raises(Rejected, match="stale tick"):
        check_metrics_rows(metrics_rows(history[62:70]), held, COLUMNS)  # a gap after tick 60
    with pytest.raises(Rejected, match="stale tick"):
        check_metrics_rows(metrics_rows(history[[61, 63]]), held, COLUMNS)  # not consecutive


def test_the_world_runs_at_least_one_record_and_at_most_what_the_topics_keep_past_the_monitor():
    from swarm_ros.protocol.central_world import monitor_reach
    from swarm_ros.protocol.plan import CENTRAL_KEPT

    assert monitor_reach(0, 20) is None  # no window: the world does not wait
    assert monitor_reach(128, 20) == 128
    assert monitor_reach(5, 20) == 20  # the monitor reports a tick only once its record is in
    assert monitor_reach(10**6, 20) == (CENTRAL_KEPT - 2) * 20
    for window in (1, 7, 128, 10**6):
        for every in (1, 3, 20, 1000):
            reach = monitor_reach(window, every)
            assert reach is not None
            records_past = reach // every + 1  # the records in (held, held + reach], and the end's own
            assert 1 <= reach // every and records_past <= CENTRAL_KEPT - 1


def test_the_monitors_held_report_is_checked():
    from swarm_ros.protocol.central_world import check_held

    run = RubensteinRun(square(6), RunParams(40, algorithm="rubenstein", seed=5))
    assert check_held(np.array([-1, 0]), run) == (-1, False)
    assert check_held(np.array([3000, 0]), run) == (3000, False)  # a restarted world's monitor may be past it
    for values in ([1], [1, 0, 0], [-2, 0], [10**12, 0], [0, 2], [0, 1]):  # the end only once the run has ended
        with pytest.raises(Rejected, match="held"):
            check_held(np.array(values), run)
    run.run()
    assert check_held(np.array([run.tick, 1]), run) == (run.tick, True)
    with pytest.raises(Rejected, match="held"):
        check_held(np.array([run.tick - 1, 1]), run)


def test_the_world_names_the_batches_it_waits_for():
    run = RubensteinRun(square(6), RunParams(40, algorithm="rubenstein", seed=6, max_ticks=TICKS))
    ls = CentralLockstep(run, RubensteinWire)
    strips = strips_for(run, 2)
    for k in range(2):
        ls.announce(f"robot_batch_{k}", strips.strip(k))
    assert ls.awaited() == ["robot_batch_0", "robot_batch_1"]
    ls.decisions(0, 1, decisions_of_batch_0(run, ls))
    assert ls.awaited() == ["robot_batch_1"]


def test_a_world_shard_names_its_batches_then_the_peer_shards_it_waits_for():
    """A still run's error names what the shard waits for: its batches' decisions, then, once they are in and sent
    on, the peer shard whose border decisions of the tick are not in."""
    from swarm_ros.core.central_shards import CentralShard
    from swarm_ros.protocol.central_shard_world import ShardLockstep

    class Port:
        def __getattr__(self, name):
            return lambda *args: None  # the messages to its peers: not looked at here

    run = RubensteinRun(square(6), RunParams(40, algorithm="rubenstein", seed=6, max_ticks=TICKS))
    strips = strips_for(run, 2)
    ls = ShardLockstep(CentralShard(run, strips, 0, 2), RubensteinWire, port=Port())
    ls.announce("robot_batch_0", strips.strip(0))
    assert ls.awaited() == ["robot_batch_0"]  # not shard 1's batch
    ls.decisions(0, 1, decisions_of_batch_0(run, ls))
    assert ls.awaited() == ["world_shard_1"]


def test_a_lapsed_peer_is_said_once_and_a_run_still_for_too_long_fails_naming_what_it_waits_for():
    """The watch behind the rubenstein world's liveliness lines and its STILL_S bound (a peer started by hand that
    died would otherwise keep the run waiting for ever)."""
    from swarm_ros.core.errors import RunFailed
    from swarm_ros.protocol.world_port import STILL_S, Watch

    watch = Watch(now=100.0)
    assert watch.liveliness("robot_batch_1", 1, 0) == "robot_batch_1 is alive (liveliness)"
    assert watch.liveliness("robot_batch_1", 1, 0) is None  # a change that says nothing new
    assert watch.liveliness("robot_batch_1", 0, 1) == "robot_batch_1 was lost (liveliness lapsed): the run waits for it"
    assert watch.liveliness("robot_batch_1", 0, 1) is None
    assert watch.lapsed == {"robot_batch_1"}
    assert not watch.still(100.0 + STILL_S - 1)
    watch.moved(150.0)  # a tick went out (a restarted process took the run up)
    assert not watch.still(100.0 + STILL_S + 1)
    assert watch.still(150.0 + STILL_S)
    failure = watch.failure(42, ["robot_batch_0", "robot_batch_1"], "")
    assert isinstance(failure, RunFailed)
    assert str(failure) == (
        f"the run has not moved for {STILL_S:g} s at tick 42 (waiting for: robot_batch_0, robot_batch_1 (liveliness "
        "lapsed); messages dropped: nothing): its processes are gone or their messages do not get through"
    )
    assert watch.liveliness("robot_batch_1", 1, 0) == "robot_batch_1 is back (liveliness)"
    assert watch.lapsed == set()


def world_run(window: int, every: int, tmp_path=None, slow: bool = False, tick_rate: float = 0.0, told: bool = True):
    """A CentralWorld over a fake port and clock, its batches' hosts fed the areas it sends, and a monitor that
    reports each record held as it goes out (``slow``: only once the world waits for it); ``told``: whether the
    status's readers acknowledge it. Checks, throughout, that the world never runs past the monitor's reach."""
    from swarm_ros.protocol.central_world import CentralWorld

    params = RunParams(40, algorithm="rubenstein", seed=6, max_ticks=TICKS)
    run, port, log, now = RubensteinRun(square(6), params), WorldPort(), Log(), [0.0]
    own = {"record_every": every, "monitor_window": window, "start_timeout": 60.0, "incarnation": 0}
    own.update(checkpoint=str(tmp_path / "world.npz") if tmp_path else "", tick_rate=tick_rate)
    port.clock, port.status_acked = (lambda: now[0]), told
    world = CentralWorld(run, RubensteinWire, own, port, log, Rejections(log), clock=port.clock)
    hosts = {}
    for k in reversed(range(2)):
        name = f"robot_batch_{k}"
        hosts[name] = CentralBatch(
            run.shape, params, {"batch": k, "batches": 2, "region_cuts": "", "name": name}, _no_drop
        )
        world.batch(name, hosts[name].strip)
    assert port.areas == [] and port.watched == ["robot_batch_1", "robot_batch_0"]
    world.poll()  # tick 0 goes out
    held, sent, world.waits = -1, 0, 0
    reach = monitor_reach(window, every)
    for _ in range(10**6):
        now[0] += 0.001
        moved = sent < len(port.areas)
        while sent < len(port.areas):  # the world sends the next areas as the last batch's decisions come in
            name, tick, rows, whole = port.areas[sent]
            sent += 1
            rows_out, at = hosts[name].inboxes[0 if whole else 1].take(decode_cloud(encode_cloud(rows, tick)))
            world.decisions(name, at, rows_out)
        out = max(port.areas[-1][1], port.records[-1][0])  # the last tick that went out
        assert reach is None or held < 0 or out <= held + reach
        last = port.records[-1][0]
        ended = world.ended_at is not None and last == run.tick
        if last > held and (not slow or not moved):
            world.waits += slow and not ended
            held = last
            moved = True
            world.held_report(np.array([held, int(ended)]))
        if tick_rate:  # the node polls when the world says a held tick is due; the fake clock gets there
            wait = world.wake_in()
            assert wait is None or wait <= 1 / tick_rate
            moved = moved or wait is not None
        world.poll()
        if world.finished:
            return run, world, port
        if not moved and not world.held_end:  # (at the end, with no acknowledgement, the fake clock runs on)
            raise AssertionError(f"stuck at tick {run.tick}")
    raise AssertionError("no end")


@pytest.mark.parametrize(("window", "every"), [(0, 20), (40, 20), (5, 7)])
def test_the_worlds_logic_over_a_fake_port_runs_the_in_process_run_with_a_record_every_k_ticks(window, every, tmp_path):
    params = RunParams(40, algorithm="rubenstein", seed=6, max_ticks=TICKS)
    whole = RubensteinRun(square(6), params)
    whole.run()
    run, world, port = world_run(window, every, tmp_path)
    assert same(whole, run)
    ticks = [tick for tick, _, _ in port.records]
    assert ticks == [*range(0, run.tick, every), run.tick] or ticks == list(range(0, run.tick + 1, every))
    metrics = np.concatenate([m for _, m, _ in port.records])
    assert len(metrics) == run.tick + 1  # every tick's metrics row once, in order
    assert port.clocks == list(range(run.tick + 1))  # /clock: each tick once, as it goes out
    assert port.statuses[-1][:2] == (run.tick, str(run.outcome)) and world.finished
    said = port.statuses[-1][3]  # what the study's model's world says too: the monitor's summary takes it
    assert said["startup_seconds"] == "1.500" and float(said["wall_seconds"]) > 0 and said["rejected_messages"] == 0
    first = port.statuses[0]
    assert first[:2] == (0, "running") and "startup_seconds" in first[3] and "wall_seconds" not in first[3]
    done, total, words = run.progress()  # what the launcher's bar shows, as simulate's does
    assert (said["progress"], said["progress_total"], said["progress_words"], said["joined"]) == (
        done,
        total,
        "joined",
        int(words["joined"]),  # (the tick's metrics by name too: a number; on the wire, text)
    )
    assert (tmp_path / "world.npz").exists()


def test_a_world_whose_batches_have_not_acknowledged_the_outcome_waits_for_them_at_most_linger_seconds():
    """The monitor holds the end, but a batch has not acknowledged the status: the world's exit would lose the
    outcome the batch stops on, so the world stays, for LINGER seconds at most (a dead batch never acknowledges)."""
    from swarm_ros.protocol.central_world import LINGER

    run, world, port = world_run(40, 20, told=False)
    assert world.held_end and world.finished
    assert port.clock() - world.ended_at == pytest.approx(LINGER, abs=0.01)  # it waited the whole grace
    assert (
        world.log.lines[-1]
        == f"exits {LINGER:g} s after the end with the outcome in the status unacknowledged by a reader"
    )
    _, at_once, quick = world_run(40, 20)  # every reader acknowledges: it ends once the monitor holds the end
    assert at_once.finished and quick.clock() - at_once.ended_at < 0.01
    assert not any("unacknowledged" in line for line in at_once.log.lines)


def test_the_world_holds_a_tick_past_the_monitors_reach_until_the_monitor_reports_more():
    run, world, port = world_run(40, 20, slow=True)
    assert world.waits > 10 and world.held_end and world.finished  # it waited, again and again, and ended
    params = RunParams(40, algorithm="rubenstein", seed=6, max_ticks=TICKS)
    whole = RubensteinRun(square(6), params)
    whole.run()
    assert same(whole, run)


def _cloud(rows: np.ndarray, tick: int):
    return decode_cloud(encode_cloud(rows, tick))


def _monitor(shards: int = 1):
    from swarm_ros.protocol.central_monitor import CentralMonitor

    logged: list[int] = []
    recorder = types.SimpleNamespace(
        log=lambda copy: logged.append(copy.tick), event=lambda t, text: logged.append(text)
    )
    copy = RubensteinRun(square(6), RunParams(40, algorithm="rubenstein", seed=6, max_ticks=TICKS))
    return CentralMonitor(copy, RubensteinWire, shards, recorder, clock=lambda: 0.0), logged


@pytest.fixture(scope="module")
def recorded():
    """A run of the world's logic with a record every 7 ticks, and what it sent the monitor (its port)."""
    run, _, port = world_run(0, 7)
    return run, port


def test_the_monitor_holds_each_record_once_its_metrics_are_in_and_ends_with_the_run_the_world_ran(recorded):
    run, port = recorded
    monitor, logged = _monitor()
    held = -1
    for tick, metrics, robots in port.records:
        assert not monitor.due()
        assert monitor.robots_record(_cloud(robots, tick))
        assert monitor.held() == (held, False)  # the record's metrics are still to come
        monitor.metrics(_cloud(metrics, tick))
        assert monitor.held() == (tick, False)
        held = tick
        assert not monitor.robots_record(_cloud(robots, tick))  # a record held: again, not taken
        monitor.metrics(_cloud(metrics, tick))  # rows of ticks held, again: equal, so nothing changes
        assert monitor.last_tick == tick
    changed = port.records[-1][1].copy()
    changed["covered"][-1] += 1
    with pytest.raises(Rejected, match="conflict"):
        monitor.metrics(_cloud(changed, run.tick))
    monitor.status({"outcome": "running"}, run.tick)
    assert not monitor.due()
    said = {"outcome": str(run.outcome), "wall_seconds": "2.500", "startup_seconds": "1.250", "rejected_messages": "3"}
    said["restarts"] = "12:robot_batch_1"  # (as the world lists them: its own and its batches')
    monitor.status(said, run.tick)
    assert monitor.held() == (run.tick, True) and monitor.due()
    assert monitor.finish(run.outcome) == 2.5  # tick 0 to the outcome, on the world's clock
    assert same(run, monitor.copy)
    fields = {"startup_seconds": 1.25, "rejected_messages": {"world": 3, "monitor": 2}, "world_shards": 1}
    assert monitor.graph_fields(2) == {**fields, "restarts": [{"tick": 12, "node": "robot_batch_1"}]}
    restart = "robot_batch_1 restarted at tick 12: a new process took over its robots"
    assert logged == [tick for tick, _, _ in port.records[1:]] + [restart]  # each record but tick 0's, once


def test_records_that_come_ahead_of_their_metrics_are_each_recorded_in_order_once_they_are_in(recorded):
    """As a restarted monitor reads the topics' histories: every record first, then every metrics message."""
    run, port = recorded
    monitor, logged = _monitor()
    for tick, _, robots in port.records:
        assert monitor.robots_record(_cloud(robots, tick))
    assert logged == []
    half = len(port.records) // 2
    for tick, metrics, _ in port.records[:half]:
        monitor.metrics(_cloud(metrics, tick))
    assert logged == [tick for tick, _, _ in port.records[1:half]]
    for tick, metrics, _ in port.records[half:]:
        monitor.metrics(_cloud(metrics, tick))
    assert logged == [tick for tick, _, _ in port.records[1:]]
    monitor.status({"outcome": str(run.outcome)}, run.tick)
    monitor.finish(run.outcome)
    assert same(run, monitor.copy)  # left at the last record


def test_a_monitor_fails_rather_than_waits_once_the_outcome_came_without_its_record():
    from swarm_ros.protocol.central_monitor import STATUS_WAIT, CentralMonitor

    now = [0.0]
    copy = RubensteinRun(square(6), RunParams(40, algorithm="rubenstein", seed=6, max_ticks=TICKS))
    monitor = CentralMonitor(copy, RubensteinWire, clock=lambda: now[0])
    monitor.status({"outcome": "running"}, 3)
    now[0] = 100.0
    assert monitor.world_end_failure() is None  # no outcome: a run may take any time
    monitor.status({"outcome": "complete"}, 40)
    now[0] += STATUS_WAIT - 0.1
    assert monitor.world_end_failure() is None
    now[0] += 0.1
    failure = monitor.world_end_failure()
    assert failure is not None and "reached the monitor only up to tick -1 within 5 s" in str(failure)


def test_the_monitor_takes_a_record_whole_from_the_world_shards_parts_in_any_order(recorded):
    run, port = recorded
    monitor, _ = _monitor(shards=2)
    for tick, metrics, robots in port.records:
        monitor.metrics(_cloud(metrics, tick))
        west, east = robots[robots["id"] % 2 == 0], robots[robots["id"] % 2 == 1]
        assert monitor.robots_record(_cloud(east, tick)) and monitor.robots_tick < tick  # half a record
        assert not monitor.robots_record(_cloud(east, tick))  # the same part again (a restarted shard's)
        with pytest.raises(Rejected, match="conflict"):
            monitor.robots_record(_cloud(east[:1], tick))  # a robot the record holds already
        assert monitor.robots_record(_cloud(west, tick)) and monitor.held() == (tick, False)
    monitor.status({"outcome": str(run.outcome)}, run.tick)
    monitor.finish(run.outcome)
    assert monitor.due() and same(run, monitor.copy)


def test_a_monitor_stopped_mid_run_keeps_the_metrics_up_to_its_last_record(recorded):
    _, port = recorded
    monitor, _ = _monitor()
    assert not monitor.cut_at_record()  # nothing in: nothing to write
    (t0, m0, r0), (t1, m1, _) = port.records[:2]
    monitor.robots_record(_cloud(r0, t0))
    monitor.metrics(_cloud(m0, t0))
    monitor.metrics(_cloud(m1, t1))  # the metrics of the next 7 ticks, whose record did not come
    assert monitor.last_tick == t1 and monitor.cut_at_record()
    assert monitor.last_tick == t0 == 0 and len(monitor.history) == 1


@pytest.mark.parametrize("recorder", [True, False])
def test_a_monitor_stopped_as_records_come_ahead_of_their_metrics_keeps_the_last_record_they_reached(
    recorded, recorder
):
    """CI stopped a run 60 ms after tick 0: the robots of 14 records were in, the metrics of tick 0 only. The run so
    far is tick 0's record, not none."""
    from swarm_ros.protocol.central_monitor import CentralMonitor

    _, port = recorded
    monitor, _ = _monitor()
    if not recorder:
        monitor = CentralMonitor(monitor.copy, RubensteinWire, clock=lambda: 0.0)
    t0, m0, _ = port.records[0]
    for tick, _, robots in port.records[:4]:
        monitor.robots_record(_cloud(robots, tick))
    monitor.metrics(_cloud(m0, t0))
    assert monitor.robots_tick == port.records[3][0] and monitor.cut_at_record()
    assert monitor.robots_tick == monitor.last_tick == 0 and len(monitor.history) == 1
    monitor.finish(Outcome.INTERRUPTED)
    zero = RubensteinRun(square(6), RunParams(40, algorithm="rubenstein", seed=6, max_ticks=TICKS))
    zero.outcome = Outcome.INTERRUPTED
    assert same(zero, monitor.copy)  # tick 0, its robots, its metrics row


def test_a_restarted_world_keeps_the_runs_clock_from_its_checkpoint(tmp_path):
    """startup_seconds and wall_seconds are the run's, not the restarted process's (the study's model's world keeps
    them in its book the same way)."""
    from swarm_ros.protocol.central_world import CentralWorld

    world_run(0, 20, tmp_path)  # its last checkpoint stays (the fake port never removes it)
    params, log = RunParams(40, algorithm="rubenstein", seed=6, max_ticks=TICKS), Log()
    own = {"record_every": 20, "monitor_window": 0, "start_timeout": 60.0, "incarnation": 1}
    own["checkpoint"] = str(tmp_path / "world.npz")
    again = CentralWorld(RubensteinRun(square(6), params), RubensteinWire, own, WorldPort(), log, Rejections(log))
    assert again.startup == 1.5 and again.started_at is not None and again.run.tick % 1000 == 0  # a checkpoint's


def test_tick_rate_paces_the_world_and_the_run_is_the_same():
    """The world parameter tick_rate (to watch a run live), as the study's model's world has it: no two ticks go
    out less than 1 / tick_rate apart."""
    params = RunParams(40, algorithm="rubenstein", seed=6, max_ticks=TICKS)
    whole = RubensteinRun(square(6), params)
    whole.run()
    run, _, port = world_run(0, 20, tick_rate=200.0)
    assert same(whole, run)
    ticks = np.array([tick for _, tick, _, _ in port.areas])
    first = np.unique(ticks, return_index=True)[1]  # the first area of each tick: when the tick went out
    assert np.diff(np.array(port.sent_at)[first]).min() >= 1 / 200 - 1e-9


def test_a_running_world_says_its_progress_ten_times_a_second():
    """The launcher's progress bar follows the status alone: a central world sends one every STATUS_PERIOD while
    it runs, as the study's model's world does, not only on events."""
    from swarm_ros.protocol.central_world import CentralWorld
    from swarm_ros.protocol.world_port import STATUS_PERIOD

    params, log, now = RunParams(40, algorithm="rubenstein", seed=6, max_ticks=TICKS), Log(), [0.0]
    port = WorldPort()
    own = {"record_every": 20, "monitor_window": 0, "start_timeout": 60.0, "incarnation": 0, "checkpoint": ""}
    world = CentralWorld(
        RubensteinRun(square(6), params), RubensteinWire, own, port, log, Rejections(log), lambda: now[0]
    )
    for k in range(2):
        batch = CentralBatch(
            square(6), params, {"batch": k, "batches": 2, "region_cuts": "", "name": f"b{k}"}, _no_drop
        )
        world.batch(f"b{k}", batch.strip)
    world.poll()  # tick 0 goes out, with a status
    said = len(port.statuses)
    now[0] += STATUS_PERIOD / 2
    world.poll()
    assert len(port.statuses) == said  # not yet
    now[0] += STATUS_PERIOD / 2
    world.poll()
    assert len(port.statuses) == said + 1 and port.statuses[-1][1] == "running"
    assert port.statuses[-1][3]["progress_total"] == world.run.progress()[1]


def test_a_restarted_batchs_second_answer_to_the_tick_just_settled_is_a_repeat_not_a_fault():
    """A batch process restarted mid-run answers the area its topic kept (which may settle the tick), then the same
    area again, which the world sent it as it announced itself: the second answer is the first's, not a stale tick
    (a run with a batch killed once reported a message dropped). Older ticks' still are."""
    params = RunParams(40, algorithm="rubenstein", seed=6, max_ticks=TICKS)
    run = RubensteinRun(square(6), params)
    ls = CentralLockstep(run, RubensteinWire)
    ls.announce("robot_batch_0", strips_for(run, 1).strip(0))
    for _ in range(3):
        rows = decisions_of_batch_0(run, ls)
        assert ls.decisions(0, run.tick + 1, rows)
    assert run.tick == 3
    assert not ls.decisions(0, run.tick, rows)  # tick 3's decisions again: taken as the repeat they are
    with pytest.raises(Rejected, match="stale tick"):
        ls.decisions(0, run.tick - 1, rows)


def test_a_batch_process_that_came_back_is_sent_its_whole_view_and_the_run_is_the_unbroken_one():
    """After tick 0 a batch is sent only the rows that changed (it keeps the rest). A process that comes back
    finds in its topics' histories the last whole view (tick 0's) and the last changes, which it cannot follow: it
    answers the first (the world takes that for what it is, not a fault, even once it sent the next whole view) and
    leaves the second; the whole view the world sends it as it announces itself again brings it back into the run."""
    params = RunParams(40, algorithm="rubenstein", seed=6, max_ticks=TICKS)
    whole = RubensteinRun(square(6), params)
    whole.run()
    run = RubensteinRun(square(6), params)
    ls = CentralLockstep(run, RubensteinWire)

    def batch(k):
        own = {"batch": k, "batches": 2, "region_cuts": "", "name": f"robot_batch_{k}"}
        return CentralBatch(run.shape, params, own, _no_drop)

    hosts = [batch(0), batch(1)]
    for k in (0, 1):
        ls.announce(f"robot_batch_{k}", hosts[k].strip)
    kept: dict[tuple[int, bool], bytes] = {}  # the last message of each batch's two topics

    def deliver(k: int, entire: bool) -> None:
        reply = hosts[k].inboxes[0 if entire else 1].take(decode_cloud(kept[k, entire]))
        assert reply is not None
        ls.decisions(k, reply[1], reply[0])

    back = False
    while run.outcome is None:
        tick = run.tick
        for k, (rows, entire) in ls.areas([0, 1], set()).items():
            assert entire == (tick == 0)
            kept[k, entire] = encode_cloud(rows, tick)
            if not (k == 1 and tick == 30):  # batch 1's process is gone before it answers tick 30's changes
                deliver(k, entire)
        if tick == 30 and not back:
            back, hosts[1] = True, batch(1)
            assert hosts[1].inboxes[1].take(decode_cloud(kept[1, False])) is None  # tick 30's changes: left
            old, decides = hosts[1].inboxes[0].take(decode_cloud(kept[1, True]))  # tick 0's whole view
            taken = decode_cloud(kept[1, True]).width * RubensteinWire.row.itemsize  # (the benches read it)
            assert hosts[1].received == taken and f"received {taken} bytes of rows" in hosts[1].summary()
            assert ls.announce("robot_batch_1", hosts[1].strip) == [1]
            (rows, entire), *_ = ls.areas([1], {1}).values()
            kept[1, True] = encode_cloud(rows, run.tick)
            assert entire and ls.wholes[1] == {0, 30}
            assert decides == 1 and not ls.decisions(1, decides, old)  # its answer to tick 0's, come late: no fault
            deliver(1, True)
    assert back and same(whole, run)


def test_a_whole_view_older_than_the_batch_holds_is_kept_beside_it_and_the_changes_tell_which_to_follow():
    """A whole view the world sent a batch process as it came back may reach it after changes it had already followed;
    a world that went on from its checkpoint sends every batch the whole view of that older tick. The batch keeps such
    a view beside what it holds and follows whichever the next changes follow: the run is the in-process one both
    ways, and the late view's answer is no fault."""
    params = RunParams(40, algorithm="rubenstein", seed=6, max_ticks=TICKS)
    whole = RubensteinRun(square(6), params)
    whole.run()
    host = CentralBatch(
        square(6), params, {"batch": 0, "batches": 1, "region_cuts": "", "name": "robot_batch_0"}, _no_drop
    )

    def world(run, saved=None):
        ls = CentralLockstep(run, RubensteinWire)
        if saved is None:
            ls.announce("robot_batch_0", host.strip)
        else:
            ls.resume({0: "robot_batch_0"}, saved, {})
        return ls

    run = RubensteinRun(square(6), params)
    ls, late, saved, checkpoint = world(run), None, None, None
    while run.outcome is None:
        (rows, entire), *_ = ls.areas([0], set()).values()
        if run.tick == 20:
            late = encode_cloud(ls.area(0), 20)  # the whole view sent as it came back, after the changes of tick 20
        reply = host.inboxes[0 if entire else 1].take(decode_cloud(encode_cloud(rows, run.tick)))
        assert reply is not None
        ls.decisions(0, reply[1], reply[0])
        if run.tick == 22:  # it reaches the batch only now, two ticks on: answered, no fault, and the run goes on
            old, decides = host.inboxes[0].take(decode_cloud(late))
            assert decides == 21 and not ls.decisions(0, decides, old)
        if run.tick == 30 and checkpoint is None:
            checkpoint = ({k: np.copy(v) for k, v in run.saved().items()}, ls.cuts)
        if run.tick == 40 and saved is None and checkpoint is not None:  # the world goes back to that checkpoint
            run, saved = RubensteinRun(square(6), params), checkpoint[1]
            run.restore(30, checkpoint[0])
            ls = world(run, saved)
    assert late is not None and saved is not None and same(whole, run)


def test_the_restarts_a_world_lists_are_taken_even_when_a_restarted_world_lists_others():
    """A world restarted from its checkpoint of tick 0 forgets a batch's restart it had listed, and lists it again at
    its own tick when the batch announces itself: its longer list replaces the shorter, each new item is told once."""
    from swarm_ros.protocol.status import WorldReport

    report = WorldReport()
    assert report.update({"restarts": "150:robot_batch_1"}) == [(150, "robot_batch_1")]
    assert report.update({"restarts": "0:world"}) == []  # not longer: the list it had stays
    assert report.update({"restarts": "0:world;200:robot_batch_1"}) == [(0, "world"), (200, "robot_batch_1")]
    assert report.restarts == [(0, "world"), (200, "robot_batch_1")]


def test_the_world_lists_each_new_batch_process_and_its_own_restart_in_its_status_and_checkpoint(tmp_path):
    """A later incarnation, or one started with the same command (ros2 launch's respawn: another process's nonce,
    heard before or after the last one's liveliness lapsed), is a restart; an announcement heard again (a latched one)
    is not. A restarted world keeps the list of its checkpoint and adds itself at the checkpoint's tick."""
    from swarm_ros.protocol.central_world import CentralWorld
    from swarm_ros.protocol.status import restarts_of

    params, log = RunParams(40, algorithm="rubenstein", seed=6, max_ticks=TICKS), Log()
    own = {"record_every": 20, "monitor_window": 0, "start_timeout": 60.0, "incarnation": 0}
    own["checkpoint"] = str(tmp_path / "world.npz")
    world = CentralWorld(RubensteinRun(square(6), params), RubensteinWire, own, WorldPort(), log, Rejections(log))
    strips = {
        f"b{k}": CentralBatch(
            square(6), params, {"batch": k, "batches": 2, "region_cuts": "", "name": f"b{k}"}, _no_drop
        ).strip
        for k in range(2)
    }
    for name, strip in strips.items():
        world.batch(name, strip, process=f"{name} first")
    world.poll()  # tick 0 goes out, and is saved
    world.batch("b0", strips["b0"], process="b0 first")  # heard again: no new process
    world.batch("b1", strips["b1"], incarnation=1, process="b1 second")
    world.batch("b0", strips["b0"], process="b0 second")  # the same command again, its process's lapse not yet heard
    world.liveliness("b0", 0, 1)
    world.batch("b0", strips["b0"], process="b0 second")  # heard again
    world.batch("b0", strips["b0"], process="b0 third")  # the same command again, after a lapse
    assert world.restarts == [(0, "b1"), (0, "b0"), (0, "b0")]
    world.status("running", "running")
    assert restarts_of(world.port.statuses[-1][3]["restarts"]) == world.restarts
    world._save()
    own["incarnation"] = 1
    again = CentralWorld(RubensteinRun(square(6), params), RubensteinWire, own, WorldPort(), log, Rejections(log))
    assert again.restarts == [(0, "b1"), (0, "b0"), (0, "b0"), (0, "world")]
    again.batch("b1", strips["b1"], incarnation=1, process="b1 second")  # its announcement, latched, again: known
    again.batch("b0", strips["b0"], process="b0 third")
    assert len(again.restarts) == 4


def test_a_world_still_at_its_first_tick_for_want_of_the_monitors_readers_says_what_its_graph_lists():
    """A full run of the suite saw a world wait 120 s for a monitor it heard alive; its error now says who reads
    the run's topics."""
    from swarm_ros.core.errors import RunFailed
    from swarm_ros.protocol.central_world import CentralWorld
    from swarm_ros.protocol.world_port import STILL_S

    params, log, now = RunParams(40, algorithm="rubenstein", seed=6, max_ticks=TICKS), Log(), [0.0]
    own = {"record_every": 20, "monitor_window": 0, "start_timeout": 60.0, "incarnation": 0, "checkpoint": ""}
    port = WorldPort()
    port.reads = False
    run = RubensteinRun(square(6), params)
    world = CentralWorld(run, RubensteinWire, own, port, log, Rejections(log), clock=lambda: now[0])
    for k in range(2):
        own_k = {"batch": k, "batches": 2, "region_cuts": "", "name": f"b{k}"}
        world.batch(f"b{k}", CentralBatch(square(6), params, own_k, _no_drop).strip)
    world.poll()
    assert world.first  # tick 0 waits
    now[0] = STILL_S + 1
    with pytest.raises(RunFailed, match=r"at tick 0 \(waiting for: monitor, whose readers this world's ROS graph "
                       r"lists as /swarm/status: robot_batch_0;"):  # fmt: skip
        world.poll()


def test_a_new_batch_process_that_announces_itself_counts_as_alive_and_its_next_lapse_is_a_loss():
    """Should the liveliness event of a restarted batch's process be lost (CI saw the world then miss its second death
    and wait 120 s), its announcement says it is alive: its next lapse is seen."""
    from swarm_ros.protocol.central_world import CentralWorld

    params, log = RunParams(40, algorithm="rubenstein", seed=6, max_ticks=TICKS), Log()
    own = {"record_every": 20, "monitor_window": 0, "start_timeout": 60.0, "incarnation": 0, "checkpoint": ""}
    world = CentralWorld(RubensteinRun(square(6), params), RubensteinWire, own, WorldPort(), log, Rejections(log))
    strips = {}
    for k in range(2):
        own_k = {"batch": k, "batches": 2, "region_cuts": "", "name": f"b{k}"}
        strips[f"b{k}"] = CentralBatch(square(6), params, own_k, _no_drop).strip
        world.batch(f"b{k}", strips[f"b{k}"])
    world.poll()
    world.liveliness("b1", 0, 1)
    assert world.watch.lapsed == {"b1"}
    world.batch("b1", strips["b1"], incarnation=1)  # (its liveliness event, lost)
    assert world.watch.lapsed == set()
    world.liveliness("b1", 0, 1)  # it dies again
    assert world.watch.lapsed == {"b1"}
