"""World shards' coordination (swarm_ros.protocol.lockstep) driven by method calls over fake channels: S
shard locksteps, the robot batches of their strips (each following its region from snapshots and region rows, as
a batch process does), and a monitor that joins the S parts of each tick. Channels deliver in order, in a random
interleaving; a shard process may be killed at any moment and restarted from its last save. Every run must be
the in-process engine's, tick for tick, as the monitor counts it and as every shard holds it."""

from __future__ import annotations

import random
from collections import defaultdict, deque

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from lockstep_fakes import Clock, Log

from swarm_ros.core.engine import Simulation
from swarm_ros.core.errors import RunFailed
from swarm_ros.core.params import RunParams
from swarm_ros.core.regions import area, batch_cuts, columns, halo, shard_batches, shard_cuts, strip
from swarm_ros.core.rules import Decider
from swarm_ros.core.shapes import Shape
from swarm_ros.core.shards import ShardPlan, WorldShard
from swarm_ros.core.state import RobotState
from swarm_ros.core.swarm_view import SwarmView
from swarm_ros.protocol.cdr import decode_cloud, encode_cloud
from swarm_ros.protocol.checks import Rejections, apply_robots
from swarm_ros.protocol.lockstep import Lockstep, first_of
from swarm_ros.protocol.monitoring import MonitorCore
from swarm_ros.protocol.plan import batch_name
from swarm_ros.protocol.rows import decision_rows, pose_of
from swarm_ros.protocol.shard_save import ShardSaver
from swarm_ros.protocol.world_port import LOSS_CONFIRM_S, Policy

pytestmark = pytest.mark.unit


class Batch:
    """A robot batch as its process behaves: a regional view fed by its shard, decisions from it."""

    def __init__(self, graph: ShardedGraph, k: int) -> None:
        self.g, self.k = graph, k
        self.strip = graph.strips[k]
        width = 2 * graph.shape.world.radius + 1
        self.area = area(self.strip, halo(graph.params.vision_radius), width)
        self.view = SwarmView(graph.shape, graph.params.robots, area=self.area)
        self.decider = Decider(graph.shape, graph.params)
        self.sent: deque = deque(maxlen=256)  # its decisions topic's history (TRANSIENT_LOCAL, depth 256)

    def snapshot(self, tick: int, rows: np.ndarray) -> None:
        if tick <= self.view.tick:
            return
        self.view.load(tick, rows["id"], rows["state"], **pose_of(rows))
        self.decide()

    def region(self, tick: int, rows: np.ndarray) -> None:
        if tick != self.view.tick + 1:
            return  # before its snapshot, or again
        apply_robots(self.view, tick, rows)
        self.decide()

    def decide(self) -> None:
        moving = self.view.moving_ids()
        cols = columns(self.view.state.x[moving], self.g.shape.world.radius)
        own = moving[(cols >= self.strip[0]) & (cols <= self.strip[1])]
        if own.size:
            tick = self.view.tick + 1
            rows = decision_rows(self.decider.decide(self.view.state, own, tick, moving))
            self.sent.append((tick, rows))
            self.publish(tick, rows)

    def publish(self, tick: int, rows: np.ndarray) -> None:
        s = self.g.shard_of[self.k]
        ls = self.g.shards[s]
        self.g.send(("decisions", self.k), lambda: ls.decisions(ls.batch_names.index(batch_name(self.k)), tick, rows))


