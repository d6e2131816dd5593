"""The exchanges between world shards (:mod:`swarm_ros.protocol.shard_exchange`): whatever order the transport
delivers the messages in, repeated or not, with shard processes restarted from their last save at any moment,
and with forged parts among the genuine ones, every shard closes every tick as ``Simulation`` does."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from lockstep_fakes import Log
from runs import disc_shape

from swarm_ros.core import RunParams, Simulation, World
from swarm_ros.core.errors import ContractError
from swarm_ros.core.rules import Decider
from swarm_ros.core.sharded_run import _assemble
from swarm_ros.core.shards import ShardPlan, WorldShard
from swarm_ros.protocol.checks import Rejections
from swarm_ros.protocol.shard_exchange import ExchangeSaved, ShardExchange

pytestmark = pytest.mark.unit

WORLD = World(radius=12)
DISC = disc_shape(WORLD, 7.0)


class Bus:
    """S shards, their robots (deciding from the shard's view, as a batch does) and a transport that delivers
    what is in flight in a random order, sometimes twice; ``restart(k)`` replaces shard k's process."""

    def __init__(self, params: RunParams, cuts, seed: int) -> None:
        self.params, self.rng = params, np.random.default_rng(seed)
        self.plan = ShardPlan(WORLD.radius, params.vision_radius, np.asarray(cuts, dtype=np.int64))
        self.rejections = Rejections(Log())
        self.flight: list[tuple] = []  # (to, kind, *args)
        self.restarts = 0
        self.decided: list[dict] = [{} for _ in range(self.plan.shards)]  # per shard: tick -> decisions sent
        self.closed: list[dict] = [{} for _ in range(self.plan.shards)]  # per shard: tick -> rows closed
        self.exchanges = [self._start(k) for k in range(self.plan.shards)]
        self.saves = [[ExchangeSaved(ex.shard.saved(), {})] for ex in self.exchanges]  # per shard, oldest first
        for k in range(self.plan.shards):
            self._decide(k)

    def _start(self, k: int) -> ShardExchange:
        return ShardExchange(WorldShard(DISC, self.params, self.plan, k), Port(self, k), self.rejections)

    def _decide(self, k: int) -> None:
        """Shard k's robots decide the tick after the one it closed last (a batch, on the rows of that tick)."""
        sh = self.exchanges[k].shard
        if sh.outcome is None:
            tick = sh.tick + 1
            if tick not in self.decided[k]:
                self.decided[k][tick] = Decider(DISC, self.params).decide(
                    sh.state, sh.own_moving(), tick, sh.view.moving_ids()
                )
            self.flight.append((k, "decisions", self.decided[k][tick]))

    def deliver(self) -> None:
        item = self.flight.pop(int(self.rng.integers(len(self.flight))))
        if self.rng.random() < 0.1:
            self.flight.append(item)  # delivered twice
        to, kind, *args = item
        ex = self.exchanges[to]
        if kind == "decisions":
            ex.own_decisions(*args)
        elif kind == "claims":
            ex.peer_claims(*args)
        elif kind == "part":
            ex.peer_part(*args)
        elif kind == "resend":
            ex.resend(*args)

    def restart(self, k: int, older: bool) -> None:
        """Shard k's process dies (what was in flight to it is lost) and a new one goes on from its last save (or
        the one before: it died before writing the last); its peers send again, its batch decides again."""
        self.flight = [m for m in self.flight if m[0] != k]
        self.restarts += 1
        saves = self.saves[k]
        saved = saves[-2] if older and len(saves) > 1 else saves[-1]
        self.exchanges[k] = self._start(k)
        self.exchanges[k].restore(saved)
        for j in range(self.plan.shards):
            if j != k:
                self.flight.append((j, "resend", k))
        for tick in sorted(t for t in self.decided[k] if t > saved.shard.tick):
            self.flight.append((k, "decisions", self.decided[k][tick]))  # the batch's history, handed over again

    def done(self) -> bool:
        return all(ex.shard.outcome is not None for ex in self.exchanges) and not self.flight


@dataclasses.dataclass
class Port:
    bus: Bus
    k: int

    def send_claims(self, peer, tick, claims):
        self.bus.flight.append((peer, "claims", self.k, tick, claims))

    def send_part(self, peer, tick, part):
        self.bus.flight.append((peer, "part", self.k, tick, part))

    def ask_again(self, peer):
        self.bus.flight.append((peer, "resend", self.k))

    def closed(self, tick, part, saved):  # saved: the messages kept for the peers
        seen = self.bus.closed[self.k]
        if tick in seen:  # closed again by a restarted process: the same rows
            assert np.array_equal(seen[tick].ids, part.ids) and np.array_equal(seen[tick].x, part.x)
        seen[tick] = part
        self.bus.saves[self.k].append(ExchangeSaved(self.bus.exchanges[self.k].shard.saved(), saved))
        self.bus._decide(self.k)


def _run(bus: Bus, restarts: float = 0.0, forge: float = 0.0) -> None:
    steps = 0
    while not bus.done():
        steps += 1
        assert steps < 200_000, "the exchange stalled"
        if not bus.flight:
            raise AssertionError("nothing in flight, and the run has not ended: a stall")
        if bus.rng.random() < restarts:
            bus.restart(int(bus.rng.integers(bus.plan.shards)), older=bool(bus.rng.random() < 0.5))
        if forge and bus.rng.random() < forge:
            held = [m for m in bus.flight if m[1] in ("part", "claims") and m[4].ids.size]
            if held:
                to, kind, source, tick, genuine = held[int(bus.rng.integers(len(held)))]
                if kind == "part":  # moved too far
                    forged = dataclasses.replace(genuine, x=genuine.x + 3 * bus.plan.halo)
                else:  # a claim on a patch out of the receiver's window: a rival that could steal a patch
                    forged = dataclasses.replace(genuine, claim=genuine.claim * 0 - 1)
                bus.flight.append((to, kind, source, tick, forged))
        bus.deliver()


def _same_as_simulate(bus: Bus) -> None:
    sim = Simulation(DISC, bus.params)
    sim.run()
    for ex in bus.exchanges:
        assert np.array_equal(np.asarray(ex.shard.history), sim.history)
    state = _assemble([ex.shard for ex in bus.exchanges])
    for name in ("x", "y", "heading", "state", "occupancy", "frontier"):
        assert np.array_equal(getattr(state, name), getattr(sim.state, name)), name


@pytest.mark.parametrize("seed", range(6))
def test_any_order_and_repeats_give_the_in_process_run(seed):
    """One shard alone, or four, or six (cuts a column apart among them)."""
    params = RunParams(robots=DISC.patches + 30, seed=seed, rules=("paper", "local", "literal")[seed % 3])
    bus = Bus(params, ([], [-6, -1, 4], [-3, -2, -1, 0, 1])[seed % 3], seed)
    _run(bus)
    _same_as_simulate(bus)


@pytest.mark.parametrize("seed", range(10))
def test_shards_restarted_at_any_moment_give_the_in_process_run(seed):
    """A process dies between any two deliveries (1 in 50), from the first tick to the last, and goes on from
    its last save or, as if it died while writing it, the one before; failures at tick 15 in between."""
    params = RunParams(robots=DISC.patches + 30, seed=seed, fail_fraction=0.1, fail_tick=15)
    bus = Bus(params, [-4, 3], seed)
    _run(bus, restarts=0.02)
    _same_as_simulate(bus)
    assert bus.restarts > 5


def test_forged_parts_and_claims_are_dropped_counted_and_asked_for_again():
    params = RunParams(robots=DISC.patches + 30, seed=5)
    bus = Bus(params, [-4, 3], 5)
    _run(bus, forge=0.05)
    _same_as_simulate(bus)
    assert bus.rejections.total > 5
    assert {"parts: moved too far", "claims: bad claim"} <= set(bus.rejections.counts)


def test_decisions_far_ahead_are_refused():
    bus = Bus(RunParams(robots=DISC.patches + 30, seed=1), [0], 1)
    ex = bus.exchanges[0]
    d = dataclasses.replace(bus.decided[0][1], tick=5)
    with pytest.raises(ContractError, match="tick 5"):
        ex.own_decisions(d)
