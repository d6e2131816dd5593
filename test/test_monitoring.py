"""The monitor's side of a run (swarm_ros.protocol.monitoring) driven by method calls, a fake port and a fake
clock, with no rclpy: what the process tests of the monitor cover (its count, its wait for the world's outcome,
its refusals, a restarted monitor's replay), in milliseconds.

The world's rows are what a world process publishes after each tick of the in-process engine (every robot at
tick 0, then the rows of the robots that decided or were removed), serialized and read back as the monitor
reads them, so the count must be the engine's tick for tick.
"""

from __future__ import annotations

import numpy as np
import pytest
from lockstep_fakes import Clock, Log
from runs import disc_shape

from swarm_ros.core import RunParams, Simulation, World
from swarm_ros.core.errors import Rejected, RunFailed
from swarm_ros.core.metrics import Outcome, TickMetrics
from swarm_ros.core.rules import Decider
from swarm_ros.core.state import RobotState
from swarm_ros.protocol.cdr import decode_cloud, encode_cloud
from swarm_ros.protocol.monitoring import BAG_WAIT, STATUS_WAIT, MonitorCore
from swarm_ros.protocol.plan import MONITOR
from swarm_ros.protocol.rows import decision_rows, state_rows
from swarm_ros.protocol.status import restarts_text
from swarm_ros.protocol.world_records import state_counts

pytestmark = pytest.mark.unit

WORLD = World(radius=12)
SHAPE = disc_shape(WORLD, 5.0)


class Port:
    """Records what the core asks of its node."""

    def __init__(self) -> None:
        self.counted: list[tuple[int, bool, bool]] = []  # (tick, first, changed)
        self.decisions: list[int] = []
        self.missed = 0  # how many take_missed() hands over (once)
        self.on_missed = None  # called by take_missed(): a message the executor had not handed over

    def tick_counted(self, tick, metrics, occupancy, first, changed, messages) -> None:
        assert isinstance(metrics, TickMetrics) and metrics.tick == tick
        self.counted.append((tick, first, changed))

    def decisions_taken(self, tick: int) -> None:
        self.decisions.append(tick)

    def take_missed(self) -> int:
        if self.on_missed is not None:
            self.on_missed()
            self.on_missed = None
        missed, self.missed = self.missed, 0
        return missed


class Recorder:
    """Records what the core hands the recording."""

    def __init__(self) -> None:
        self.closed, self.every = False, 1
        self.ticks: list[int] = []
        self.forced: list[bool] = []
        self.events: list[tuple[int, str]] = []
        self.ended: tuple[str, int] | None = None

    def metrics(self, rows: list) -> None:
        self.ticks += [r.tick for r in rows]

    def robots(self, state, force: bool = False) -> None:
        self.forced.append(force)

    def event(self, tick: int, text: str) -> None:
        self.events.append((tick, text))

    def outcome(self, outcome: str, final: TickMetrics) -> None:
        assert not self.closed
        self.ended = (outcome, final.tick)

    def close(self) -> None:
        self.closed = True


def world_rows(params: RunParams) -> tuple[Simulation, list[tuple[np.ndarray, np.ndarray | None]]]:
    """The engine's run, and per tick the rows a world process publishes and its applied decisions (None at
    tick 0)."""
    sim, decider = Simulation(SHAPE, params), Decider(SHAPE, params)
    out: list[tuple[np.ndarray, np.ndarray | None]] = [(state_rows(np.arange(params.robots), sim.state), None)]
    while not sim.done:
        decisions = decider.decide(sim.state, sim.moving_ids(), sim.tick + 1)
        sim.apply(decisions)
        ids = np.union1d(np.sort(decisions.ids), sim.last_removed)
        out.append((state_rows(ids, sim.state), decision_rows(decisions)))
    return sim, out


def world_messages(params: RunParams) -> tuple[Simulation, list[tuple[bytes, bytes | None]]]:
    """:func:`world_rows`, serialized."""
    sim, rows = world_rows(params)
    return sim, [(encode_cloud(r, t), None if d is None else encode_cloud(d, t)) for t, (r, d) in enumerate(rows)]


