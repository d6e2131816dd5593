"""The world's half of a tick can be split by region without changing a byte: what a split of the world's
checks and apply into region shards (docs/protocol.md, "World shards") relies on, checked on the kernel as it is.

A *shard* here owns a strip of columns: it applies the decisions of the moving robots standing in its strip,
on its own copy of the state, with the in-process engine's kernel (:func:`resolve_kernel`), given also the
claims of robots outside its strip on the patches its own robots claim (the lottery is per patch). The test
asserts, against :meth:`Simulation.apply` of the whole tick, that every robot's new row is its shard's, that
the occupancy and the frontier every shard derives from all shards' localizations are the world's, that the
per-shard counts sum to the tick's metrics, and that every claim a shard needs from outside comes from a
robot within the halo of its strip (:func:`swarm_ros.core.darr_niazi.legality.halo`): from a neighbour, never from
anywhere.
"""

from __future__ import annotations

import numpy as np
import pytest
from runs import disc_shape

from swarm_ros.core import RunParams, Simulation, World
from swarm_ros.core.darr_niazi.arbitration import occupy, resolve_kernel
from swarm_ros.core.darr_niazi.kernel_state import Moves, grid_of, robots_of, rules_of
from swarm_ros.core.darr_niazi.legality import halo
from swarm_ros.core.darr_niazi.rules import Decider
from swarm_ros.core.darr_niazi.state import IS_MOVING, STATE_COUNT, RobotState

pytestmark = pytest.mark.unit

WORLD = World(radius=12)
SHAPE = disc_shape(WORLD, 7.0)


def _shard_apply(sim: Simulation, decisions, mine: np.ndarray) -> tuple:
    """Shard ``mine`` (a mask over ``decisions``)'s tick: its own decisions and the outside claims on the patches
    its robots claim, applied to a copy of the state. Returns (the copy, the outside claimants it needed)."""
    claims = decisions.claim
    wanted = np.unique(claims[mine & (claims >= 0)])
    outside = ~mine & np.isin(claims, wanted)
    take = np.flatnonzero(mine | outside)
    s = sim.state.copy()
    world, empty = SHAPE.world, np.empty(0)
    moves = Moves(
        claims[take].astype(np.int64), decisions.x[take], decisions.y[take], empty, decisions.heading[take], empty
    )
    grid = grid_of(SHAPE, s, SHAPE.mask.ravel().copy(), world.wall_mask().ravel(), world.neighbour_offsets())
    resolve_kernel(
        decisions.ids[take],
        moves,
        robots_of(s),
        grid,
        rules_of(sim.params),
        decisions.tick,
        np.full(world.patch_count, -1, dtype=np.int64),
        sim.metrics.localized,
        SHAPE.patches,
        np.empty(take.size, dtype=np.int8),
        take.size,
    )
    return s, decisions.ids[outside]


@pytest.mark.parametrize("rules,vision", [("paper", 1.0), ("local", 3.0), ("literal", 2.0)])
def test_a_tick_applied_by_region_shards_is_the_worlds_tick(rules, vision):
    """60 seeded cases per rule set: a random tick of a random run, cut into 2-9 strips at random columns.
    Crowded (up to twice the shape's patches in robots) so that robots of two strips claim one patch."""
    rng = np.random.default_rng(35)
    outside_claims = 0
    for _ in range(60):
        params = RunParams(
            robots=SHAPE.patches + int(rng.integers(10, SHAPE.patches)),
            seed=int(rng.integers(10**6)),
            rules=rules,
            vision_radius=vision,
        )
        cuts = np.sort(rng.choice(np.arange(1, 2 * WORLD.radius + 1), size=int(rng.integers(1, 9)), replace=False))
        outside_claims += _check_one_tick(params, int(rng.integers(0, 60)), cuts)
    assert outside_claims > 0  # the case that matters was met: a shard needed its neighbours' claims


def _check_one_tick(params: RunParams, ticks: int, cuts: np.ndarray) -> int:
    """Run ``ticks`` ticks, then apply the next one by the shards of strips starting at ``cuts`` and as the
    world does; assert they agree (see the module's docstring). Returns the claims shards took from outside."""
    sim = Simulation(SHAPE, params)
    sim.run(max_ticks=ticks)
    if sim.done:
        return 0
    moving = sim.moving_ids()
    decisions = Decider(SHAPE, params).decide(sim.state, moving, sim.tick + 1)
    strip_of = np.searchsorted(cuts, sim.grid.columns(sim.state.x[decisions.ids]), side="right")
    reach = halo(params.vision_radius)
    before = sim.state.copy()
    shards, taken = [], 0
    for k in range(cuts.size + 1):
        mine = strip_of == k
        state, outside = _shard_apply(sim, decisions, mine)
        first = cuts[k - 1] if k else 0
        last = cuts[k] - 1 if k < cuts.size else 2 * WORLD.radius
        cols = sim.grid.columns(before.x[outside])
        assert ((cols >= first - reach) & (cols <= last + reach)).all()  # a neighbour's claims, from the halo
        shards.append((decisions.ids[mine], state))
        taken += outside.size

    sim.apply(decisions)
    world = sim.state
    if sim.outcome is not None and (world.state == RobotState.SEPARATED).any():
        # complete with robots left over: every shard, from the reduced counts, separates its moving robots
        for ids, state in shards:
            state.state[ids[IS_MOVING[state.state[ids]]]] = RobotState.SEPARATED
    # every robot's row is its own shard's
    for ids, state in shards:
        for name in ("x", "y", "heading", "state"):
            assert np.array_equal(getattr(state, name)[ids], getattr(world, name)[ids]), name
    # the stationary changes of all shards (every shard hears of every localization) give the world's
    # occupancy and frontier: start from the state before and occupy each shard's winners
    occupancy, frontier, blocks = before.occupancy.copy(), before.frontier.copy(), before.frontier_blocks.copy()
    for ids, state in shards:
        for i in ids[state.state[ids] == RobotState.LOCALIZED]:
            p = int(np.flatnonzero(state.occupancy == i)[0])
            occupy(p, i, occupancy, frontier, blocks, SHAPE.mask.ravel().copy(), WORLD.neighbour_offsets(), WORLD.size)
    assert np.array_equal(occupancy, world.occupancy) and np.array_equal(frontier, world.frontier)
    assert np.array_equal(blocks, world.frontier_blocks)
    # the tick's metrics are the sum of the shards' own counts (and of the robots that did not decide)
    counts = np.bincount(before.state[~IS_MOVING[before.state]], minlength=STATE_COUNT)
    for ids, state in shards:
        counts += np.bincount(state.state[ids], minlength=STATE_COUNT)
    assert np.array_equal(counts, world.counts())
    return taken
