"""The robot rule under each switch value: hand-built situations, the nearest-frontier search
against brute force, and independence from how robots are batched."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from runs import disc_shape, params

from swarm_ros.core import RobotState, Shape, Simulation, World, decide
from swarm_ros.core.darr_niazi.invariants import nearest_frontier_patch
from swarm_ros.core.darr_niazi.rules import Decisions
from swarm_ros.core.darr_niazi.rules2d import block_distances, nearest_frontier
from swarm_ros.core.darr_niazi.state import FRONTIER_BLOCK, SwarmState, frontier_blocks_of, initial_state
from swarm_ros.core.errors import ContractError

pytestmark = pytest.mark.unit

RULES = ["paper", "local", "literal"]


@pytest.fixture(scope="module")
def disc():
    return disc_shape(World(radius=10), 5.0)


def with_robots(shape: Shape, robots: list[tuple[float, float, float]], walking=()) -> SwarmState:
    """Seeds on (-1..0, -1..0) plus moving robots at (x, y, heading) given by hand; robots 4 + k for
    k in ``walking`` are walking, the others wander inside or outside by their patch."""
    s = initial_state(shape, 4, seed=1)
    xs, ys, hs = (np.array([r[k] for r in robots]) for k in range(3))
    flat = shape.world.flat_index(*shape.world.patch_of(xs, ys))
    st_ = np.where(shape.mask.ravel()[flat], RobotState.MOVING_INSIDE, RobotState.MOVING_OUTSIDE)
    st_[list(walking)] = RobotState.WALKING
    return SwarmState(
        x=np.r_[s.x, xs],
        y=np.r_[s.y, ys],
        heading=np.r_[s.heading, hs],
        state=np.r_[s.state, st_].astype(np.int8),
        occupancy=s.occupancy,
        frontier=s.frontier,
        frontier_blocks=s.frontier_blocks,
    )


def decide_all(view, shape, **kw) -> Decisions:
    p = params(view.robots, **kw)
    return decide(view, view.moving_ids(), shape, p, tick=1)


def patch(shape, flat):
    px, py = shape.world.patch_xy(flat)
    return int(px), int(py)


# -- join: walk ---------------------------------------------------------------------


def test_walk_steps_exactly_one_patch_towards_the_nearest_frontier_patch(disc):
    view = with_robots(disc, [(3.0, 0.0, 1.0)])  # inside; nearest frontier patch (1, 0), 2 away
    d = decide_all(view, disc, rules="paper")
    assert d.claim[0] == -1
    assert (d.x[0], d.y[0]) == (2.0, 0.0) and d.heading[0] == pytest.approx(math.pi)


def test_walk_claims_the_nearest_frontier_patch_once_within_one_patch(disc):
    view = with_robots(disc, [(1.9, 0.1, 1.0)])  # (1, 0) is 0.906 away
    d = decide_all(view, disc, rules="paper")
    assert patch(disc, d.claim[0]) == (1, 0)
    assert (d.x[0], d.y[0], d.heading[0]) == (1.9, 0.1, 1.0)  # it claims standing


def test_walk_ties_go_to_the_lowest_y_then_x(disc):
    # (-1, 1) and (0, 1) are equally near; (-1, 1) has the same y and the lower x
    far = decide_all(with_robots(disc, [(-0.5, 2.6, 0.0)]), disc, rules="paper")
    target = np.array([-1.0, 1.0])
    step = np.array([far.x[0], far.y[0]]) - [-0.5, 2.6]
    assert far.claim[0] == -1 and np.hypot(*step) == pytest.approx(1.0)
    assert np.allclose(step, (target - [-0.5, 2.6]) / np.hypot(*(target - [-0.5, 2.6])))
    near = decide_all(with_robots(disc, [(-0.5, 1.8, 0.0)]), disc, rules="paper")
    assert patch(disc, near.claim[0]) == (-1, 1)


def test_walking_robots_walk_anywhere_and_wandering_outside_robots_do_not(disc):
    walking = with_robots(disc, [(6.5, 0.0, 2.0)], walking=[0])  # off the shape, but already walking
    d = decide_all(walking, disc, rules="paper")
    assert (d.x[0], d.y[0]) == (5.5, 0.0) and d.heading[0] == pytest.approx(math.pi)
    wandering = decide_all(with_robots(disc, [(6.5, 0.0, 2.0)]), disc, rules="paper", wiggle_deg=0.0)
    assert wandering.x[0] == pytest.approx(6.5 + math.cos(2.0))  # a plain wandering step


def test_walk_ignores_walls_and_crowding(disc):
    # robot 5 sits right where robot 4 steps and on the patch ahead of it: a walker goes anyway
    view = with_robots(disc, [(3.0, 0.0, 0.0), (2.0, 0.0, 0.0)])
    d = decide_all(view, disc, rules="paper")
    assert (d.x[0], d.y[0]) == (2.0, 0.0)


def test_with_an_empty_frontier_walkers_wander(disc):
    view = with_robots(disc, [(3.0, 0.0, 0.0)], walking=[0])
    view.frontier[:] = False
    view.frontier_blocks[:] = frontier_blocks_of(view.frontier, disc.world.size)
    d = decide_all(view, disc, rules="paper", wiggle_deg=0.0)
    assert d.claim[0] == -1 and (d.x[0], d.y[0]) == (4.0, 0.0)


def _place(sim: Simulation, robots: list[tuple[float, float, float]], states: list[int]) -> None:
    """Put the non-seed robots of a fresh simulation where the test wants them (state arrays in place)."""
    s = sim.state
    for k, ((x, y, h), code) in enumerate(zip(robots, states), start=4):
        s.x[k], s.y[k], s.heading[k], s.state[k] = x, y, h, code


def test_a_walking_loser_stays_walking_and_retargets(disc):
    sim = Simulation(disc, params(6, rules="paper", seed=5))
    walking = int(RobotState.WALKING)
    _place(sim, [(1.6, 0.3, 0.0), (1.6, -0.3, 0.0)], [walking, walking])  # both nearest to (1, 0)
    sim.step()
    ids, claim, outcome = sim.last_joins()
    assert [patch(disc, c) for c in claim] == [(1, 0), (1, 0)]
    loser = int(ids[outcome != 0][0])
    assert sim.state.state[loser] == RobotState.WALKING
    assert (sim.state.x[loser], abs(sim.state.y[loser])) == (1.6, 0.3)  # it keeps the pose it decided
    expected = nearest_frontier_patch(sim.state.frontier, sim.state.x[loser], sim.state.y[loser], disc.world)
    assert patch(disc, expected) == (2, 0)  # (1, 0) is taken; its new neighbour (2, 0) is nearest
    sim.step()
    ids, claim, outcome = sim.last_joins()
    assert ids.tolist() == [loser] and claim[0] == expected and outcome[0] == 0
    assert sim.state.state[loser] == RobotState.LOCALIZED


def test_a_robot_that_steps_inside_starts_walking_next_tick(disc):
    sim = Simulation(disc, params(5, rules="paper", seed=2, wiggle_deg=0.0))
    _place(sim, [(5.6, 0.0, math.pi)], [int(RobotState.MOVING_OUTSIDE)])
    sim.step()  # wanders one patch west, onto the shape
    assert sim.state.x[4] == pytest.approx(4.6) and sim.state.state[4] == RobotState.MOVING_INSIDE
    sim.step()  # now it walks towards (1, 0)
    assert sim.state.state[4] == RobotState.WALKING and sim.state.x[4] == pytest.approx(3.6)


@st.composite
def frontiers(draw):
    # sizes 11, 21, 65, 81, 301: partial last blocks and super-blocks too; 301 has five super-blocks a side
    radius = draw(st.sampled_from([5, 10, 32, 40, 150]))
    world = World(radius)
    density = draw(st.sampled_from([0.0005, 0.003, 0.05, 0.5]))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    frontier = rng.random(world.patch_count) < density
    frontier &= ~world.wall_mask().ravel()
    lim = radius - 1.5
    x, y = (draw(st.floats(-lim, lim)) for _ in range(2))
    if draw(st.booleans()):  # land exactly between patch centres now and then: exact ties
        x, y = round(x * 2) / 2, round(y * 2) / 2
    return world, frontier, x, y


@settings(max_examples=300, deadline=None)
@given(frontiers())
def test_block_search_finds_what_brute_force_finds(case):
    """With or without each block's distance to the frontier, which only lets the search skip rings."""
    world, frontier, x, y = case
    blocks = frontier_blocks_of(frontier, world.size)
    nearest = nearest_frontier_patch(frontier, x, y, world)
    assert nearest_frontier(x, y, frontier, blocks, world.radius, world.size) == nearest
    near = block_distances(blocks, world.size)
    assert nearest_frontier(x, y, frontier, blocks, world.radius, world.size, near) == nearest


