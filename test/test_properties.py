"""Property-based tests (hypothesis): random small shapes, robot counts, vision radii and seeds.

Every tick of every generated run must satisfy the Z-spec invariants; runs must be
reproducible and independent of how robots are split into batches.
"""

import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st
from runs import final_of, run_checked, run_in_batches

from swarm_ros.core import RunParams, Shape, ShapeError, Simulation, World

pytestmark = pytest.mark.unit

STEPS = [(-1, -1), (0, -1), (1, -1), (-1, 0), (1, 0), (-1, 1), (0, 1), (1, 1)]


@st.composite
def small_shapes(draw) -> Shape:
    """An 8-connected blob grown from a 2 x 2 block, kept off the walls of a small world."""
    radius = draw(st.integers(5, 9))
    lim = radius - 2
    x0 = draw(st.integers(-lim, lim - 1))
    y0 = draw(st.integers(-lim, lim - 1))
    cells = [(x0, y0), (x0 + 1, y0), (x0, y0 + 1), (x0 + 1, y0 + 1)]
    seen = set(cells)
    for pick, step in draw(st.lists(st.tuples(st.integers(0, 10**6), st.integers(0, 7)), max_size=120)):
        cx, cy = cells[pick % len(cells)]
        nx, ny = cx + STEPS[step][0], cy + STEPS[step][1]
        if abs(nx) <= lim and abs(ny) <= lim and (nx, ny) not in seen:
            seen.add((nx, ny))
            cells.append((nx, ny))
    world = World(radius)
    mask = np.zeros((world.size, world.size), dtype=bool)
    xs, ys = np.array(cells).T
    mask[ys + radius, xs + radius] = True
    return Shape(name="blob", mask=mask, world=world, source="hypothesis blob")


@st.composite
def runs(draw):
    shape = draw(small_shapes())
    robots = draw(st.integers(4, min(shape.free_patches, 2 * shape.patches + 10)))
    vision = draw(st.sampled_from([1.0, 1.5, 2.0, 3.0]))
    seed = draw(st.integers(0, 2**63 - 1))
    rules = draw(st.sampled_from(["paper", "local", "literal"]))
    crowding = draw(st.sampled_from(["", "ahead", "disc"]))
    return shape, RunParams(
        robots=robots, vision_radius=vision, seed=seed, max_ticks=300, rules=rules, crowding=crowding
    )


SETTINGS = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])


@SETTINGS
@given(runs())
def test_every_invariant_holds_at_every_tick(run):
    shape, p = run
    sim = run_checked(Simulation(shape, p))
    assert sim.outcome is not None
    event(f"outcome {sim.outcome}")
    event(f"ticks {'<50' if sim.tick < 50 else '<300' if sim.tick < 300 else '300'}")
    assert sim.metrics.localized <= min(p.robots, shape.patches)


@settings(max_examples=15, deadline=None)
@given(runs(), st.integers(1, 5), st.integers(0, 1000))
def test_runs_are_reproducible_and_independent_of_batching(run, batches, split_seed):
    shape, p = run
    a = Simulation(shape, p)
    a.run()
    b = Simulation(shape, p)
    b.run()
    assert final_of(a) == final_of(b)
    assert final_of(run_in_batches(shape, p, batches, split_seed)) == final_of(a)


@settings(max_examples=200, deadline=None)
@given(st.text(alphabet="#.;x \n\t", max_size=200))
def test_text_loader_accepts_or_rejects_with_a_shape_error(tmp_path_factory, text):
    path = tmp_path_factory.mktemp("fuzz") / "s.txt"
    path.write_text(text)
    try:
        shape = Shape.load(path, World(radius=8))
    except ShapeError as exc:
        assert str(path) in str(exc) and "\n" not in str(exc)
    else:
        assert shape.patches > 0 and shape.seed_patches.shape == (4, 2)
