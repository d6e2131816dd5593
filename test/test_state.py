"""Initial placement (tick 0)."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy import ndimage

from swarm_ros.core import ParameterError, RobotState, Shape
from swarm_ros.core.darr_niazi.state import frontier_of, initial_state, near_any

pytestmark = pytest.mark.unit


@pytest.fixture(scope="module")
def star():
    return Shape.load("star")


def test_seeds_are_robots_0_to_3_on_the_seed_block(star):
    s = initial_state(star, 1036, seed=5)
    assert (s.state[:4] == RobotState.SEED).all()
    assert np.array_equal(np.c_[s.x[:4], s.y[:4]], star.seed_patches)
    assert sorted(s.occupancy[s.occupancy >= 0].tolist()) == [0, 1, 2, 3]


def test_other_robots_start_on_distinct_free_patches_inside_or_outside_the_shape(star):
    s = initial_state(star, 3000, seed=5)
    world = star.world
    px, py = world.patch_of(s.x, s.y)
    flat = world.flat_index(px, py)
    assert np.unique(flat).size == 3000
    assert not world.wall_mask().ravel()[flat].any()
    inside = star.mask.ravel()[flat[4:]]
    assert inside.any() and (~inside).any()
    expected = np.where(inside, RobotState.MOVING_INSIDE, RobotState.MOVING_OUTSIDE)
    assert np.array_equal(s.state[4:], expected)
    assert (s.heading >= 0).all() and (s.heading < 2 * np.pi).all()


def test_positions_are_spread_uniformly_over_free_patches(star):
    s = initial_state(star, 3000, seed=9)
    offsets = np.r_[s.x[4:] - np.floor(s.x[4:] + 0.5), s.y[4:] - np.floor(s.y[4:] + 0.5)]
    assert -0.5 <= offsets.min() and offsets.max() < 0.5
    assert abs(offsets.mean()) < 0.02


def test_same_seed_same_start_different_seed_different_start(star):
    a, b, c = initial_state(star, 500, 1), initial_state(star, 500, 1), initial_state(star, 500, 2)
    assert np.array_equal(a.x, b.x) and np.array_equal(a.heading, b.heading)
    assert not np.array_equal(a.x, c.x)


def test_frontier_is_the_ring_around_the_seeds(star):
    s = initial_state(star, 100, 1)
    assert s.frontier.sum() == 12  # the 4 x 4 ring around a 2 x 2 block inside the star
    assert np.array_equal(s.frontier, frontier_of(star, s.occupancy))


def test_too_many_or_too_few_robots_are_rejected(star):
    with pytest.raises(ParameterError, match="3970 robots do not fit on the 3969 free patches"):
        initial_state(star, 3970, 1)
    with pytest.raises(ParameterError, match="at least 4"):
        initial_state(star, 3, 1)
    assert initial_state(star, 3969, 1).robots == 3969  # every free patch taken is fine


@settings(max_examples=200, deadline=None)
@given(arrays(bool, st.tuples(st.integers(1, 20), st.integers(1, 20))))
def test_near_any_is_a_3x3_binary_dilation(grid):
    assert np.array_equal(near_any(grid), ndimage.binary_dilation(grid, structure=np.ones((3, 3), bool)))


#: numpy's transcendental ufuncs: on a CPU with AVX-512 numpy computes them with other code (its SIMD dispatch),
#: whose last bits differ from the C library's, so a run's result would depend on the machine
_CPU_DEPENDENT = {
    "sin", "cos", "tan", "arcsin", "arccos", "arctan", "arctan2", "sinh", "cosh", "tanh",
    "exp", "exp2", "expm1", "log", "log2", "log10", "log1p", "power", "cbrt",
}  # fmt: skip


def test_the_model_uses_no_numpy_function_whose_last_bits_depend_on_the_cpu():
    """The same seed gave another 3D run on an AVX-512 machine: the initial pitches came from np.arcsin. The
    model's transcendental functions are the C library's (math.*, and numba's, which calls it)."""
    import ast
    from pathlib import Path

    import swarm_ros.core

    found = []
    for path in sorted(Path(swarm_ros.core.__file__).parent.glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if (
                isinstance(node, ast.Attribute)
                and node.attr in _CPU_DEPENDENT
                and isinstance(node.value, ast.Name)
                and node.value.id in ("np", "numpy")
            ):
                found.append(f"{path.name}:{node.lineno}: np.{node.attr}")
    assert not found, found


def test_initial_pitches_are_the_c_librarys_arcsine_of_their_draws():
    from swarm_ros.core.darr_niazi.state import STREAM_PLACE_PITCH
    from swarm_ros.core.rng import uniform_array

    shape = Shape.load("torus")
    s = initial_state(shape, 300, 7)
    ids = np.arange(4, 300)
    want = [math.asin(2.0 * u - 1.0) for u in uniform_array(7, ids, 0, STREAM_PLACE_PITCH).tolist()]
    assert s.pitch is not None and s.pitch[4:].tolist() == want