def make(params: RunParams, recorder: Recorder | None = None, **kw) -> tuple[MonitorCore, Port, Clock, Log]:
    port, clock, log = Port(), Clock(), Log()
    core = MonitorCore(SHAPE, params, WORLD.radius, port, recorder, log, clock=clock, **kw)
    return core, port, clock, log


def feed(core: MonitorCore, messages, upto: int | None = None) -> None:
    for rows, decided in messages[:upto]:
        core.robots(decode_cloud(rows))
        if decided is not None:
            core.decisions(decode_cloud(decided))


@pytest.mark.parametrize(
    "params",
    [
        RunParams(robots=60, seed=3, max_ticks=400),
        RunParams(robots=90, seed=5, rules="local", vision_radius=3.0, max_ticks=400),
        RunParams(robots=60, seed=7, max_ticks=300, fail_fraction=0.2, fail_tick=20),
        RunParams(robots=60, seed=1, max_ticks=300, fail_fraction=0.2, fail_tick=3),  # no robot joins at tick 3
    ],
)
def test_the_core_counts_the_worlds_rows_as_the_engine_does(params):
    sim, messages = world_messages(params)
    recorder = Recorder()
    core, port, clock, log = make(params, recorder)
    feed(core, messages)
    assert [tuple(r) for r in core.rows] == [tuple(r) for r in sim.history]
    assert core.outcome == sim.outcome and core.losses == sim.losses
    assert [t for t, _, _ in port.counted] == list(range(sim.tick + 1))
    assert [first for _, first, _ in port.counted] == [True] + [False] * sim.tick
    # the occupancy is reported changed at tick 0 and when a robot joined or was removed, only then
    changed = [c for _, _, c in port.counted]
    localized = sim.history[:, 2]
    assert changed[1:] == [
        bool(localized[t] != localized[t - 1]) or any(at == t for at, _ in sim.losses) for t in range(1, sim.tick + 1)
    ]
    assert port.decisions == list(range(1, sim.tick + 1))
    assert recorder.ticks == list(range(sim.tick + 1)) and recorder.forced == [False] * sim.tick + [True]
    assert core.bag_complete()
    assert any(line.startswith(f"last tick, {sim.tick}: {sim.outcome.value}") for line in log.lines)
    record = core.record(rejected=0)
    assert np.array_equal(record.history, sim.history) and record.outcome == sim.outcome
    for name in ("state", "x", "y", "heading", "occupancy"):
        assert np.array_equal(getattr(record.state, name), getattr(sim.state, name)), name


def test_rows_again_and_rows_that_cannot_be_the_next_change_nothing():
    params = RunParams(robots=60, seed=3, max_ticks=400)
    _, messages = world_messages(params)
    core, port, _, _ = make(params)
    feed(core, messages, 3)
    before = [tuple(r) for r in core.rows]
    core.robots(decode_cloud(messages[1][0]))  # again: a late-matched reader's history
    with pytest.raises(Rejected, match="inconsistent rows"):
        core.robots(decode_cloud(messages[4][0]))  # tick 4 after tick 2
    bad = state_rows(np.arange(3), core.view.state)
    bad["id"][0] = params.robots  # out of range
    with pytest.raises(Rejected):
        core.robots(decode_cloud(encode_cloud(bad, 3)))
    assert [tuple(r) for r in core.rows] == before and len(port.counted) == 3 and core.view.tick == 2
    core.robots(decode_cloud(messages[3][0]))  # the true next rows are still taken
    assert core.view.tick == 3
    core.decisions(decode_cloud(messages[3][1]))
    core.decisions(decode_cloud(messages[3][1]))  # again: a restarted world's: counted and bagged once
    assert port.decisions == [1, 2, 3]