class Port:
    """Shard ``s``'s node, as the fake channels see it."""

    def __init__(self, graph: ShardedGraph, s: int) -> None:
        self.g, self.s = graph, s
        g = graph
        self.saver = ShardSaver(g.folder / f"shard{s}", g.params, g.plan, s, g.policy.monitor_window + 2, 2)
        self.saver.create()
        self.batch_of: dict[int, int] = {}  # the shard's batch number -> the run's

    def watch_batch(self, k, name):
        self.batch_of[k] = int(name.rsplit("_", 1)[1])

    def send_snapshot(self, k, tick, rows):
        b = self.g.batches[self.batch_of[k]]
        self.g.send(("batch", b.k), lambda: b.snapshot(tick, rows))

    def publish_tick(self, tick, rows, joined, applied, regional, tally):
        for k, part in enumerate(regional or ()):
            b = self.g.batches[self.batch_of[k]]
            self.g.send(("batch", b.k), lambda b=b, part=part: b.region(tick, part))
        every = self.g.policy.record_every
        unrecorded = every > 1 and tick % every > 0 and tick < self.g.end
        assert (tally is None) == (every == 1 or self.s > 0) and (rows is None) == unrecorded  # shard 0: the run's
        self.g.published[self.s].append((tick, self.g.clock.now))
        sender = f"world_shard_{self.s}"  # a channel per topic, as DDS orders a writer's messages per topic
        if tally is not None:
            data = np.array([tick, every, *tally], dtype=np.int64)  # the message's numbers, as the node hands them
            self.g.send(("tally", self.s), lambda: self.g.monitor.tally(data, sender))
        if rows is not None:
            msg = encode_cloud(rows, tick)
            self.g.send(("monitor", self.s), lambda: self.g.monitor.robots(decode_cloud(msg), sender))

    def publish_status(self, status):
        self.g.statuses[self.s] = status

    def monitor_reads_all(self):
        return True

    def delivered(self):
        return True

    def decisions_delivered(self):
        return True

    def startup_seconds(self):
        return 0.5

    def send_claims(self, peer, tick, claims):
        self.g.send(("claims", self.s, peer), lambda: self.g.shards[peer].exchange.peer_claims(self.s, tick, claims))

    def send_part(self, peer, tick, part):
        self.g.send(("part", self.s, peer), lambda: self.g.shards[peer].exchange.peer_part(self.s, tick, part))

    def ask_again(self, peer):
        self.g.send(("again", self.s, peer), lambda: self.g.shards[peer].exchange.resend(self.s))

    def save_tick(self, tick, rows, published, applied, metrics, sent, tally):
        self.saver.write_tick(tick, rows, published, applied, metrics, sent, tally)

    def save_book(self, book):
        self.saver.save_book(book)


