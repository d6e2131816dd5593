"""The messages between world shards as bytes (:mod:`swarm_ros.protocol.shard_rows`): a sharded run whose every
claim and part goes through its standard message payload (PointCloud2 bytes, Int64MultiArray numbers) gives
``Simulation``'s run; a counts message that is not one is refused in one kind, never with another error."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from runs import disc_shape

from swarm_ros.core import RunParams, Shape, Simulation, World
from swarm_ros.core.errors import Rejected
from swarm_ros.core.sharded_run import run_sharded
from swarm_ros.core.shards import WorldShard
from swarm_ros.protocol import checks
from swarm_ros.protocol.cdr import decode_cloud, encode_cloud
from swarm_ros.protocol.rows import decision_row, decision_rows, decisions_of
from swarm_ros.protocol.shard_rows import assemble, counts_data, counts_of, part_row, part_rows

pytestmark = pytest.mark.unit

WORLD = World(radius=12)
DISC = disc_shape(WORLD, 7.0)


def _over_the_wire(monkeypatch, dims: int, robots: int, shards: int) -> None:
    """Make every shard's claims and parts go through their messages' bytes and numbers, and back."""
    claims, routes = WorldShard.claims, WorldShard.routes

    def wired_claims(self, decisions):
        out = []
        for c in claims(self, decisions):
            msg = decode_cloud(encode_cloud(decision_rows(c), c.tick))
            out.append(decisions_of(checks.tick_stamp(msg.header), checks.cloud(msg, decision_row(dims), robots, 0)))
        return out

    def wired_routes(self, part):
        out = []
        for q in routes(self, part):
            msg = decode_cloud(encode_cloud(part_rows(q, dims), q.tick))
            rows = checks.cloud(msg, part_row(dims), robots, 0)
            out.append(
                assemble(checks.tick_stamp(msg.header), q.source, rows, counts_of(counts_data(q), robots, shards))
            )
        return out

    monkeypatch.setattr(WorldShard, "claims", wired_claims)
    monkeypatch.setattr(WorldShard, "routes", wired_routes)


@pytest.mark.parametrize("rules", ["paper", "literal"])
def test_a_run_whose_messages_go_through_their_payloads_is_the_in_process_run(monkeypatch, rules):
    params = RunParams(robots=DISC.patches + 40, seed=3, rules=rules, fail_fraction=0.1, fail_tick=9)
    cuts = np.array([-5, 0, 6])
    _over_the_wire(monkeypatch, 2, params.robots, cuts.size + 1)
    sim = Simulation(DISC, params)
    removals = {}
    while sim.outcome is None:
        deciders = sim.moving_ids()
        sim.step()
        if sim.tick in (5, 9, 20) and deciders.size:
            removals[sim.tick] = deciders[::7]
            sim.remove(removals[sim.tick])
    run = run_sharded(DISC, params, cuts, removals=removals)
    assert np.array_equal(run.history, sim.history) and run.losses == sim.losses
    for name in ("x", "y", "heading", "state", "occupancy"):
        assert np.array_equal(getattr(run.state, name), getattr(sim.state, name)), name


def test_a_3d_run_over_the_wire(monkeypatch):
    box = Shape.load("box")
    params = RunParams(robots=box.patches + 20, seed=1, rules="literal")
    _over_the_wire(monkeypatch, 3, params.robots, 3)
    sim = Simulation(box, params)
    sim.run(max_ticks=80)
    run = run_sharded(box, params, np.array([-3, 2]), max_ticks=80)
    assert np.array_equal(run.history, sim.history)
    for name in ("x", "y", "z", "pitch", "state"):
        assert np.array_equal(getattr(run.state, name), getattr(sim.state, name)), name


def test_counts_that_are_not_a_parts_are_refused():
    good = np.array([3, 1] + [0] * 11 + [5, 9], dtype=np.int64)
    assert counts_of(good, 10, 2)[:2] == (3, 1)
    for bad in (
        good[:5],  # too short
        np.concatenate([[0], good[1:]]),  # tick 0 is nobody's part
        np.concatenate([[3, 2], good[2:]]),  # no shard 2 of 2
        np.concatenate([good[:2], [-1], good[3:]]),  # a negative count
        np.concatenate([good[:-1], [10]]),  # a robot id out of range
        np.concatenate([good[:-1], [5]]),  # a robot removed twice
    ):
        with pytest.raises(Rejected, match="malformed counts"):
            counts_of(bad, 10, 2)
    rows = np.zeros(0, dtype=part_row(2))
    with pytest.raises(Rejected, match="mismatched part"):
        assemble(4, 1, rows, counts_of(good, 10, 2))


@settings(max_examples=300, deadline=None)
@given(st.lists(st.integers(-(2**63), 2**63 - 1), max_size=40))
def test_any_numbers_as_counts_are_taken_or_refused_in_one_kind(numbers):
    try:
        tick, source, counts, removing = counts_of(np.array(numbers, dtype=np.int64), 20, 3)
    except Rejected as fault:
        assert fault.kind == "malformed counts"
        return
    assert tick >= 1 and 0 <= source < 3 and (counts >= 0).all() and ((removing >= 0) & (removing < 20)).all()
