"""The invariant checker itself: each rule must fire on a state broken in that way."""

import numpy as np
import pytest
from runs import disc_shape, params

from swarm_ros.core import RobotState, Shape, Simulation, World
from swarm_ros.core.darr_niazi.arbitration import JoinOutcome
from swarm_ros.core.darr_niazi.invariants import check_state, check_tick
from swarm_ros.core.errors import InvariantError

pytestmark = pytest.mark.unit


def ticked(rules="local"):
    """A run 20 ticks in: (state before the last tick, simulation after it); a small disc under
    ``local``, the star under ``paper`` (so that robots are walking)."""
    if rules == "local":
        sim = Simulation(disc_shape(World(radius=10), 5.0), params(150, seed=6, rules="local"))
    else:
        sim = Simulation(Shape.load("star"), params(1036, seed=6, rules=rules))
    sim.run(max_ticks=19)
    prev = sim.state.copy()
    sim.step()
    check_tick(prev, sim)  # the unbroken run passes
    return prev, sim


def localized_ids(s):
    return np.flatnonzero(s.state == RobotState.LOCALIZED)


def wandered_ids(sim):
    ids, claim, outcome = sim.last_joins()
    return ids[outcome == JoinOutcome.NO_CLAIM]


def two_on_one_patch(prev, sim):
    a, b = localized_ids(sim.state)[:2]
    sim.state.x[a], sim.state.y[a] = sim.state.x[b], sim.state.y[b]


def localized_off_shape(prev, sim):
    a = localized_ids(sim.state)[0]
    sim.state.x[a], sim.state.y[a] = 8.0, 8.0


def stale_frontier(prev, sim):
    sim.state.frontier[np.flatnonzero(sim.state.frontier)[0]] = False


def mislabelled_inside(prev, sim):
    s = sim.state
    i = np.flatnonzero(s.state == RobotState.MOVING_INSIDE)[0]
    s.state[i] = RobotState.MOVING_OUTSIDE


def localized_moved(prev, sim):
    a = localized_ids(prev)[0]
    prev.x[a] += 1.0


def unlocalized(prev, sim):
    prev.state[wandered_ids(sim)[0]] = RobotState.LOCALIZED


def long_step(prev, sim):
    prev.x[wandered_ids(sim)[0]] += 0.5


def no_tick(prev, sim):
    prev.tick = sim.tick


def seed_lost(prev, sim):
    sim.state.state[0] = RobotState.LOCALIZED


def stale_blocks(prev, sim):
    sim.state.frontier_blocks[0] += 1


def walking_under_local(prev, sim):
    sim.state.state[wandered_ids(sim)[0]] = RobotState.WALKING


def walker_missed_the_nearest(prev, sim):
    """A frontier patch appears right beside a walker that stepped elsewhere."""
    d = sim.last_decisions()
    k = np.flatnonzero((d.claim < 0) & (prev.state[d.ids] == RobotState.WALKING))[0]
    i = d.ids[k]
    px, py = sim.shape.world.patch_of(prev.x[i], prev.y[i])
    prev.frontier[sim.shape.world.flat_index(px, py)] = True


def loser_moved(prev, sim):
    d = sim.last_decisions()
    sim.state.x[d.ids[0]] += 0.25


BREAKS = [
    (two_on_one_patch, "two localized robots on one patch"),
    (localized_off_shape, "off the shape"),
    (stale_frontier, "frontier out of date"),
    (mislabelled_inside, "do not match the state"),
    (localized_moved, "a localized robot moved"),
    (unlocalized, "a localized robot became unlocalized"),
    (long_step, "moved other than one patch"),
    (no_tick, "tick did not advance"),
    (seed_lost, "robots 0-3, and only they, are seeds"),
    (stale_blocks, "frontier block counts out of date"),
    (walking_under_local, "a robot walks, yet the rule set's join is not 'walk'"),
]
WALK_BREAKS = [
    (walker_missed_the_nearest, "did not step 1 patch towards the nearest frontier patch"),
    (loser_moved, "not at the pose it decided"),
]


@pytest.mark.parametrize("corrupt,message", BREAKS, ids=[b[0].__name__ for b in BREAKS])
def test_each_rule_detects_its_violation(corrupt, message):
    prev, sim = ticked()
    corrupt(prev, sim)
    with pytest.raises(InvariantError, match=message):
        check_tick(prev, sim)


@pytest.mark.parametrize("corrupt,message", WALK_BREAKS, ids=[b[0].__name__ for b in WALK_BREAKS])
def test_each_walk_rule_detects_its_violation(corrupt, message):
    prev, sim = ticked("paper")
    corrupt(prev, sim)
    with pytest.raises(InvariantError, match=message):
        check_tick(prev, sim)


def test_check_state_alone_passes_on_a_fresh_run():
    sim = Simulation(disc_shape(World(radius=10), 5.0), params(150, seed=6))
    check_state(sim)
