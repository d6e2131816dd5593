"""Whole runs: every outcome, every built-in shape with all invariants checked, determinism,
and equality between the fused in-process step and the batched decide/apply data flow."""

import pytest
from runs import disc_shape, final_of, params, run_checked, run_in_batches

from swarm_ros.core import METRIC_COLUMNS, Outcome, RobotState, Shape, Simulation, World
from swarm_ros.core.darr_niazi.invariants import check_state
from swarm_ros.core.darr_niazi.run_result import summary_of
from swarm_ros.core.errors import ContractError

pytestmark = pytest.mark.unit

BUILTINS = ["k-letter", "rectangle", "spinner", "star", "tyre", "wrench"]


RULES = ["paper", "local", "literal"]


@pytest.mark.parametrize("rules", RULES)
@pytest.mark.parametrize("name", BUILTINS)
def test_builtin_shape_completes_with_its_patch_count_and_every_invariant_holds(name, rules):
    """Every invariant after every tick under the paper's rules; under the others, at the end (every tick under each
    rule set is test_properties', on 60 random shapes: checked here too, these 12 runs took 2 minutes in a process)."""
    shape = Shape.load(name)
    sim = Simulation(shape, params(shape.patches, seed=2, rules=rules))
    if rules == "paper":
        run_checked(sim)
    else:
        sim.run()
        check_state(sim)
    assert sim.outcome is Outcome.COMPLETE
    assert sim.metrics.empty_patches == 0 and sim.metrics.moving == 0


def test_paper_rules_walk_and_complete_the_star_in_a_few_hundred_ticks():
    sim = Simulation(Shape.load("star"), params(1036, seed=1))
    assert sim.params.rules == "paper"
    sim.run()
    walking = sim.history[:, METRIC_COLUMNS.index("walking")]
    assert sim.outcome is Outcome.COMPLETE and sim.tick < 1000
    assert walking[0] == 0 and walking[1:50].min() > 0  # robots inside the shape walk from tick 1


def test_local_with_disc_crowding_is_the_reading_before_rule_sets():
    """The project's results before rule sets existed were this reading; they stay reproducible
    (the star with seed 1 completed at tick 2757, and at vision 2 it gridlocked)."""
    sim = Simulation(Shape.load("star"), params(1036, seed=1, rules="local", crowding="disc"))
    assert sim.run() is Outcome.COMPLETE and sim.tick == 2757
    stuck = Simulation(
        Shape.load("star"), params(1036, seed=1, rules="local", crowding="disc", vision_radius=2.0, max_ticks=20000)
    )
    assert stuck.run() is Outcome.TIMEOUT
    fast = Simulation(Shape.load("star"), params(1036, seed=1, rules="local", vision_radius=2.0))
    assert fast.run() is Outcome.COMPLETE  # crowding 'ahead' does not freeze the swarm


def test_fewer_robots_than_patches_ends_incomplete():
    shape = disc_shape(World(radius=10), 5.0)  # 81 patches
    sim = run_checked(Simulation(shape, params(60, seed=4)))
    assert sim.outcome is Outcome.INCOMPLETE
    assert sim.metrics.localized == 60 and sim.metrics.empty_patches == 21


def test_more_robots_than_patches_completes_and_separates_the_extras():
    shape = disc_shape(World(radius=10), 5.0)
    sim = run_checked(Simulation(shape, params(100, seed=4)))
    assert sim.outcome is Outcome.COMPLETE_WITH_EXTRAS
    summary = summary_of(sim)
    assert summary["separated"] == summary["unlocalized"] == 19
    assert (sim.state.state == RobotState.SEPARATED).sum() == 19
    assert sim.metrics.stationary == 100 and sim.metrics.moving == 0


def test_tick_limit_ends_in_timeout():
    sim = run_checked(Simulation(Shape.load("star"), params(1036, seed=1, max_ticks=25)))
    assert sim.outcome is Outcome.TIMEOUT and sim.tick == 25
    assert summary_of(sim)["convergence_tick"] == 25


def test_only_the_seeds_is_incomplete_at_tick_zero():
    sim = Simulation(Shape.load("star"), params(4))
    assert sim.outcome is Outcome.INCOMPLETE and sim.tick == 0


def test_history_has_one_row_per_tick_and_matches_the_final_state():
    sim = Simulation(Shape.load("rectangle"), params(450, seed=8))
    seen = []
    sim.run(on_tick=lambda s: seen.append(s.tick))
    assert sim.history[:, 0].tolist() == list(range(sim.tick + 1))
    assert seen == list(range(1, sim.tick + 1))
    with pytest.raises(ContractError, match="has ended"):
        sim.step()


def test_same_seed_same_run_different_seed_different_run():
    shape = Shape.load("wrench")
    a = Simulation(shape, params(566, seed=21))
    b = Simulation(shape, params(566, seed=21))
    c = Simulation(shape, params(566, seed=22))
    for s in (a, b, c):
        s.run()
    assert final_of(a) == final_of(b)
    assert final_of(a) != final_of(c)


@pytest.mark.parametrize("rules", RULES)
@pytest.mark.parametrize("name,robots,vision", [("star", 1036, 1.0), ("tyre", 1300, 2.0)])
@pytest.mark.parametrize("batches", [1, 2, 4])
def test_batched_decide_and_apply_equal_the_fused_engine(name, robots, vision, batches, rules):
    shape = Shape.load(name)
    p = params(robots, seed=5, vision_radius=vision, max_ticks=4000, rules=rules)
    fused = Simulation(shape, p)
    fused.run()
    assert final_of(run_in_batches(shape, p, batches, seed=batches)) == final_of(fused)


@pytest.mark.parametrize("rules", RULES)
def test_batched_equals_fused_with_wider_vision_on_a_small_ring(small_ring, rules):
    p = params(90, seed=3, vision_radius=2.0, max_ticks=3000, rules=rules)
    fused = Simulation(small_ring, p)
    fused.run()
    assert final_of(run_in_batches(small_ring, p, 3, seed=1)) == final_of(fused)


@pytest.mark.parametrize("rules", RULES)
def test_running_in_chunks_equals_stepping_tick_by_tick(rules):
    shape = Shape.load("spinner")
    p = params(1100, seed=13, max_ticks=3000, rules=rules)
    stepped = Simulation(shape, p)
    while not stepped.done:
        stepped.step()
    chunked = Simulation(shape, p)
    while chunked.run(max_ticks=7) is None:
        assert chunked.tick % 7 == 0
    assert final_of(chunked) == final_of(stepped)
    assert chunked.history.shape == (chunked.tick + 1, len(METRIC_COLUMNS))
