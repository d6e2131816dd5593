"""Region cuts and the study's model's halo (swarm_ros.core.strips, swarm_ros.core.darr_niazi.legality): no ROS
needed. How strips tile a grid and follow its robots is test_study_central's and test_rubenstein_batches'."""

from __future__ import annotations

import pytest

from swarm_ros.core.darr_niazi.legality import halo
from swarm_ros.core.errors import ParameterError
from swarm_ros.core.strips import parse_cuts

pytestmark = pytest.mark.unit


@pytest.mark.parametrize(
    ("text", "why"),
    [("a,b", "whole x positions"), ("3,1", "strictly ascending"), ("1.5", "whole x positions"), ("1,,2", "empty")],
)
def test_bad_cuts_are_refused_in_one_line(text, why):
    with pytest.raises(ParameterError, match=why):
        parse_cuts(text)


def test_cuts_are_read_in_order_and_none_is_empty():
    assert parse_cuts("-20, 0,20").tolist() == [-20, 0, 20] and parse_cuts("").size == 0


def test_the_halo_covers_what_a_decision_reads():
    # three literal moves, the crowding test's centre one patch ahead, its vision radius, a patch of rounding
    assert halo(1.0) == 6 and halo(2.5) == 8