def test_world_shards_parts_are_joined_in_any_order_and_a_robot_in_two_parts_fails_the_run():
    """With S = 2 the rows of a tick come as two parts, split here by id parity as no shard would split them;
    a part of the next tick may come before the other part of this one. The joined count is the engine's;
    parts that hold one robot twice fail the run rather than count it twice."""
    params = RunParams(robots=60, seed=3, max_ticks=400)
    sim, ticks = world_rows(params)
    halves = [[encode_cloud(rows[rows["id"] % 2 == k], t) for k in (0, 1)] for t, (rows, _) in enumerate(ticks)]
    core, _, _, _ = make(params, shards=2)
    for tick, (_, odd) in enumerate(halves):
        core.robots(decode_cloud(odd), "world_shard_1")
        if tick:
            core.robots(decode_cloud(halves[tick - 1][0]), "world_shard_0")  # the other part, one tick late
    core.robots(decode_cloud(halves[-1][0]), "world_shard_0")
    assert [tuple(r) for r in core.rows] == [tuple(r) for r in sim.history] and core.outcome == sim.outcome

    core, _, _, _ = make(params, shards=2)
    core.robots(decode_cloud(halves[0][0]), "world_shard_0")
    core.robots(decode_cloud(halves[0][1]), "world_shard_1")
    rows = ticks[1][0]
    core.robots(decode_cloud(encode_cloud(rows[rows["id"] % 2 == 0], 1)), "world_shard_0")
    with pytest.raises(RunFailed, match="hold a robot twice"):
        core.robots(decode_cloud(encode_cloud(rows, 1)), "world_shard_1")  # every row of the tick: evens twice
    assert core.view.tick == 0


def sampled_messages(params: RunParams, every: int) -> tuple[Simulation, list[tuple[np.ndarray, bytes | None]]]:
    """What a world with ``record_every`` = ``every`` publishes after each tick: its tally's numbers (as the node
    hands them over), and every robot's rows at every ``every``-th tick and the last (else None)."""
    sim, decider = Simulation(SHAPE, params), Decider(SHAPE, params)
    out = []
    while True:
        counts = np.bincount(sim.state.state, minlength=len(RobotState))
        rows = None
        if sim.tick % every == 0 or sim.done:
            rows = encode_cloud(state_rows(np.arange(params.robots), sim.state), sim.tick)
        out.append((np.array([sim.tick, every, *counts], dtype=np.int64), rows))
        if sim.done:
            return sim, out
        sim.apply(decider.decide(sim.state, sim.moving_ids(), sim.tick + 1))


@pytest.mark.parametrize("tallies_first", [True, False])
def test_with_record_every_the_core_counts_each_tick_from_the_tallies_and_checks_the_rows(tallies_first):
    """``record_every`` 4: a tally every tick, every robot's row every 4th tick and at the last, in either order.
    The count is the engine's tick for tick; the occupancy goes to the port, and the robots to the recording,
    at the ticks whose rows came; the view ends as the engine's state."""
    params = RunParams(robots=60, seed=7, max_ticks=300, fail_fraction=0.2, fail_tick=21)
    sim, messages = sampled_messages(params, 4)
    recorder = Recorder()
    core, port, _, _ = make(params, recorder, every=4)
    seen: list[bool] = []
    port.tick_counted = lambda tick, metrics, occupancy, first, changed, held: seen.append(occupancy is not None)
    for tally, rows in messages:
        if rows is not None and not tallies_first:
            core.robots(decode_cloud(rows), "world", rows)
        core.tally(tally, "world", b"tally")
        if rows is not None and tallies_first:
            core.robots(decode_cloud(rows), "world", rows)
    assert [tuple(r) for r in core.rows] == [tuple(r) for r in sim.history]
    assert core.outcome == sim.outcome and core.losses == sim.losses and sim.tick % 4 != 0
    recorded = [t % 4 == 0 or t == sim.tick for t in range(sim.tick + 1)]
    assert seen == recorded and len(recorder.forced) == sum(recorded) and recorder.forced[-1]
    for name in ("state", "x", "y", "heading", "occupancy"):
        assert np.array_equal(getattr(core.view.state, name), getattr(sim.state, name)), name


