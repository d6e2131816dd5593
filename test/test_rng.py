"""The counter-based RNG: pinned values, uniformity, independence of streams and keys."""

import numpy as np
import pytest
from scipy import stats

from swarm_ros.core.rng import STREAM_TURN, STREAM_WIGGLE, draw_bits, draw_uniform, uniform_array

pytestmark = pytest.mark.unit

MASK = (1 << 64) - 1


def _mix(z):
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & MASK
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & MASK
    return z ^ (z >> 31)


def reference_bits(seed, robot, tick, stream):
    """Plain-Python statement of the draw, independent of numba's integer typing."""
    z = _mix((seed + 0x9E3779B97F4A7C15) & MASK)
    z = _mix(z ^ robot)
    z = _mix(z ^ tick)
    return _mix(z ^ stream)


@pytest.mark.parametrize("key", [(0, 0, 0, 0), (1, 4, 1, 0), (2**63 - 1, 99_999, 1_000_000, 5), (123, 7, 42, 2)])
def test_draws_match_the_reference_statement(key):
    assert int(draw_bits(*key)) == reference_bits(*key)
    assert draw_uniform(*key) == (reference_bits(*key) >> 11) / 2.0**53


def test_uniform_draws_are_uniform_on_unit_interval():
    u = uniform_array(7, np.arange(200_000, dtype=np.int64), 3, STREAM_WIGGLE)
    assert u.min() >= 0.0 and u.max() < 1.0
    assert stats.kstest(u, "uniform").pvalue > 1e-3


def test_streams_ticks_and_seeds_are_uncorrelated():
    ids = np.arange(50_000, dtype=np.int64)
    base = uniform_array(7, ids, 3, STREAM_WIGGLE)
    for other in (
        uniform_array(7, ids, 3, STREAM_TURN),
        uniform_array(7, ids, 4, STREAM_WIGGLE),
        uniform_array(8, ids, 3, STREAM_WIGGLE),
        uniform_array(7, ids + 1, 3, STREAM_WIGGLE),
    ):
        assert abs(np.corrcoef(base, other)[0, 1]) < 0.02
