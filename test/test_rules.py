"""The robot rule: hand-built situations, and independence from how robots are batched."""

import math

import numpy as np
import pytest

from conftest import disc_shape, params
from swarm_ros.core import RobotState, Shape, Simulation, World, decide
from swarm_ros.core.rules import Decisions
from swarm_ros.core.state import SwarmState, initial_state


@pytest.fixture(scope="module")
def disc():
    return disc_shape(World(radius=10), 5.0)


def with_robots(shape: Shape, robots: list[tuple[float, float, float]]) -> SwarmState:
    """Seeds plus moving robots at (x, y, heading) given by hand."""
    s = initial_state(shape, 4, seed=1)
    xs, ys, hs = (np.array([r[k] for r in robots]) for k in range(3))
    flat = shape.world.flat_index(*shape.world.patch_of(xs, ys))
    st = np.where(shape.mask.ravel()[flat], RobotState.MOVING_INSIDE, RobotState.MOVING_OUTSIDE)
    return SwarmState(x=np.r_[s.x, xs], y=np.r_[s.y, ys], heading=np.r_[s.heading, hs],
                      state=np.r_[s.state, st].astype(np.int8), occupancy=s.occupancy, frontier=s.frontier)


def decide_all(view, shape, **kw) -> Decisions:
    p = params(view.robots, **kw)
    return decide(view, view.moving_ids(), shape, p, tick=1)


def test_inside_robot_claims_the_nearest_frontier_patch(disc):
    # seeds occupy (-1..0, -1..0); the robot stands on (1.2, 0.1): frontier (1, 0) is nearest
    view = with_robots(disc, [(1.2, 0.1, 0.0)])
    d = decide_all(view, disc)
    assert disc.world.patch_xy(d.claim[0]) == (1, 0)
    assert (d.x[0], d.y[0]) == (1.2, 0.1)  # joining robots do not also wander


def test_robot_without_a_frontier_patch_in_view_wanders(disc):
    view = with_robots(disc, [(4.0, 0.0, 0.0)])
    d = decide_all(view, disc, vision_radius=1.0)
    assert d.claim[0] == -1
    far = decide_all(view, disc, vision_radius=3.0)  # (1, 0) is now within reach
    assert disc.world.patch_xy(far.claim[0]) == (1, 0)


def test_robot_outside_the_shape_never_claims(disc):
    view = with_robots(disc, [(6.0, 0.0, math.pi)])  # outside, frontier (1, 0) within vision 5
    assert decide_all(view, disc, vision_radius=5.0).claim[0] == -1


def test_free_robot_steps_one_patch_along_its_heading(disc):
    view = with_robots(disc, [(-7.0, 6.0, 0.25)])
    d = decide_all(view, disc, wiggle_deg=0.0)
    assert d.claim[0] == -1
    assert d.x[0] == pytest.approx(-7.0 + math.cos(0.25)) and d.y[0] == pytest.approx(6.0 + math.sin(0.25))
    assert d.heading[0] == 0.25


def test_robot_facing_a_wall_turns_and_stays(disc):
    view = with_robots(disc, [(8.8, -7.0, 0.0)])  # one step east lands on the wall x = 10
    d = decide_all(view, disc, wiggle_deg=0.0)
    assert (d.x[0], d.y[0]) == (8.8, -7.0)
    assert d.heading[0] != 0.0


def test_robot_with_another_moving_robot_near_the_point_ahead_stays(disc):
    view = with_robots(disc, [(-7.0, -7.0, 0.0), (-5.5, -7.0, math.pi / 2)])
    d = decide_all(view, disc, wiggle_deg=0.0, vision_radius=1.0)
    assert (d.x[0], d.y[0]) == (-7.0, -7.0)  # robot 5 is 0.5 from robot 4's point ahead
    # robot 5's point ahead (-5.5, -6) is 1.8 from robot 4: free to go
    assert d.y[1] == pytest.approx(-6.0)


def test_localized_robots_do_not_block(disc):
    view = with_robots(disc, [(3.0, 1.6, math.pi / 2), (3.0, 3.0, 0.0)])
    view.state[5] = RobotState.LOCALIZED  # robot 5 sits 0.4 from robot 4's point ahead
    view.frontier[:] = False  # nothing to join: robot 4 can only walk
    d = decide(view, np.array([4]), disc, params(6, wiggle_deg=0.0), tick=1)
    assert d.claim[0] == -1 and d.y[0] == pytest.approx(2.6)


@pytest.fixture(scope="module")
def mid_run_star():
    sim = Simulation(Shape.load("star"), params(1100, seed=11))
    for _ in range(150):
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
    for field in ("x", "y", "heading", "state", "occupancy", "frontier"):
        assert np.array_equal(getattr(before, field), getattr(sim.state, field))


def test_decide_refuses_stationary_robots(mid_run_star):
    with pytest.raises(ValueError, match="moving robots only"):
        decide(mid_run_star.state, np.array([0]), mid_run_star.shape, mid_run_star.params, 1)