@pytest.mark.parametrize(
    "params",
    [
        RunParams(robots=60, seed=7, max_ticks=300, fail_fraction=0.3, fail_tick=3),  # seeds among the failed
        RunParams(robots=140, seed=2, max_ticks=400),  # more robots than patches: separated ones at the end
    ],
)
def test_the_worlds_tally_from_its_metrics_is_its_robots_by_state_at_every_tick(params):
    """state_counts, the tally world process 0 sends from the run's metrics (every shard holds them, not every
    robot), is the engine's robots by state at every tick, removed seeds and separated robots included."""
    sim, decider = Simulation(SHAPE, params), Decider(SHAPE, params)
    while True:
        removed = sim.state.state == RobotState.REMOVED
        got = state_counts(sim.metrics, 4 - int(removed[:4].sum()), int(removed.sum()))
        assert got.tolist() == np.bincount(sim.state.state, minlength=len(RobotState)).tolist(), sim.tick
        if sim.done:
            break
        sim.apply(decider.decide(sim.state, sim.moving_ids(), sim.tick + 1))
    if params.failures:
        assert removed[:4].any()  # the case it is here for
    else:
        assert (sim.state.state == RobotState.SEPARATED).any()


def test_with_world_shards_the_tally_comes_from_shard_0_and_one_from_another_is_dropped():
    params = RunParams(robots=60, seed=3, max_ticks=400)
    _, messages = sampled_messages(params, 3)
    core, port, _, _ = make(params, every=3, shards=2)
    counted: list[int] = []
    port.tick_counted = lambda tick, metrics, occupancy, first, changed, held: counted.append(tick)
    rows = state_rows(np.arange(params.robots), Simulation(SHAPE, params).state)  # tick 0's, in two parts
    core.robots(decode_cloud(encode_cloud(rows[rows["id"] < 30], 0)), "world_shard_0")
    core.robots(decode_cloud(encode_cloud(rows[rows["id"] >= 30], 0)), "world_shard_1")
    with pytest.raises(Rejected, match="unexpected sender"):
        core.tally(messages[0][0], "world_shard_1")
    assert counted == []
    core.tally(messages[0][0], "world_shard_0")
    core.tally(messages[1][0], "world_shard_0")
    assert counted == [0, 1]


def test_with_record_every_the_port_gets_each_ticks_messages_as_they_came_tallies_first():
    params = RunParams(robots=60, seed=3, max_ticks=400)
    _, messages = sampled_messages(params, 3)
    core, port, _, _ = make(params, every=3)
    got: list[list[tuple[str, bytes]]] = []
    port.tick_counted = lambda tick, metrics, occupancy, first, changed, held: got.append(held)
    for tick, (tally, rows) in enumerate(messages[:4]):
        if rows is not None:
            core.robots(decode_cloud(rows), "world", rows)
        with pytest.raises(Rejected, match="malformed tally"):
            core.tally(tally[:-1], "world", b"short")  # dropped: what it would have replaced is held again
        core.tally(tally, "world", b"tally %d" % tick)
    assert got[0] == [("/swarm/tally", b"tally 0"), ("/swarm/robots", messages[0][1])]
    assert got[1:3] == [[("/swarm/tally", b"tally 1")], [("/swarm/tally", b"tally 2")]]
    assert got[3] == [("/swarm/tally", b"tally 3"), ("/swarm/robots", messages[3][1])]


