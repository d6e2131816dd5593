"""World shards (:mod:`swarm_ros.core.shards`): the world's half of a tick split by region gives the in-process
engine's run byte for byte, for any number of shards and any cuts, and each shard only ever hears of what lies
near its strips."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import disc_shape

from swarm_ros.core import RunParams, Shape, Simulation, World
from swarm_ros.core.errors import ContractError
from swarm_ros.core.regions import columns
from swarm_ros.core.replica import UNKNOWN
from swarm_ros.core.shards import ShardedWorld, run_sharded
from swarm_ros.core.state import IS_MOVING, RobotState

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


def test_a_3d_run_and_the_star():
    box = Shape.load("box")
    _same_run(box, RunParams(robots=box.patches + 20, seed=1, rules="literal"), [-3, 0, 4], max_ticks=120)
    _same_run(Shape.load("star"), RunParams(robots=1036, seed=1), [-10, 0, 12])


def test_a_shard_hears_only_of_its_area():
    """Every tick: each shard's replica equals the world's in its area (every stationary robot, the moving
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
            first, last = sh.replica.area
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


def test_a_shard_refuses_what_is_not_its_tick():
    world = ShardedWorld(DISC, RunParams(robots=DISC.patches + 10, seed=2), np.array([0]))
    sh = world.shards[0]
    d = world.deciders[0].decide(sh.state, sh.own_moving(), 1, sh.replica.moving_ids())
    with pytest.raises(ContractError, match="for tick 2"):
        sh.apply(world.deciders[0].decide(sh.state, sh.own_moving(), 2, sh.replica.moving_ids()), [])
    with pytest.raises(ContractError, match="exactly once"):
        other = world.shards[1]
        sh.apply(world.deciders[1].decide(other.state, other.own_moving(), 1, other.replica.moving_ids()), [])
    part = sh.apply(d, [])
    stale = sh.routes(part)[1]
    stale.tick = 5
    with pytest.raises(ContractError, match="tick 5"):
        world.shards[1].close(part, [stale])
