"""The SwarmView rebuilds the world's state from broadcast rows; the Decider equals decide()."""

from __future__ import annotations

import numpy as np
import pytest
from runs import params

from swarm_ros.core import RunParams, Shape, Simulation
from swarm_ros.core.darr_niazi.rules import Decider, Decisions, decide
from swarm_ros.core.darr_niazi.state import RobotState
from swarm_ros.core.darr_niazi.swarm_view import SwarmView
from swarm_ros.core.errors import ContractError

pytestmark = pytest.mark.unit


def _feed(view: SwarmView, sim: Simulation, ids: np.ndarray) -> None:
    s = sim.state
    view.update(sim.tick, ids, s.state[ids], s.x[ids], s.y[ids], s.heading[ids])


def _assert_same(a, b) -> None:
    for name in ("x", "y", "heading", "state", "occupancy", "frontier"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    assert a.tick == b.tick


@pytest.mark.parametrize("robots_over_patches", [-30, 0, 25])
def test_view_fed_the_changed_rows_equals_the_world_every_tick(small_ring, robots_over_patches):
    sim = Simulation(small_ring, params(small_ring.patches + robots_over_patches, seed=3))
    view = SwarmView(small_ring, sim.params.robots)
    _feed(view, sim, np.arange(sim.params.robots))
    _assert_same(view.state, sim.state)
    while not sim.done:
        sim.step()
        _feed(view, sim, sim.last_joins()[0])
        _assert_same(view.state, sim.state)
    assert sim.outcome is not None


def test_decider_from_a_view_gives_the_fused_engines_run(small_ring):
    p = params(small_ring.patches + 5, seed=11, vision_radius=2.0)
    fused = Simulation(small_ring, p)
    fused.run()
    sim = Simulation(small_ring, p)
    view = SwarmView(small_ring, p.robots)
    _feed(view, sim, np.arange(p.robots))
    decider = Decider(small_ring, p)
    while not sim.done:
        moving = view.moving_ids()
        halves = [decider.decide(view.state, part, sim.tick + 1, moving) for part in np.array_split(moving, 2)]
        sim.apply(Decisions.concatenate([h for h in halves if h.ids.size]))
        _feed(view, sim, sim.last_joins()[0])
    np.testing.assert_array_equal(sim.history, fused.history)
    _assert_same(sim.state, fused.state)


def test_decider_reused_across_ticks_equals_one_shot_decide():
    shape = Shape.load("wrench")
    p = RunParams(robots=400, seed=5)
    sim = Simulation(shape, p)
    decider = Decider(shape, p)
    for _ in range(30):
        ids = sim.moving_ids()
        a = decider.decide(sim.state, ids, sim.tick + 1)
        b = decide(sim.state, ids, shape, p, sim.tick + 1)
        for name in ("ids", "claim", "x", "y", "heading"):
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
        sim.apply(a)


def test_view_rejects_skipped_ticks_partial_tick_zero_and_impossible_joins(small_disc):
    sim = Simulation(small_disc, params(40, seed=2))
    s, all_ids = sim.state, np.arange(40)
    view = SwarmView(small_disc, 40)
    with pytest.raises(ContractError, match="tick 0 must hold every robot"):
        view.update(0, all_ids[:-1], s.state[:-1], s.x[:-1], s.y[:-1], s.heading[:-1])
    view = SwarmView(small_disc, 40)
    with pytest.raises(ContractError, match="arrived after tick -1"):
        view.update(1, all_ids, s.state, s.x, s.y, s.heading)
    view.update(0, all_ids, s.state, s.x, s.y, s.heading)
    with pytest.raises(ContractError, match="unknown robot state"):
        view.update(1, all_ids[4:5], np.array([9]), s.x[4:5], s.y[4:5], s.heading[4:5])
    view = SwarmView(small_disc, 40)
    view.update(0, all_ids, s.state, s.x, s.y, s.heading)
    # robot 4 "localizes" on a seed's patch: not an empty shape patch
    with pytest.raises(ContractError, match="not an empty shape patch"):
        view.update(1, np.array([4]), np.array([RobotState.LOCALIZED]), s.x[:1], s.y[:1], s.heading[:1])


@pytest.mark.parametrize("fail", [0.0, 0.2])
def test_a_view_loaded_from_a_snapshot_equals_one_that_followed_every_tick(small_ring, fail):
    """How a restarted robot batch catches up: every robot's row at tick t gives the same state,
    occupancy, frontier and frontier blocks as following the rows from tick 0 (removals included)."""
    sim = Simulation(small_ring, params(small_ring.patches + 10, seed=5, fail_fraction=fail, fail_tick=12))
    every = np.arange(sim.params.robots)
    followed = SwarmView(small_ring, sim.params.robots)
    _feed(followed, sim, every)
    loads = 0
    while not sim.done:
        sim.step()
        _feed(followed, sim, np.union1d(sim.last_joins()[0], sim.last_removed))
        if sim.tick % 7 == 0 or sim.done:
            loaded = SwarmView(small_ring, sim.params.robots)
            s = sim.state
            loaded.load(sim.tick, every[::-1], s.state[::-1], s.x[::-1], s.y[::-1], s.heading[::-1])  # any order
            _assert_same(loaded.state, followed.state)
            np.testing.assert_array_equal(loaded.state.frontier_blocks, followed.state.frontier_blocks)
            loads += 1
            # and it follows the next ticks like the other
            followed, loaded = loaded, followed
    assert loads > 3 and (fail == 0 or (sim.state.state == RobotState.REMOVED).any())


def test_a_snapshot_must_hold_every_robot_once(small_disc):
    sim = Simulation(small_disc, params(small_disc.patches, seed=1))
    s = sim.state
    view = SwarmView(small_disc, sim.params.robots)
    ids = np.arange(sim.params.robots)
    with pytest.raises(ContractError, match="must hold every robot once"):
        view.load(5, ids[1:], s.state[1:], s.x[1:], s.y[1:], s.heading[1:])
    with pytest.raises(ContractError, match="a snapshot of tick -1"):
        view.load(-1, ids, s.state, s.x, s.y, s.heading)
