"""World shards (:mod:`swarm_ros.core.shards`): the world's half of a tick split by region gives the in-process
engine's run byte for byte, for any number of shards and any cuts, and each shard only ever hears of what lies
near its strips."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from lockstep_fakes import Log
from runs import disc_shape

from swarm_ros.core import RunParams, Shape, Simulation, World
from swarm_ros.core.errors import ContractError, Rejected
from swarm_ros.core.regions import columns
from swarm_ros.core.rules import Decider
from swarm_ros.core.sharded_run import ShardedWorld, run_sharded
from swarm_ros.core.shards import ShardPlan, WorldShard
from swarm_ros.core.state import IS_MOVING, RobotState
from swarm_ros.core.swarm_view import UNKNOWN
from swarm_ros.protocol.checks import Rejections
from swarm_ros.protocol.shard_exchange import ShardExchange

pytestmark = pytest.mark.unit

WORLD = World(radius=12)
DISC = disc_shape(WORLD, 7.0)
_ROWS = ("x", "y", "heading", "state", "z", "pitch", "occupancy", "frontier", "frontier_blocks")


def _same_run(shape: Shape, params: RunParams, cuts, max_ticks: int | None = None) -> Simulation:
    sim = Simulation(shape, params)
    sim.run(max_ticks=max_ticks)
    run = run_sharded(shape, params, np.asarray(cuts, dtype=np.int64), max_ticks=max_ticks)
    assert np.array_equal(run.history, sim.history)
    assert run.outcome == sim.outcome and run.losses == sim.losses
    for name in _ROWS:
        if getattr(sim.state, name) is not None:
            assert np.array_equal(getattr(run.state, name), getattr(sim.state, name)), name
    return sim


@pytest.mark.parametrize("rules", ["paper", "local", "literal"])
def test_any_cuts_give_the_in_process_run(rules):
    """20 seeded runs per rule set, cut into 1-8 shards at random columns: crowded runs (ending with robots
    separated), sparse ones (ending incomplete), scheduled failures, a tick limit, a wider vision radius."""
    rng = np.random.default_rng(36)
    ends = set()
    for case in range(20):
        extra = int(rng.integers(-40, 40)) if case % 3 else DISC.patches  # crowded: ends with robots left over
        failing = case % 4 == 1
        params = RunParams(
            robots=DISC.patches + extra,
            seed=int(rng.integers(10**6)),
            rules=rules,
            vision_radius=float(rng.choice([1.0, 2.0, 3.0])),
            fail_fraction=0.2 if failing else 0.0,
            fail_tick=int(rng.integers(1, 40)) if failing else 0,
            max_ticks=60 if case % 5 == 3 else 5000,
        )
        cuts = np.sort(rng.choice(np.arange(-WORLD.radius + 1, WORLD.radius + 1), int(rng.integers(0, 8)), False))
        ends.add(_same_run(DISC, params, cuts).outcome)
    assert len(ends) >= 3, ends  # complete with extras, incomplete and timeout were all met


def test_shards_beyond_a_claims_reach_trade_no_claims_and_drop_any():
    """A shard sends claims only to the shards its robots' claims can reach (ShardPlan.reaches: its strips widened
    by the reach, theirs by the halo) and waits only for theirs: on the star cut in four, its neighbours. A run over
    such cuts is the in-process run (a claim beyond them would stop it: ContractError), and claims from a shard
    beyond reach are dropped and counted."""
    star = Shape.load("star")
    params = RunParams(robots=star.patches, seed=5)
    radius = star.world.radius
    cuts = np.array([-radius // 2, 0, radius // 2])
    plan = ShardPlan(radius, params.vision_radius, cuts)
    shards = [WorldShard(star, params, plan, k) for k in range(4)]
    assert [sh.claims_to for sh in shards] == [[1], [0, 2], [1, 3], [2]]
    assert [sh.claims_from for sh in shards] == [sh.claims_to for sh in shards]
    _same_run(star, params, cuts, max_ticks=150)
    rejections = Rejections(Log())
    exchange = ShardExchange(shards[0], None, rejections)  # type: ignore[arg-type]  # nothing is sent here
    far = shards[3].claims(Decider(star, params).decide(shards[3].state, shards[3].own_moving(), 1))[0]
    exchange.peer_claims(3, 1, far)
    assert rejections.total == 1 and exchange.claims == {}


def test_robots_removed_at_a_ticks_end_give_the_in_process_run():
    """Robots removed at the end of a tick, as the world removes a lost batch's (``Simulation.remove`` after
    the tick): deciders of that tick picked at random (some localize in it), at several ticks, some in the
    very tick of the scheduled failures."""
    rng = np.random.default_rng(37)
    removed = 0
    for case in range(12):
        failing = case % 2 == 1
        params = RunParams(
            robots=DISC.patches + int(rng.integers(0, 60)),
            seed=int(rng.integers(10**6)),
            rules=("paper", "local", "literal")[case % 3],
            fail_fraction=0.1 if failing else 0.0,
            fail_tick=12 if failing else 0,
        )
        sim, removals = Simulation(DISC, params), {}
        at = {int(t) for t in rng.integers(1, 40, size=3)} | ({12} if failing else set())
        while sim.outcome is None:
            deciders = sim.moving_ids()
            sim.step()
            if sim.tick in at and deciders.size:
                ids = np.sort(rng.choice(deciders, size=min(deciders.size, int(rng.integers(1, 20))), replace=False))
                removed += sim.remove(ids)
                removals[sim.tick] = ids
        cuts = np.sort(rng.choice(np.arange(-WORLD.radius + 1, WORLD.radius + 1), int(rng.integers(1, 5)), False))
        run = run_sharded(DISC, params, cuts, removals=removals)
        assert np.array_equal(run.history, sim.history) and run.outcome == sim.outcome
        assert run.losses == sim.losses
        for name in _ROWS[:4] + ("occupancy", "frontier"):
            assert np.array_equal(getattr(run.state, name), getattr(sim.state, name)), name
    assert removed > 50


def test_a_3d_run_and_the_star():
    box = Shape.load("box")
    _same_run(box, RunParams(robots=box.patches + 20, seed=1, rules="literal"), [-3, 0, 4], max_ticks=120)
    failing = RunParams(robots=box.patches + 20, seed=2, rules="paper", fail_fraction=0.2, fail_tick=30)
    _same_run(box, failing, [-2, 3], max_ticks=150)
    _same_run(Shape.load("star"), RunParams(robots=1036, seed=1), [-10, 0, 12])


def test_a_shard_hears_only_of_its_area():
    """Every tick: each shard's view equals the world's in its area (every stationary robot, the moving
    robots of its strips and halo) and its occupancy is the world's; the rows it received are of robots in its
    area before or after the tick, or that became stationary; the claims it received, of robots in its halo."""
    params = RunParams(robots=DISC.patches + 40, seed=8, rules="literal", vision_radius=2.0)
    sim, world = Simulation(DISC, params), ShardedWorld(DISC, params, np.array([-7, -2, 3, 8]))
    rivals = 0
    while sim.outcome is None:
        before = sim.state.copy()
        sim.step()
        world.step()
        s = sim.state
        for sh, parts, claims in zip(world.shards, world.received, world.claims):
            first, last = sh.view.area
            known = sh.state.state != UNKNOWN
            cols = columns(s.x, WORLD.radius)
            # robots separated at the end were moving: a shard separates those it follows, and tells no one
            stationary = ~IS_MOVING[s.state] & (s.state != RobotState.SEPARATED)
            assert np.array_equal(known, stationary | ((cols >= first) & (cols <= last)))
            for name in ("x", "y", "heading", "state"):
                assert np.array_equal(getattr(sh.state, name)[known], getattr(s, name)[known])
            assert np.array_equal(sh.state.occupancy, s.occupancy) and np.array_equal(sh.state.frontier, s.frontier)
            for q in parts:
                was, now = columns(before.x[q.ids], WORLD.radius), columns(q.x, WORLD.radius)
                near = ((was >= first) & (was <= last)) | ((now >= first) & (now <= last))
                assert (near | ~IS_MOVING[q.state]).all()
            h = world.plan.halo
            for c in claims:
                at = columns(before.x[c.ids], WORLD.radius)
                assert ((at >= sh.strip[0] - 2 * h) & (at <= sh.strip[1] + 2 * h)).all()
                rivals += c.ids.size
    assert sim.outcome is not None and rivals > 0


def test_a_shard_refuses_decisions_that_are_not_its_own():
    world = ShardedWorld(DISC, RunParams(robots=DISC.patches + 10, seed=2), np.array([0]))
    sh, other = world.shards
    with pytest.raises(ContractError, match="for tick 2"):
        sh.apply(world.deciders[0].decide(sh.state, sh.own_moving(), 2, sh.view.moving_ids()), [])
    with pytest.raises(ContractError, match="exactly once"):
        sh.apply(world.deciders[1].decide(other.state, other.own_moving(), 1, other.view.moving_ids()), [])


def _tick_parts(world: ShardedWorld) -> tuple[list, list]:
    """Decide and apply the next tick in every shard of ``world``; (each shard's part, what each receives)."""
    tick, count = world.shards[0].tick + 1, range(world.plan.shards)
    decisions = [
        d.decide(sh.state, sh.own_moving(), tick, sh.view.moving_ids()) for sh, d in zip(world.shards, world.deciders)
    ]
    claims = [sh.claims(d) for sh, d in zip(world.shards, decisions)]
    parts = [sh.apply(decisions[k], [claims[i][k] for i in count if i != k]) for k, sh in enumerate(world.shards)]
    routed = [sh.routes(p) for sh, p in zip(world.shards, parts)]
    return parts, [[routed[i][k] for i in count if i != k] for k in count]


def test_forged_claims_are_refused():
    """Every way a rival's claims can be wrong that a shard can see, over a whole run: refused with its kind."""
    params = RunParams(robots=DISC.patches + 60, seed=12, vision_radius=2.0)
    world = ShardedWorld(DISC, params, np.array([0]))
    met: set[str] = set()
    while world.outcome is None:
        tick, sh, other = world.shards[0].tick + 1, world.shards[1], world.shards[0]
        d = world.deciders[0].decide(other.state, other.own_moving(), tick, other.view.moving_ids())
        theirs = other.claims(d)[1]  # shard 0's claims on shard 1's window
        sh.check_claims(0, theirs)  # the genuine ones pass
        if theirs.ids.size:
            stationary = np.flatnonzero(~IS_MOVING[sh.state.state] & (sh.state.state != UNKNOWN))[0]
            cases = [
                (dataclasses.replace(theirs, tick=tick + 1), "claims of another tick"),
                (dataclasses.replace(theirs, x=theirs.x[:-1]), "malformed claims"),
                (dataclasses.replace(theirs, claim=theirs.claim.astype(np.int32)), "malformed claims"),
                (dataclasses.replace(theirs, ids=theirs.ids + params.robots), "bad robot ids"),
                (dataclasses.replace(theirs, heading=theirs.heading * np.inf), "bad pose"),
                (dataclasses.replace(theirs, claim=theirs.claim * 0 - 1), "bad claim"),
                (dataclasses.replace(theirs, claim=theirs.claim * 0), "bad claim"),  # the west wall's corner
            ]
            one = dataclasses.replace(
                theirs, **{f: getattr(theirs, f)[:1] for f in ("ids", "claim", "x", "y", "heading")}
            )
            cases.append((dataclasses.replace(one, ids=np.array([stationary])), "not the sender's robots"))
            if sh.own_moving().size:  # a robot shard 1 decides for itself
                cases.append((dataclasses.replace(one, ids=sh.own_moving()[:1]), "not the sender's robots"))
            for bad, kind in cases:
                with pytest.raises(Rejected) as caught:
                    sh.check_claims(0, bad)
                assert caught.value.kind == kind
                met.add(kind)
        world.step()
    kinds = {"claims of another tick", "malformed claims", "bad robot ids", "bad pose", "bad claim"}
    assert met == kinds | {"not the sender's robots"}


def _forged(part, **changes):
    return dataclasses.replace(part, **changes)


def test_a_hostile_part_is_refused_whole_and_the_run_goes_on():
    """Every way a part can be wrong that a shard can see is refused (Rejected, its kind) before anything is
    taken; the genuine parts taken afterwards give the in-process run."""
    params = RunParams(robots=DISC.patches + 60, seed=11, vision_radius=2.0)
    sim, world = Simulation(DISC, params), ShardedWorld(DISC, params, np.array([0]))
    forged, met = 0, set()
    while sim.outcome is None:
        sim.step()
        parts, received = _tick_parts(world)
        sh, theirs = world.shards[1], received[1][0]  # shard 1 and what shard 0 sent it
        s = sh.state
        joins = np.flatnonzero(theirs.state == RobotState.LOCALIZED)
        cases = [
            (_forged(theirs, tick=theirs.tick + 1), "part of another tick"),
            (_forged(theirs, source=1), "parts of the wrong shards"),
            (_forged(theirs, counts=theirs.counts[:3]), "malformed part"),
            (_forged(theirs, counts=theirs.counts - 1 - theirs.counts.max()), "impossible counts"),
        ]
        if theirs.ids.size:
            cases += [
                (_forged(theirs, x=theirs.x[:-1]), "malformed part"),
                (_forged(theirs, ids=theirs.ids + params.robots), "bad robot ids"),
                (_forged(theirs, state=theirs.state.astype(np.int64)), "malformed part"),
                (_forged(theirs, state=np.full_like(theirs.state, RobotState.SEPARATED)), "bad robot state"),
                (_forged(theirs, x=theirs.x + np.nan), "bad pose"),
                (_forged(theirs, before=theirs.before + WORLD.size), "not the sender's robots"),
                (_forged(theirs, x=theirs.x + 3 * world.plan.halo), "moved too far"),
            ]
            stationary = np.flatnonzero(~IS_MOVING[s.state] & (s.state != UNKNOWN))[0]
            one = theirs.take(np.array([0]))
            cases.append((_forged(one, ids=np.array([stationary])), "a stationary robot moved"))
            twice = np.concatenate([theirs.ids[:1], theirs.ids])[: theirs.ids.size]  # the first robot twice
            if twice.size > 1:
                cases.append((_forged(theirs, ids=twice), "bad robot ids"))
        wrong = theirs.counts.copy()
        wrong[8] = wrong[1] + 1  # more removed inside than it has inside
        cases.append((_forged(theirs, counts=wrong), "impossible counts"))
        cases.append((_forged(theirs, removing=np.array([0], dtype=np.int64)), "impossible counts"))  # uncounted
        if joins.size:
            counts = theirs.counts.copy()
            counts[0] += 1
            cases.append((_forged(theirs, counts=counts), "impossible counts"))
            j = joins[0]
            taken = np.flatnonzero(s.occupancy >= 0)  # patches robots hold already
            near = taken[np.abs(taken % WORLD.size - theirs.before[j]) <= world.plan.halo]
            if near.size:
                x, y = theirs.x.copy(), theirs.y.copy()
                x[j], y[j] = near[0] % WORLD.size - WORLD.radius, near[0] // WORLD.size - WORLD.radius
                cases.append((_forged(theirs, x=x, y=y), "bad join"))
        for bad, kind in cases:
            before = s.copy()
            with pytest.raises(Rejected) as caught:
                sh.close(parts[1], [bad])
            assert caught.value.kind == kind
            met.add(kind)
            for name in _ROWS[:4] + ("occupancy", "frontier"):
                assert np.array_equal(getattr(s, name), getattr(before, name)), name  # nothing taken
            forged += 1
        for k, shard in enumerate(world.shards):
            shard.close(parts[k], received[k])
    assert np.array_equal(np.asarray(world.shards[1].history), sim.history) and forged > 200
    assert len(met) == 11, met  # every kind of forgery was tried