@settings(max_examples=100, deadline=None)
@given(frontiers())
def test_block_distances_are_the_king_move_distances_to_the_nearest_block_with_frontier_patches(case):
    world, frontier, _, _ = case
    blocks = frontier_blocks_of(frontier, world.size)
    nb = -(-world.size // FRONTIER_BLOCK)
    near = block_distances(blocks, world.size).reshape(nb, nb)
    full = np.flatnonzero(blocks[: nb * nb])
    if not full.size:  # no frontier at all: every block says farther than the world is wide
        assert (near >= nb).all()
        return
    by, bx = np.divmod(np.arange(nb * nb), nb)
    fy, fx = np.divmod(full, nb)
    expect = np.maximum(abs(by[:, None] - fy[None, :]), abs(bx[:, None] - fx[None, :])).min(axis=1)
    assert np.array_equal(near.ravel(), expect)


# -- join: local --------------------------------------------------------------------


def test_local_claims_the_nearest_frontier_patch_within_the_vision_radius(disc):
    view = with_robots(disc, [(1.2, 0.1, 0.0)])  # (1, 0) is nearest
    d = decide_all(view, disc, rules="local")
    assert patch(disc, d.claim[0]) == (1, 0)
    assert (d.x[0], d.y[0]) == (1.2, 0.1)  # joining robots do not also wander


def test_local_without_a_frontier_patch_in_view_wanders(disc):
    view = with_robots(disc, [(4.0, 0.0, 0.0)])
    assert decide_all(view, disc, rules="local", vision_radius=1.0).claim[0] == -1
    far = decide_all(view, disc, rules="local", vision_radius=3.0)  # (1, 0) is now within reach
    assert patch(disc, far.claim[0]) == (1, 0)


@pytest.mark.parametrize("rules", RULES)
def test_a_robot_outside_the_shape_never_claims(disc, rules):
    view = with_robots(disc, [(6.0, 0.0, math.pi)])  # outside, frontier (1, 0) within vision 5
    assert decide_all(view, disc, rules=rules, vision_radius=5.0, wiggle_deg=0.0).claim[0] == -1


# -- steps: one ---------------------------------------------------------------------


@pytest.mark.parametrize("rules", RULES[:2])
def test_one_step_goes_one_patch_along_the_heading(disc, rules):
    view = with_robots(disc, [(-7.0, 6.0, 0.25)])
    d = decide_all(view, disc, rules=rules, wiggle_deg=0.0)
    assert d.claim[0] == -1
    assert d.x[0] == pytest.approx(-7.0 + math.cos(0.25)) and d.y[0] == pytest.approx(6.0 + math.sin(0.25))
    assert d.heading[0] == 0.25


def test_one_step_facing_a_wall_turns_and_stays(disc):
    view = with_robots(disc, [(8.8, -7.0, 0.0)])  # one step east lands on the wall x = 10
    d = decide_all(view, disc, rules="local", wiggle_deg=0.0)
    assert (d.x[0], d.y[0]) == (8.8, -7.0)
    assert d.heading[0] != 0.0


# -- crowding -----------------------------------------------------------------------


@pytest.mark.parametrize("vision", [1.0, 2.0, 3.0])
def test_ahead_looks_only_at_the_patch_r_ahead(disc, vision):
    r = int(vision)
    for gap in (1, 2, 3):
        view = with_robots(disc, [(-7.0, -7.0, 0.0), (-7.0 + gap, -7.0, math.pi / 2)])
        d = decide_all(view, disc, rules="local", crowding="ahead", wiggle_deg=0.0, vision_radius=vision)
        blocked = (d.x[0], d.y[0]) == (-7.0, -7.0)
        assert blocked == (gap == r), (vision, gap)


def test_ahead_beyond_the_walls_is_never_crowded(disc):
    view = with_robots(disc, [(7.6, -7.0, 0.0)])  # 3 ahead is beyond the wall at x = 10
    d = decide_all(view, disc, rules="local", wiggle_deg=0.0, vision_radius=3.0)
    assert d.x[0] == pytest.approx(8.6)


def test_disc_blocks_when_another_moving_robot_is_near_the_point_ahead(disc):
    view = with_robots(disc, [(-7.0, -7.0, 0.0), (-5.5, -7.0, math.pi / 2)])
    d = decide_all(view, disc, rules="local", crowding="disc", wiggle_deg=0.0, vision_radius=1.0)
    assert (d.x[0], d.y[0]) == (-7.0, -7.0)  # robot 5 is 0.5 from robot 4's point ahead
    # robot 5's point ahead (-5.5, -6) is 1.8 from robot 4: free to go
    assert d.y[1] == pytest.approx(-6.0)
    # under 'ahead', robot 5 stands on no patch r = 1 ahead of robot 4 ((-6, -7)): robot 4 goes
    ahead = decide_all(view, disc, rules="local", crowding="ahead", wiggle_deg=0.0, vision_radius=1.0)
    assert ahead.x[0] == pytest.approx(-6.0)


@pytest.mark.parametrize("crowding", ["ahead", "disc"])
def test_localized_robots_do_not_block(disc, crowding):
    view = with_robots(disc, [(3.0, 1.6, math.pi / 2), (3.0, 2.6, 0.0)])
    view.state[5] = RobotState.LOCALIZED  # robot 5 sits on the patch ahead of robot 4
    view.frontier[:] = False  # nothing to join: robot 4 can only wander
    view.frontier_blocks[:] = 0
    d = decide(view, np.array([4]), disc, params(6, rules="local", crowding=crowding, wiggle_deg=0.0), tick=1)
    assert d.claim[0] == -1 and d.y[0] == pytest.approx(2.6)


# -- steps: literal -----------------------------------------------------------------


def test_literal_takes_three_steps_outside(disc):
    d = decide_all(with_robots(disc, [(-7.0, 6.0, 0.0)]), disc, rules="literal", wiggle_deg=0.0)
    assert (d.x[0], d.y[0], d.claim[0]) == (pytest.approx(-4.0), pytest.approx(6.0), -1)


def test_literal_takes_two_steps_inside_then_joins_from_where_it_stands(disc):
    moved = decide_all(with_robots(disc, [(-3.0, 3.0, math.pi / 2)]), disc, rules="literal", wiggle_deg=0.0)
    assert (moved.x[0], moved.y[0], moved.claim[0]) == (pytest.approx(-3.0), pytest.approx(5.0), -1)
    joins = decide_all(with_robots(disc, [(3.0, 0.0, math.pi)]), disc, rules="literal", wiggle_deg=0.0)
    assert joins.x[0] == pytest.approx(1.0) and patch(disc, joins.claim[0]) == (1, 0)


def test_literal_crowding_stops_the_last_step(disc):
    # robot 5 on (-5, 6): after two steps robot 4 stands at (-6, 6) facing it, so it turns instead
    view = with_robots(disc, [(-8.0, 6.0, 0.0), (-5.0, 6.0, math.pi / 2)])
    d = decide_all(view, disc, rules="literal", wiggle_deg=0.0, vision_radius=1.0)
    assert (d.x[0], d.y[0]) == (pytest.approx(-6.0), pytest.approx(6.0)) and d.heading[0] != 0.0


@pytest.mark.parametrize("seed", range(5))
def test_literal_never_steps_onto_a_wall(disc, seed):
    rng = np.random.default_rng(seed)
    robots = [(rng.uniform(-9.4, 9.4), rng.uniform(-9.4, 9.4), rng.uniform(0, 2 * math.pi)) for _ in range(300)]
    view = with_robots(disc, robots)
    d = decide_all(view, disc, rules="literal", seed=seed, vision_radius=2.0)
    px, py = disc.world.patch_of(d.x, d.y)
    assert np.all((np.abs(px) < 10) & (np.abs(py) < 10))
    inside = view.state[4:] == RobotState.MOVING_INSIDE
    moved = np.hypot(d.x - view.x[4:], d.y - view.y[4:])
    assert np.all(moved[inside] <= 2 + 1e-9) and np.all(moved[~inside] <= 3 + 1e-9)
    assert moved[~inside].max() > 2.5  # some robots did take three steps


# -- batches ------------------------------------------------------------------------


@pytest.fixture(scope="module", params=RULES)
def mid_run_star(request):
    sim = Simulation(Shape.load("star"), params(1100, seed=11, rules=request.param))
    for _ in range(60):
        sim.step()
    return sim


@pytest.mark.parametrize("batches", [2, 3, 7])
def test_any_split_into_batches_gives_the_same_decisions(mid_run_star, batches):
    sim = mid_run_star
    view, ids = sim.state, sim.moving_ids()
    whole = decide(view, ids, sim.shape, sim.params, sim.tick + 1)
    rng = np.random.default_rng(batches)
    owner = rng.integers(0, batches, ids.size)
    parts = [decide(view, ids[owner == b], sim.shape, sim.params, sim.tick + 1) for b in rng.permutation(batches)]
    joined = Decisions.concatenate(parts)
    order = np.argsort(joined.ids)
    for field in ("ids", "claim", "x", "y", "heading"):
        assert np.array_equal(getattr(joined, field)[order], getattr(whole, field)), field


def test_decide_reads_but_never_writes_the_view(mid_run_star):
    sim = mid_run_star
    before = sim.state.copy()
    decide(sim.state, sim.moving_ids(), sim.shape, sim.params, sim.tick + 1)
    for field in ("x", "y", "heading", "state", "occupancy", "frontier", "frontier_blocks"):
        assert np.array_equal(getattr(before, field), getattr(sim.state, field))


def test_decide_refuses_stationary_robots(mid_run_star):
    with pytest.raises(ContractError, match="moving robots only"):
        decide(mid_run_star.state, np.array([0]), mid_run_star.shape, mid_run_star.params, 1)
