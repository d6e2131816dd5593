"""Strips, halos and compact rows (swarm_ros.core.regions, swarm_ros.protocol.rows): no ROS needed."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from swarm_ros.core import Shape
from swarm_ros.core.errors import ParameterError
from swarm_ros.core.regions import balanced_cuts, columns, halo, parse_cuts, strip
from swarm_ros.core.state import initial_state

pytestmark = pytest.mark.unit


@given(radius=st.integers(2, 60), batches=st.integers(1, 9), data=st.data())
def test_strips_tile_the_columns_exactly_once_for_any_cuts(radius, batches, data):
    width = 2 * radius + 1
    if batches > width:
        return
    inner = data.draw(st.lists(st.integers(1, width - 1), min_size=batches - 1, max_size=batches - 1, unique=True))
    cuts = np.sort(np.asarray(inner, dtype=np.int64)) - radius
    spans = [strip(k, batches, cuts, radius) for k in range(batches)]
    covered = np.concatenate([np.arange(first, last + 1) for first, last in spans])
    assert np.array_equal(covered, np.arange(width))


@settings(deadline=None)  # the first example loads numba's cached kernels (0.3 s) when this module runs alone
@given(seed=st.integers(0, 10**6), batches=st.integers(1, 12))
def test_balanced_cuts_give_each_strip_about_as_many_robots(seed, batches):
    shape = Shape.load("star")
    radius = shape.world.radius
    x = initial_state(shape, 1036, seed).x[4:]
    cuts = balanced_cuts(x, radius, batches)
    counts = np.bincount(np.searchsorted(cuts + radius, columns(x, radius), side="right"), minlength=batches)
    assert counts.sum() == x.size
    # a column holds at most 2R + 1 robots, so no strip is more than a column off its share
    assert np.abs(counts - x.size / batches).max() <= 2 * radius + 1


def test_balanced_cuts_leave_every_strip_a_column_even_when_the_robots_crowd_one():
    cuts = balanced_cuts(np.zeros(100), 3, 7)  # every robot in the middle column of 7
    assert [strip(k, 7, cuts, 3) for k in range(7)] == [(k, k) for k in range(7)]


@pytest.mark.parametrize(
    ("text", "why"), [("a,b", "whole x positions"), ("3,1", "strictly ascending"), ("1.5", "whole x positions")]
)
def test_bad_cuts_are_refused_in_one_line(text, why):
    with pytest.raises(ParameterError, match=why):
        parse_cuts(text)


@pytest.mark.parametrize(
    ("cuts", "batches", "why"),
    [
        ([0], 3, "gives 1 cuts; 3 batches need 2"),
        ([-40], 2, "leave a strip with no column"),
        ([0, 0], 3, "leave a strip with no column"),
    ],
)
def test_cuts_that_do_not_fit_the_batches_are_refused(cuts, batches, why):
    with pytest.raises(ParameterError, match=why):
        strip(0, batches, np.asarray(cuts), 32)


def test_the_halo_covers_what_a_decision_reads():
    # three literal moves, the crowding test's centre one patch ahead, its vision radius, a patch of rounding
    assert halo(1.0) == 6 and halo(2.5) == 8
