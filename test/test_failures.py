"""Robot failures (--fail-robots P@T, and Simulation.remove for lost processes): removal, self-repair,
the formal checks' one exception, and the view following the world."""

from __future__ import annotations

import numpy as np
import pytest
from runs import disc_shape, run_checked

from swarm_ros.app import cli
from swarm_ros.core import RunParams, Simulation, World
from swarm_ros.core.darr_niazi.arbitration import JoinOutcome
from swarm_ros.core.darr_niazi.engine import failing_robots
from swarm_ros.core.darr_niazi.run_result import summary_of
from swarm_ros.core.darr_niazi.state import RobotState, frontier_of
from swarm_ros.core.darr_niazi.swarm_view import SwarmView
from swarm_ros.core.errors import ContractError, ParameterError

pytestmark = pytest.mark.unit


@pytest.fixture(scope="module")
def disc():
    return disc_shape(World(10), 5.0)


@pytest.mark.parametrize("extra,fraction,tick", [(10, 0.2, 30), (0, 0.5, 5), (-5, 0.1, 60), (3, 0.05, 1), (20, 0.3, 2)])
def test_failures_keep_every_invariant_and_the_swarm_repairs_the_shape(disc, extra, fraction, tick):
    n = disc.patches + extra
    sim = run_checked(Simulation(disc, RunParams(robots=n, seed=4, fail_fraction=fraction, fail_tick=tick)))
    lost = round(fraction * n)
    assert sim.losses == [(tick, lost)] and sim.removed == lost
    s = sim.state
    assert int((s.state == RobotState.REMOVED).sum()) == lost
    summary = summary_of(sim)
    assert summary["lost_robots"] == lost and summary["losses"] == [{"tick": tick, "robots": lost}]
    assert summary["localized"] + summary["unlocalized"] + lost == n
    # self-repair: the remaining robots refill the freed patches, as far as there are robots
    assert summary["localized"] == min(n - lost, disc.patches)
    assert np.array_equal(s.frontier, frontier_of(disc, s.occupancy))


def test_removed_localized_robots_free_their_patches_at_the_failure_tick(disc):
    p = RunParams(robots=disc.patches, seed=9, fail_fraction=0.4, fail_tick=80)
    sim = Simulation(disc, p)
    sim.run(max_ticks=79)
    before = sim.state.copy()
    sim.step()
    failed = failing_robots(p)
    assert np.array_equal(sim.last_removed, failed) and failed.size == round(0.4 * disc.patches)
    was_localized = failed[np.isin(before.state[failed], (RobotState.SEED, RobotState.LOCALIZED))]
    assert was_localized.size > 0
    assert not np.isin(was_localized, sim.state.occupancy).any()
    ids, _, outcome = sim.last_joins()
    joined_and_kept = int(np.sum((outcome == JoinOutcome.SUCCESS) & ~np.isin(ids, failed)))
    localized_before = int(np.isin(before.state, (RobotState.SEED, RobotState.LOCALIZED)).sum())
    assert sim.metrics.localized == localized_before + joined_and_kept - was_localized.size


def test_the_same_seed_fails_the_same_robots_in_run_and_in_step(disc):
    p = RunParams(robots=disc.patches + 5, seed=2, fail_fraction=0.25, fail_tick=40)
    a = Simulation(disc, p)
    a.run()
    b = Simulation(disc, p)
    while not b.done:
        b.step()
    assert np.array_equal(a.history, b.history) and np.array_equal(a.state.state, b.state.state)
    other = failing_robots(RunParams(robots=disc.patches + 5, seed=3, fail_fraction=0.25, fail_tick=40))
    assert not np.array_equal(failing_robots(p), other)


def test_view_follows_removals_and_rejects_a_removed_robot_coming_back(disc):
    p = RunParams(robots=disc.patches, seed=5, fail_fraction=0.3, fail_tick=50)
    sim = Simulation(disc, p)
    rep = SwarmView(disc, p.robots)
    s = sim.state
    rep.update(0, np.arange(p.robots), s.state, s.x, s.y, s.heading)
    while not sim.done:
        sim.step()
        ids = np.union1d(sim.last_joins()[0], sim.last_removed)
        rep.update(sim.tick, ids, s.state[ids], s.x[ids], s.y[ids], s.heading[ids])
        assert np.array_equal(rep.state.occupancy, s.occupancy) and np.array_equal(rep.state.frontier, s.frontier)
    gone = int(np.flatnonzero(s.state == RobotState.REMOVED)[0])
    with pytest.raises(ContractError, match="returns after removal"):
        rep.update(
            sim.tick + 1,
            np.array([gone]),
            np.array([RobotState.MOVING_OUTSIDE]),
            s.x[[gone]],
            s.y[[gone]],
            s.heading[[gone]],
        )


def test_remove_is_idempotent_and_checks_ids(disc):
    sim = Simulation(disc, RunParams(robots=disc.patches, seed=1))
    sim.run(max_ticks=10)
    assert sim.remove(np.array([7, 8])) == 2 and sim.remove(np.array([8])) == 0
    with pytest.raises(ContractError, match="robot ids must be in"):
        sim.remove(np.array([disc.patches]))


@pytest.mark.parametrize(
    "kw,message",
    [
        ({"fail_fraction": 0.1}, "fail_tick must be >= 1"),
        ({"fail_fraction": 1.5, "fail_tick": 3}, "fail_fraction must be"),
        ({"fail_fraction": -0.1, "fail_tick": 3}, "fail_fraction must be"),
    ],
)
def test_bad_failure_parameters(kw, message):
    with pytest.raises(ParameterError, match=message):
        RunParams(robots=50, **kw)


def test_fail_robots_flag_reports_the_loss(tmp_path, capsys):
    out = tmp_path / "run"
    assert (
        cli.main(
            [
                "simulate",
                "--shape",
                "rectangle",
                "--robots",
                "460",
                "--seed",
                "3",
                "--fail-robots",
                "0.1@300",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    text = capsys.readouterr().out
    assert "lost robots       46  (46 at tick 300)" in text and "outcome           incomplete" in text


@pytest.mark.parametrize("flag,taken", [("1@5", (1.0, 5)), ("0.25@7", (0.25, 7))])
def test_the_fail_robots_flag_takes_what_the_parameters_take(flag, taken):
    """--fail-robots P@T is fail_fraction and fail_tick, each checked by its declaration: a parameter file's
    fail_fraction: 1.0 (every robot fails) is a flag's 1@T too."""
    from swarm_ros.app.cli import build_parser

    args = build_parser().parse_args(["simulate", "--fail-robots", flag])
    assert args.fail_robots == taken
