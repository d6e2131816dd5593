import numpy as np
import pytest

from swarm_ros.core import ParameterError, World

pytestmark = pytest.mark.unit


def test_default_world_is_65_by_65_with_a_wall_ring():
    w = World()
    assert w.size == 65
    wall = w.wall_mask()
    assert wall.shape == (65, 65)
    assert wall.sum() == 65 * 4 - 4
    assert not wall[1:-1, 1:-1].any()


def test_flat_index_and_patch_xy_round_trip():
    w = World(radius=5)
    px, py = np.meshgrid(np.arange(-5, 6), np.arange(-5, 6))
    flat = w.flat_index(px.ravel(), py.ravel())
    assert np.array_equal(flat, np.arange(w.patch_count))
    bx, by = w.patch_xy(flat)
    assert np.array_equal(bx, px.ravel()) and np.array_equal(by, py.ravel())


def test_robot_is_on_the_patch_with_the_nearest_centre():
    w = World()
    x = np.array([0.49, 0.5, -0.5, -0.51, 2.2])
    px, _ = w.patch_of(x, x)
    assert px.tolist() == [0, 1, 0, -1, 2]


@pytest.mark.parametrize("radius", [2, -1, 3.5, "8"])
def test_bad_world_radius_is_rejected(radius):
    with pytest.raises(ParameterError, match="world_radius"):
        World(radius)
