"""The world's settlement of claims: one robot per patch, a fixed lottery, Z-spec outcomes."""

import numpy as np
import pytest
from runs import disc_shape, params

from swarm_ros.core import JoinOutcome, Outcome, RobotState, Shape, Simulation, World
from swarm_ros.core.darr_niazi.rules import Decisions
from swarm_ros.core.errors import ContractError
from swarm_ros.core.rng import STREAM_PRIORITY, draw_bits

pytestmark = pytest.mark.unit


def claims(sim: Simulation, patch_of_robot: dict[int, int]) -> Decisions:
    """Decisions for every moving robot: the given claims, everyone else stays put."""
    ids = sim.moving_ids()
    s = sim.state
    claim = np.array([patch_of_robot.get(int(i), -1) for i in ids], dtype=np.int64)
    return Decisions(
        tick=sim.tick + 1, ids=ids, claim=claim, x=s.x[ids].copy(), y=s.y[ids].copy(), heading=s.heading[ids].copy()
    )


def reorder(d: Decisions, order: np.ndarray) -> Decisions:
    return Decisions(d.tick, d.ids[order], d.claim[order], d.x[order], d.y[order], d.heading[order])


@pytest.fixture
def disc():
    return disc_shape(World(radius=10), 5.0)


@pytest.mark.parametrize("seed", [1, 2, 3, 4, 5])
def test_two_claims_on_one_patch_one_winner_by_lottery_in_any_order(disc, seed):
    patch = disc.world.flat_index(1, 0)
    winners = set()
    for order in ([0, 1, 2], [2, 1, 0], [1, 2, 0]):
        sim = Simulation(disc, params(7, seed=seed))
        d = reorder(claims(sim, {4: patch, 6: patch}), np.array(order))
        before = sim.state.copy()
        sim.apply(d)
        ids, claim, outcome = sim.last_joins()
        won = ids[outcome == JoinOutcome.SUCCESS]
        assert won.size == 1
        winners.add(int(won[0]))
        loser = 10 - int(won[0])
        assert outcome[ids == loser][0] == JoinOutcome.INCOMPLETE
        assert (sim.state.x[loser], sim.state.y[loser]) == (before.x[loser], before.y[loser])
        assert sim.state.occupancy[patch] == won[0] and sim.state.state[won[0]] == RobotState.LOCALIZED
    assert len(winners) == 1
    tickets = {i: int(draw_bits(seed, i, 1, STREAM_PRIORITY)) for i in (4, 6)}
    assert winners.pop() == min(tickets, key=tickets.get)


def test_claim_on_an_occupied_patch_is_refused(disc):
    sim = Simulation(disc, params(6, seed=1))
    sim.apply(claims(sim, {4: disc.world.flat_index(0, 0)}))  # a seed's patch
    ids, _, outcome = sim.last_joins()
    assert outcome[ids == 4][0] == JoinOutcome.INCOMPLETE
    assert sim.state.occupancy[disc.world.flat_index(0, 0)] == 3


def test_refused_claim_on_a_completed_shape_is_already_complete():
    world = World(radius=6)
    mask = np.zeros((13, 13), dtype=bool)
    mask[6:8, 6:8] = True  # the seeds' 2 x 2 block ...
    mask[6, 8] = True  # ... and one more patch to fill
    shape = Shape(name="tiny", mask=mask, world=world, source="test tiny")
    sim = Simulation(shape, params(7, seed=3))
    last = int(np.flatnonzero(sim.state.frontier & shape.mask.ravel())[0])
    ids = sim.moving_ids()
    sim.apply(claims(sim, {int(i): last for i in ids}))
    _, _, outcome = sim.last_joins()
    assert sorted(outcome.tolist()) == [JoinOutcome.SUCCESS, JoinOutcome.ALREADY_COMPLETE, JoinOutcome.ALREADY_COMPLETE]
    assert sim.outcome is Outcome.COMPLETE_WITH_EXTRAS
    assert (sim.state.state == RobotState.SEPARATED).sum() == 2


def test_apply_checks_tick_and_coverage(disc):
    sim = Simulation(disc, params(8, seed=1))
    d = claims(sim, {})
    with pytest.raises(ContractError, match="tick"):
        sim.apply(Decisions(d.tick + 1, d.ids, d.claim, d.x, d.y, d.heading))
    with pytest.raises(ContractError, match="every moving robot exactly once"):
        sim.apply(reorder(d, np.arange(d.ids.size - 1)))