class ShardedGraph:
    def __init__(
        self,
        shape: Shape,
        params: RunParams,
        batches: int,
        shards: int,
        seed: int,
        folder,
        window: int = 3,
        tick_rate: float = 0.0,
        every: int = 1,
        on_batch_loss: str = "restart",
    ) -> None:
        self.shape, self.params, self.rng, self.folder = shape, params, random.Random(seed), folder
        radius = shape.world.radius
        cuts = batch_cuts(shape, params, batches)
        self.strips = [strip(k, batches, cuts, radius) for k in range(batches)]
        self.plan = ShardPlan(radius, params.vision_radius, shard_cuts(cuts, shards, batches))
        self.members = [list(shard_batches(s, shards, batches)) for s in range(shards)]
        self.shard_of = {k: s for s, ks in enumerate(self.members) for k in ks}
        self.channels: dict[tuple, deque] = defaultdict(deque)
        self.statuses: dict[int, object] = {}
        self.clock, self.log = Clock(), Log()
        self.policy = Policy(
            monitor_window=window, tick_rate=tick_rate, record_every=every, on_batch_loss=on_batch_loss
        )
        self.published: dict[int, list[tuple[int, float]]] = defaultdict(list)  # shard -> (tick, clock) published
        self.ports = [Port(self, s) for s in range(shards)]
        self.incarnations = [0] * shards
        self.shards = [self.make(s) for s in range(shards)]
        self.batches = [Batch(self, k) for k in range(batches)]
        ref = Simulation(shape, params)
        ref.run()
        self.end = ref.tick  # the last tick: its rows go out whatever record_every says
        self.monitor = MonitorCore(shape, params, radius, self, None, self.log, shards=shards, every=every)
        self.view = self.monitor.view  # the monitor's
        self.restarts = 0

    @property
    def history(self) -> list[tuple[int, ...]]:
        return [tuple(int(v) for v in row) for row in self.monitor.rows]

    # -- the monitor's port
    def tick_counted(self, tick, metrics, occupancy, first, changed, messages) -> None:
        for j in range(len(self.shards)):
            self.send(("held", j), lambda j=j, t=tick: self.shards[j].held(t, "monitor-1"))

    def decisions_taken(self, tick: int) -> None:
        pass

    def take_missed(self) -> int:
        return 0

    def make(self, s: int) -> Lockstep:
        shard = WorldShard(self.shape, self.params, self.plan, s)
        return Lockstep(
            shard, f"world_shard_{s}", self.policy, self.ports[s], self.log, Rejections(self.log), clock=self.clock
        )

    def send(self, channel: tuple, deliver) -> None:
        self.channels[channel].append(deliver)

    def start(self) -> None:
        for ls in self.shards:
            ls.monitor_liveliness(1, 0)
        order = list(range(len(self.batches)))
        self.rng.shuffle(order)
        for k in order:
            b = self.batches[k]
            for ls in self.shards:  # every shard hears every announcement; each admits its own
                ls.announce(batch_name(k), 0, b.strip)

    def kill(self, s: int) -> None:
        """Shard ``s``'s process dies; a new one goes on from its save (what was on its way to it is lost)."""
        port = self.ports[s]
        port.saver = ShardSaver(port.saver.path, self.params, self.plan, s, self.policy.monitor_window + 2, 2)
        saved = port.saver.restore()
        if saved is None:
            return
        for channel in list(self.channels):
            to_it = channel[2] == s if channel[0] in ("claims", "part", "again") else channel[1] == s
            if channel[0] in ("claims", "part", "again", "held") and to_it:
                self.channels[channel].clear()
            if channel[0] == "decisions" and self.shard_of[channel[1]] == s:
                self.channels[channel].clear()
        self.incarnations[s] += 1
        self.shards[s] = ls = self.make(s)
        ls.monitor_liveliness(1, 0)
        ls.restore(saved, self.incarnations[s])
        self.restarts += 1
        if self.monitor.last >= 0:  # the new process's readers get the writers' histories (held: latched)
            self.send(("held", s), lambda t=self.monitor.last: ls.held(t, "monitor-1"))
        for b in self.batches:
            if self.shard_of[b.k] == s:
                ls.announce(batch_name(b.k), 0, b.strip)
                for tick, rows in b.sent:
                    b.publish(tick, rows)

    def step_until(self, condition, limit: int = 200_000) -> None:
        """Deliver messages in a random order until ``condition()`` holds."""
        for _ in range(limit):
            if condition():
                return
            self.channels[self.rng.choice([c for c, q in self.channels.items() if q])].popleft()()
        raise AssertionError("never held")

    def run(self, kill_every: int = 0, limit: int = 200_000) -> None:
        for _ in range(limit):
            if all(ls.sim.done for ls in self.shards) and self.monitor.outcome is not None:
                return
            busy = [c for c, q in self.channels.items() if q]
            if not busy:
                due = [w for ls in self.shards if (w := ls.wake_in()) is not None]
                if due:  # tick_rate: what the node's spin would wait for
                    self.clock.now += min(due)
                for ls in self.shards:
                    ls.poll()
                if not any(q for q in self.channels.values()):
                    raise AssertionError(f"stalled at ticks {[ls.sim.tick for ls in self.shards]}")
                continue
            if kill_every and self.rng.randrange(kill_every) == 0:
                self.kill(self.rng.randrange(len(self.shards)))
                continue
            self.channels[self.rng.choice(busy)].popleft()()
        raise AssertionError("did not end")