def test_with_record_every_a_world_that_disagrees_with_itself_or_the_monitor_fails_the_run():
    params = RunParams(robots=60, seed=3, max_ticks=400)
    _, messages = sampled_messages(params, 2)
    core, _, _, _ = make(params, every=3)
    with pytest.raises(RunFailed, match="every 2 ticks and this monitor was told every 3"):
        core.tally(messages[0][0], "world")
    with pytest.raises(RunFailed, match="every 1 ticks and this monitor was told every 3"):
        core.status({"record_every": "1", "outcome": "starting"}, 0)  # said before tick 0: no tally ever comes
    core, _, _, _ = make(params, every=2)
    core.robots(decode_cloud(messages[0][1]), "world")
    wrong = messages[0][0].copy()
    wrong[2:4] += [1, -1]  # a seed more, a robot moving outside fewer: not what the rows hold
    with pytest.raises(RunFailed, match="its tallies"):
        core.tally(wrong, "world")
    core, _, _, _ = make(params, every=2)
    core.robots(decode_cloud(messages[0][1]), "world")
    for tally, _ in messages[:2]:
        core.tally(tally, "world")
    rows = state_rows(np.arange(params.robots), Simulation(SHAPE, params).state)  # tick 0's rows again at tick 2
    rows["x"][0] += 1.0  # a seed moved
    core.tally(messages[2][0], "world")
    with pytest.raises(RunFailed, match="move a robot that was stationary"):
        core.robots(decode_cloud(encode_cloud(rows, 2)), "world")
    assert core.last == 1 and core.view.tick == 0


def test_with_record_every_a_run_stopped_between_recorded_ticks_is_recorded_up_to_the_last_of_them():
    params = RunParams(robots=60, seed=7, max_ticks=300, fail_fraction=0.2, fail_tick=5)
    sim, messages = sampled_messages(params, 4)
    core, _, _, _ = make(params, every=4)
    for tally, rows in messages[:7]:  # ticks 0-6: the rows of 0 and 4 came
        if rows is not None:
            core.robots(decode_cloud(rows), "world")
        core.tally(tally, "world")
    assert core.last == 6 and core.view.tick == 4 and core.losses == [(5, sim.losses[0][1])]
    record = core.record(0, Outcome.INTERRUPTED)
    assert np.array_equal(record.history, sim.history[:5]) and record.state.tick == 4
    assert record.summary["convergence_tick"] == 4 and record.summary["lost_robots"] == 0


def _ended(params=RunParams(robots=60, seed=3, max_ticks=400), recorder=None):
    sim, messages = world_messages(params)
    core, port, clock, log = make(params, recorder)
    feed(core, messages)
    return sim, core, port, clock, log


def _status(core: MonitorCore, outcome: str, tick: int, restarts: str = "") -> None:
    core.status({"tick": str(tick), "outcome": outcome, "restarts": restarts}, tick)


def test_the_run_is_due_once_the_world_agrees_and_the_recording_is_closed_with_the_outcome():
    recorder = Recorder()
    sim, core, port, clock, log = _ended(recorder=recorder)
    assert not core.due(bag=True)  # the world's outcome has not come
    _status(core, sim.outcome.value, sim.tick, restarts_text([(5, "robot_batch_0")]))
    assert recorder.events and recorder.events[0][0] == 5 and "robot_batch_0 was restarted at tick 5" in log.lines
    port.missed = 2
    assert core.due(bag=True) and recorder.closed and recorder.ended == (sim.outcome.value, sim.tick)
    assert any("2 messages were still in the readers" in line for line in log.lines)


def test_an_outcome_the_world_does_not_confirm_waits_then_the_run_is_written_with_the_count():
    sim, core, _, clock, _ = _ended()
    clock.now += STATUS_WAIT - 0.1
    assert not core.due(bag=False)
    clock.now += 0.2
    assert core.due(bag=False) and core.record(rejected=0).outcome == sim.outcome


def test_a_world_that_reports_another_outcome_fails_the_run():
    sim, core, _, _, _ = _ended()
    other = next(o for o in Outcome if o not in (sim.outcome, Outcome.INTERRUPTED))
    _status(core, other.value, sim.tick)
    with pytest.raises(RunFailed, match=f"the world reports '{other.value}', the monitor counted"):
        core.due(bag=False)


