"""The invariant checker itself: each rule must fire on a state broken in that way."""

import numpy as np
import pytest

from conftest import disc_shape, params
from swarm_ros.core import RobotState, Simulation, World
from swarm_ros.core.arbitration import JoinOutcome
from swarm_ros.core.invariants import InvariantError, check_state, check_tick


def ticked():
    """A small run 20 ticks in: (state before the last tick, simulation after it)."""
    sim = Simulation(disc_shape(World(radius=10), 5.0), params(150, seed=6))
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
]


@pytest.mark.parametrize("corrupt,message", BREAKS, ids=[b[0].__name__ for b in BREAKS])
def test_each_rule_detects_its_violation(corrupt, message):
    prev, sim = ticked()
    corrupt(prev, sim)
    with pytest.raises(InvariantError, match=message):
        check_tick(prev, sim)


def test_check_state_alone_passes_on_a_fresh_run():
    sim = Simulation(disc_shape(World(radius=10), 5.0), params(150, seed=6))
    check_state(sim)