CASES = [  # (robots, batches, shards, seed)
    (60, 2, 2, 1),
    (200, 4, 2, 2),
    (200, 4, 4, 3),
    (300, 6, 3, 4),
]


@pytest.mark.parametrize(("robots", "batches", "shards", "seed"), CASES)
def test_a_run_over_shards_is_the_engines_run(robots, batches, shards, seed, tmp_path):
    shape = Shape.load("star")
    params = RunParams(robots=robots, seed=seed, max_ticks=300)
    g = ShardedGraph(shape, params, batches, shards, seed, tmp_path)
    g.start()
    g.run()
    ref = Simulation(shape, params)
    ref.run()
    assert g.history == [tuple(int(v) for v in row) for row in ref.history]
    for ls in g.shards:
        assert ls.sim.history == [tuple(int(v) for v in row) for row in ref.history]
        assert ls.sim.outcome == ref.outcome
    assert np.array_equal(g.view.state.state, ref.state.state)
    assert np.array_equal(g.view.state.x, ref.state.x) and np.array_equal(g.view.state.y, ref.state.y)


@pytest.mark.parametrize(("robots", "batches", "shards", "seed", "every"), [(200, 4, 2, 2, 3), (300, 6, 3, 4, 7)])
def test_shards_that_send_the_robots_every_kth_tick_are_counted_from_their_tallies(
    robots, batches, shards, seed, every, tmp_path
):
    """``record_every`` > 1: shard 0 sends the monitor the run's tally every tick (the others none), each shard every
    robot in its strips every k-th tick and at the last; the monitor counts each tick from the tally, checks the
    rows against it, and its count is the engine's tick for tick, its view the engine's final state."""
    shape = Shape.load("star")
    params = RunParams(robots=robots, seed=seed, max_ticks=299, fail_fraction=0.05, fail_tick=10)
    g = ShardedGraph(shape, params, batches, shards, seed, tmp_path, every=every)
    g.start()
    g.run()
    ref = Simulation(shape, params)
    ref.run()
    assert g.history == [tuple(int(v) for v in row) for row in ref.history]
    assert g.view.tick == ref.tick and ref.tick % every != 0  # the last tick, whatever k says
    assert np.array_equal(g.view.state.state, ref.state.state)
    assert np.array_equal(g.view.state.x, ref.state.x) and np.array_equal(g.view.state.y, ref.state.y)
    rows_at = sorted({t for ticks in g.published.values() for t, _ in ticks})
    assert rows_at == list(range(ref.tick + 1))  # a tally of every tick


def test_paced_shards_publish_a_tick_a_period_apart_and_the_run_is_the_engines(tmp_path):
    """``tick_rate`` with world shards: each shard holds a closed tick until its time, and the run is unchanged."""
    shape = Shape.load("star")
    params = RunParams(robots=200, seed=2, max_ticks=60)
    g = ShardedGraph(shape, params, 4, 2, 2, tmp_path, tick_rate=8.0)
    g.start()
    g.run()
    ref = Simulation(shape, params)
    ref.run()
    assert g.history == [tuple(int(v) for v in row) for row in ref.history]
    for s in range(2):
        times = [at for tick, at in g.published[s] if tick > 0]
        assert len(times) == 60 and min(np.diff(times)) >= 0.125, g.published[s][:5]


@pytest.mark.parametrize("seed", range(8))
def test_shards_killed_at_any_moment_go_on_from_their_saves(seed, tmp_path):
    """Seeds 6 and 7: the shards send the robots every 4th tick (``record_every``), their tallies in between."""
    shape = Shape.load("star")
    params = RunParams(robots=200, seed=seed, max_ticks=200, fail_fraction=0.05, fail_tick=20)
    g = ShardedGraph(shape, params, 4, 1 + seed % 3 + 1, seed, tmp_path, every=1 if seed < 6 else 4)
    g.start()
    g.run(kill_every=150)
    ref = Simulation(shape, params)
    ref.run()
    assert g.restarts >= 2
    assert g.history == [tuple(int(v) for v in row) for row in ref.history]
    assert np.array_equal(g.view.state.state, ref.state.state)
    restarts = sum(len([r for r in ls.restarts if r[1].startswith("world_shard")]) for ls in g.shards)
    assert restarts >= 1


