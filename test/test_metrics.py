"""Metric definitions and termination order."""

import numpy as np
import pytest

from swarm_ros.core.darr_niazi.metrics import TickMetrics, convergence_rate, outcome_of, tick_metrics
from swarm_ros.core.metrics import Outcome

pytestmark = pytest.mark.unit


def test_metrics_from_state_counts():
    # seed, moving outside, moving inside, localized, separated, removed, walking
    m = tick_metrics(12, np.array([4, 30, 7, 50, 0, 9, 11]), shape_patches=100)
    assert m == TickMetrics(tick=12, stationary=54, localized=54, inside=7, moving=48, empty_patches=46, walking=11)


@pytest.mark.parametrize(
    "m,robots,expected",
    [
        (TickMetrics(5, 100, 100, 0, 0, 0, 0), 100, Outcome.COMPLETE),
        (TickMetrics(5, 100, 100, 0, 3, 0, 0), 103, Outcome.COMPLETE_WITH_EXTRAS),
        (TickMetrics(5, 90, 90, 0, 0, 10, 0), 90, Outcome.INCOMPLETE),
        (TickMetrics(50, 90, 90, 1, 5, 10, 0), 95, Outcome.TIMEOUT),
        (TickMetrics(49, 90, 90, 1, 5, 10, 0), 95, None),
        (TickMetrics(50, 100, 100, 0, 0, 0, 0), 100, Outcome.COMPLETE),  # completion wins over the limit
    ],
)
def test_outcome_is_checked_in_model_order(m, robots, expected):
    assert outcome_of(m, shape_patches=100, robots=robots, max_ticks=50) is expected


def test_walking_robots_are_moving_so_the_run_goes_on():
    m = TickMetrics(7, 90, 90, 0, 4, 10, 4)  # four robots walk, none wanders
    assert outcome_of(m, shape_patches=100, robots=94, max_ticks=50) is None


def test_convergence_rate_counts_joins_per_tick_without_the_seeds():
    assert convergence_rate(TickMetrics(100, 54, 54, 0, 0, 0, 0)) == 0.5
    assert convergence_rate(TickMetrics(0, 4, 4, 0, 0, 0, 0)) == 0.0


def test_state_codes_are_stable():
    from swarm_ros.core import RobotState

    assert [(s.value, s.label) for s in RobotState] == [
        (0, "seed"),
        (1, "moving_outside"),
        (2, "moving_inside"),
        (3, "localized"),
        (4, "separated"),
        (5, "removed"),
        (6, "walking"),
    ]
