"""Hot-path row layouts (no ROS needed)."""

from __future__ import annotations

import numpy as np
import pytest

from swarm_ros.core import RunParams, Shape, Simulation
from swarm_ros.core.errors import ContractError
from swarm_ros.protocol.darr_niazi.rows import DECISION_ROW, ROBOT_ROW, decision_rows, decisions_of, robot_rows
from swarm_ros.protocol.rows import FLOAT64, UINT8, UINT32, check_fields, point_fields

pytestmark = pytest.mark.unit


def test_row_layouts_are_the_documented_point_fields():
    assert point_fields(ROBOT_ROW) == (
        ("x", 0, FLOAT64, 1),
        ("y", 8, FLOAT64, 1),
        ("z", 16, FLOAT64, 1),
        ("heading", 24, FLOAT64, 1),
        ("id", 32, UINT32, 1),
        ("state", 36, UINT8, 1),
    )
    assert ROBOT_ROW.itemsize == DECISION_ROW.itemsize == 40
    check_fields(point_fields(DECISION_ROW), 40, DECISION_ROW)
    with pytest.raises(ContractError, match="unexpected point layout"):
        check_fields(point_fields(DECISION_ROW), 40, ROBOT_ROW)


def test_rows_carry_state_and_decisions_bit_for_bit():
    sim = Simulation(Shape.load("star"), RunParams(robots=300, seed=4))
    from swarm_ros.core.darr_niazi.rules import decide

    d = decide(sim.state, sim.moving_ids(), sim.shape, sim.params, 1)
    back = decisions_of(1, np.frombuffer(decision_rows(d).tobytes(), dtype=DECISION_ROW))
    for name in ("ids", "claim", "x", "y", "heading"):
        np.testing.assert_array_equal(getattr(back, name), getattr(d, name))
    s = sim.state
    rows = np.frombuffer(robot_rows(np.arange(300), s.state, s.x, s.y, s.heading).tobytes(), dtype=ROBOT_ROW)
    np.testing.assert_array_equal(rows["x"], s.x)
    np.testing.assert_array_equal(rows["heading"], s.heading)
    np.testing.assert_array_equal(rows["state"], s.state)
