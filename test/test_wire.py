"""Hot-path row layouts and robot-id lists (no ROS needed)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from swarm_ros.core import RunParams, Shape, Simulation
from swarm_ros.protocol.rows import (
    DECISION_ROW,
    FLOAT64,
    ROBOT_ROW,
    UINT8,
    UINT32,
    batch_ids,
    check_fields,
    decision_rows,
    decisions_of,
    format_ranges,
    parse_ranges,
    point_fields,
    robot_rows,
)

pytestmark = pytest.mark.unit


def test_row_layouts_are_the_documented_point_fields():
    assert point_fields(ROBOT_ROW) == [("x", 0, FLOAT64, 1), ("y", 8, FLOAT64, 1), ("z", 16, FLOAT64, 1),
                                       ("heading", 24, FLOAT64, 1), ("id", 32, UINT32, 1), ("state", 36, UINT8, 1)]
    assert ROBOT_ROW.itemsize == DECISION_ROW.itemsize == 40
    check_fields(point_fields(DECISION_ROW), 40, DECISION_ROW)
    with pytest.raises(ValueError, match="unexpected point layout"):
        check_fields(point_fields(DECISION_ROW), 40, ROBOT_ROW)


def test_rows_carry_state_and_decisions_bit_for_bit():
    sim = Simulation(Shape.load("star"), RunParams(robots=300, seed=4))
    from swarm_ros.core.rules import decide

    d = decide(sim.state, sim.moving_ids(), sim.shape, sim.params, 1)
    back = decisions_of(1, np.frombuffer(decision_rows(d).tobytes(), dtype=DECISION_ROW))
    for name in ("ids", "claim", "x", "y", "heading"):
        np.testing.assert_array_equal(getattr(back, name), getattr(d, name))
    s = sim.state
    rows = np.frombuffer(robot_rows(np.arange(300), s.state, s.x, s.y, s.heading).tobytes(), dtype=ROBOT_ROW)
    np.testing.assert_array_equal(rows["x"], s.x)
    np.testing.assert_array_equal(rows["heading"], s.heading)
    np.testing.assert_array_equal(rows["state"], s.state)


@given(st.sets(st.integers(0, 5000), max_size=200))
def test_id_ranges_round_trip(ids):
    arr = np.array(sorted(ids), dtype=np.int64)
    np.testing.assert_array_equal(parse_ranges(format_ranges(arr)), arr)


@pytest.mark.parametrize("text", ["4-x", "a", "9-4", "-3", "1--2"])
def test_bad_id_lists_are_refused(text):
    with pytest.raises(ValueError):
        parse_ranges(text)


@pytest.mark.parametrize("robots,batches", [(5, 1), (1036, 2), (1036, 3), (100, 7), (12, 8)])
def test_batches_split_the_non_seed_robots_exactly_once(robots, batches):
    parts = [batch_ids(robots, k, batches) for k in range(batches)]
    np.testing.assert_array_equal(np.concatenate(parts), np.arange(4, robots))
    sizes = [p.size for p in parts]
    assert max(sizes) - min(sizes) <= 1
