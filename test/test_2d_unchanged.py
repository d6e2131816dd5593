"""2D runs are byte-identical to those of the release before the 3D model (commit d168d39).

The hashes below were computed by that release's code; the 3D model shares the arbitration, the
frontier's upkeep and the view with 2D, and must not change a bit of a 2D run. Each covers the
final positions, headings, states, occupancy, frontier and every tick's metrics of one run with
failures (10% of the robots at tick 50), vision 2, 600 ticks.
"""

from __future__ import annotations

import pytest
from runs import run_digest

from swarm_ros.core import RunParams, Shape, Simulation
from swarm_ros.core.darr_niazi.rules import Decider

pytestmark = pytest.mark.unit

BEFORE_3D = {
    "star/paper": "a959c6a8b78970a5",
    "star/local": "6eec7f97ad413596",
    "star/literal": "eb7141abcf19d934",
    "tyre/paper": "e5deccdcbbcccd14",
    "tyre/local": "ebb13323bb68960b",
    "tyre/literal": "159c745c31fa77e9",
    "k-letter/paper": "8ac86a7e2a137481",
    "k-letter/local": "c9f5ff257661d672",
    "k-letter/literal": "2016ec9db03a8402",
    "wrench/paper": "f693610a190bb404",
    "wrench/local": "151cedfb19aab2e0",
    "wrench/literal": "37ae9da74675937f",
    "spinner/paper": "e0a1e6faf29d5aca",
    "spinner/local": "80d2a3dc4d5818d1",
    "spinner/literal": "717d7e7e73d94bc9",
    "rectangle/paper": "b3dea0132b73cff0",
    "rectangle/local": "78711f9261892a08",
    "rectangle/literal": "ae6763e4c3f4f413",
}


@pytest.mark.parametrize("case", sorted(BEFORE_3D))
def test_a_2d_run_is_byte_identical_to_the_release_before_3d(case):
    name, rules = case.split("/")
    shape = Shape.load(name)
    sim = Simulation(
        shape,
        RunParams(
            robots=shape.patches + 20,
            seed=2,
            rules=rules,
            max_ticks=600,
            vision_radius=2.0,
            fail_fraction=0.1,
            fail_tick=50,
        ),
    )
    sim.run()
    assert _digest(sim) == BEFORE_3D[case]


@pytest.mark.parametrize("case", [c for c in sorted(BEFORE_3D) if c.startswith(("star/", "tyre/"))])
def test_a_2d_run_decided_and_applied_tick_by_tick_is_the_same_run(case):
    """The engine's other path, a :class:`Decider`'s decisions applied tick by tick (what the ROS graph does)."""
    name, rules = case.split("/")
    shape = Shape.load(name)
    params = RunParams(
        robots=shape.patches + 20,
        seed=2,
        rules=rules,
        max_ticks=600,
        vision_radius=2.0,
        fail_fraction=0.1,
        fail_tick=50,
    )
    sim, decider = Simulation(shape, params), Decider(shape, params)
    while not sim.done:
        sim.apply(decider.decide(sim.state, sim.moving_ids(), sim.tick + 1))
    assert _digest(sim) == BEFORE_3D[case]


def _digest(sim: Simulation) -> str:
    s = sim.state
    return run_digest(sim, s.x, s.y, s.heading, s.state, s.occupancy, s.frontier)