def test_the_last_ticks_decisions_are_waited_for_a_moment():
    params = RunParams(robots=60, seed=3, max_ticks=400)
    sim, messages = world_messages(params)
    core, port, clock, _ = make(params)
    for rows, decided in messages[:-1]:
        core.robots(decode_cloud(rows))
        if decided is not None:
            core.decisions(decode_cloud(decided))
    core.robots(decode_cloud(messages[-1][0]))  # the last rows came; their tick's decisions not yet
    _status(core, sim.outcome.value, sim.tick)
    assert not core.bag_complete() and not core.due(bag=True)
    assert core.due(bag=False)  # without a bag nothing waits for them
    core2, _, clock2, log2 = make(params)
    feed(core2, messages[:-1])
    core2.robots(decode_cloud(messages[-1][0]))
    _status(core2, sim.outcome.value, sim.tick)
    clock2.now += BAG_WAIT - 0.1
    assert not core2.due(bag=True)
    clock2.now += 0.2
    assert core2.due(bag=True)  # given up on: the run is written without them, and the log says so
    moving = int(sim.history[-2][4])
    assert f"the bag is written without {moving} of them" in log2.lines[-1]


def test_a_world_that_ended_while_the_rows_never_came_fails_the_run_after_a_wait():
    params = RunParams(robots=60, seed=3, max_ticks=400)
    sim, messages = world_messages(params)
    core, port, clock, _ = make(params)
    feed(core, messages, 10)
    _status(core, sim.outcome.value, sim.tick)
    assert not core.due(bag=False)
    clock.now += STATUS_WAIT + 0.1
    with pytest.raises(RunFailed, match=f"reached the monitor only up to tick 9 within {STATUS_WAIT:g} s"):
        core.due(bag=False)
    # rows the executor had not handed over are taken first: then the run is not failed
    core, port, clock, _ = make(params)
    feed(core, messages, 10)
    _status(core, sim.outcome.value, sim.tick)
    clock.now += STATUS_WAIT + 0.1
    port.on_missed = lambda: feed(core, messages[10:])
    assert not core.due(bag=False) and core.outcome == sim.outcome


def test_a_replayed_bag_is_counted_and_recorded_but_never_reported_again():
    params = RunParams(robots=60, seed=3, max_ticks=400)
    sim, messages = world_messages(params)
    first, _, _, _ = make(params)
    feed(first, messages, 12)
    recorder = Recorder()
    core, port, _, _ = make(params, recorder, incarnation=1)
    with core.replay():
        feed(core, messages, 12)
    assert port.counted == [] and port.decisions == [] and recorder.ticks == list(range(12))
    core.replayed([tuple(r) for r in first.rows])
    assert core.resumed_at == 11
    feed(core, messages[12:])  # then the topics' histories and the live ticks
    assert [t for t, _, _ in port.counted] == list(range(12, sim.tick + 1))
    assert [tuple(r) for r in core.rows] == [tuple(r) for r in sim.history]
    record = core.record(rejected=0)
    assert record.summary["restarts"] == [{"tick": 11, "node": MONITOR}]  # a restart the world never saw


def test_a_bag_whose_metrics_are_not_its_rows_fails_the_restart():
    params = RunParams(robots=60, seed=3, max_ticks=400)
    _, messages = world_messages(params)
    core, _, _, _ = make(params, incarnation=1)
    with core.replay():
        feed(core, messages, 5)
    wrong = [tuple(r) for r in core.rows]
    wrong[2] = (2, *(v + 1 for v in wrong[2][1:]))
    with pytest.raises(RunFailed, match="holds other metrics than its rows give"):
        core.replayed(wrong)


@pytest.mark.parametrize(
    "stopped,ended,expected", [(True, False, "interrupted"), (False, False, "failed"), (False, True, "interrupted")]
)
def test_a_run_stopped_before_it_was_written_closes_its_recording_marked(stopped, ended, expected):
    params = RunParams(robots=60, seed=3, max_ticks=400)
    sim, messages = world_messages(params)
    recorder = Recorder()
    core, _, _, _ = make(params, recorder)
    feed(core, messages if ended else messages[:7])
    core.close_recording(stopped=stopped)
    assert recorder.closed and recorder.ended == (expected, sim.tick if ended else 6)
    core.close_recording(stopped=stopped)  # once only
    interrupted = core.record(rejected=4, outcome=Outcome.INTERRUPTED)
    assert interrupted.outcome == (Outcome.INTERRUPTED) and interrupted.summary["rejected_messages"]["monitor"] == 4
