"""3D runs are byte-identical to those of the code before the kernels took their state by name (issue 36).

The hashes below were computed by commit 519da07's code (positional kernel arguments, a 2D world
signalled by empty z arrays). Each covers the final positions, headings, pitches, states, occupancy,
frontier and every tick's metrics of one run with failures (10% of the robots at tick 50), vision 2,
400 ticks, through both of the engine's paths: ``Simulation.run`` (the compiled loop of ticks) and a
:class:`~swarm_ros.core.darr_niazi.rules.Decider`'s decisions applied tick by tick (what the ROS graph does).
"""

from __future__ import annotations

import pytest
from runs import run_digest

from swarm_ros.core import RunParams, Shape, Simulation
from swarm_ros.core.darr_niazi.rules import Decider

pytestmark = pytest.mark.unit

BEFORE_NAMED_STATE = {
    "torus/paper": "738e59fdd43c4d95",
    "torus/local": "0a59963c91477017",
    "torus/literal": "7a3f5c410ea18e2c",
    "shell/paper": "27faef0776eda7d9",
    "shell/local": "3c44fd194dd0d0e2",
    "shell/literal": "66bcb30c7b9f52b6",
    "jack/paper": "a5bdea853938ea86",
    "jack/local": "c8f54f441c052515",
    "jack/literal": "26b641b70fadea66",
}


def _digest(sim: Simulation) -> str:
    s = sim.state
    return run_digest(sim, s.x, s.y, s.z, s.heading, s.pitch, s.state, s.occupancy, s.frontier)


@pytest.mark.parametrize("case", sorted(BEFORE_NAMED_STATE))
def test_a_3d_run_is_byte_identical_to_the_code_before(case):
    name, rules = case.split("/")
    shape = Shape.load(name)
    params = RunParams(
        robots=shape.patches + 20,
        seed=2,
        rules=rules,
        max_ticks=400,
        vision_radius=2.0,
        fail_fraction=0.1,
        fail_tick=50,
    )
    compiled = Simulation(shape, params)
    compiled.run()
    assert _digest(compiled) == BEFORE_NAMED_STATE[case]
    stepped, decider = Simulation(shape, params), Decider(shape, params)
    while not stepped.done:
        stepped.apply(decider.decide(stepped.state, stepped.moving_ids(), stepped.tick + 1))
    assert _digest(stepped) == BEFORE_NAMED_STATE[case]