def test_a_batch_lost_for_good_while_its_shards_tick_is_with_the_peers_is_removed_once(tmp_path):
    """Under ``remove``: batch 0's process dies just after its decisions went in, while its shard's tick is with the
    peers. The loss, confirmed then, waits for the tick's close, however often the shard polls meanwhile; the robots
    are removed once, and the run goes on to its end with the world deciding for the robots in the strip."""
    shape = Shape.load("star")
    params = RunParams(robots=200, seed=2, max_ticks=300)
    g = ShardedGraph(shape, params, 4, 2, 2, tmp_path, on_batch_loss="remove")
    g.start()
    ls = g.shards[g.shard_of[0]]
    g.step_until(lambda: ls.sim.tick >= 10 and ls.inflight is not None)
    g.batches[0].decide = lambda: None  # dead: no more decisions
    k = ls.batch_names.index(batch_name(0))  # the shard's own numbering
    ls.batch_liveliness(k, 0, 1)
    g.clock.now += LOSS_CONFIRM_S + 0.1
    for _ in range(3):
        ls.poll()
    assert ls.inflight is not None and [d for d, _ in ls.deferred] == [k] and not ls.down_since
    g.run()
    assert ls.lost == [batch_name(0)] and len(ls.sim.losses) == 1
    removed = int((g.view.state.state == RobotState.REMOVED).sum())
    assert removed == ls.sim.losses[0][1] > 0 and g.history[-1][1] + g.history[-1][4] == params.robots - removed


@given(st.lists(st.sets(st.integers(0, 63), max_size=40), min_size=1, max_size=4), st.randoms(use_true_random=False))
def test_first_of_is_np_unique_with_the_first_arrays_values(id_sets, rnd):
    """The linear-time join a shard closes its tick with answers what ``np.unique(..., return_index=True)`` does."""
    ids = [np.array(sorted(s, key=lambda _: rnd.random()), dtype=np.int64) for s in id_sets]
    values = [np.array([rnd.randrange(1000) for _ in a], dtype=np.int64) for a in ids]
    every, first = first_of(64, ids, values)
    want, at = np.unique(np.concatenate(ids), return_index=True)
    assert np.array_equal(every, want) and np.array_equal(first, np.concatenate(values)[at])


def test_a_save_without_the_kept_messages_of_its_tick_is_refused_as_incomplete(tmp_path):
    """A restarted shard resends its peers the messages of the last two ticks from its save: one that lacks them
    (their slot cut off while being written, with the tick after it) is not gone on from."""
    shape = Shape.load("star")
    params = RunParams(robots=200, seed=3, max_ticks=300)
    g = ShardedGraph(shape, params, 4, 2, 3, tmp_path)
    g.start()
    g.step_until(lambda: min(ls.sim.tick for ls in g.shards) >= 5)
    port = g.ports[0]
    saver = ShardSaver(port.saver.path, g.params, g.plan, 0, g.policy.monitor_window + 2, 2)
    saved = saver.restore()
    assert saved is not None and saver.checkpoint is not None
    tick, ck = saved.exchange.shard.tick, saver.checkpoint
    assert tick >= 5 and sorted(saved.exchange.sent) == [tick - 1, tick]
    ck.map[ck.kept_at + (tick % 3) * ck.kept_slot :][:8].view(np.int64)[0] = -1
    with pytest.raises(RunFailed, match="incomplete"):
        ShardSaver(port.saver.path, g.params, g.plan, 0, g.policy.monitor_window + 2, 2).restore()
