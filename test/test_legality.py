"""The world's bounds on decisions (core/darr_niazi/legality.py): every decision the rules make keeps them; wrong
ones do not."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from swarm_ros.core import Shape
from swarm_ros.core.darr_niazi.engine import Simulation
from swarm_ros.core.darr_niazi.legality import SLACK, illegal, max_step, reach
from swarm_ros.core.darr_niazi.rules import Decider, Decisions
from swarm_ros.core.params import RunParams

pytestmark = pytest.mark.unit


def _check(sim: Simulation, d: Decisions) -> np.ndarray:
    s = sim.state
    return illegal(sim.params, sim.shape.world.radius, s.frontier, s.x[d.ids], s.y[d.ids], d.claim, d.x, d.y, d.heading)


@pytest.mark.parametrize("rules,vision", [("paper", 1.0), ("local", 1.0), ("local", 3.0), ("literal", 2.0)])
def test_no_decision_the_rules_make_is_illegal(rules, vision):
    shape = Shape.load("k-letter")
    params = RunParams(robots=shape.patches + 40, vision_radius=vision, seed=11, rules=rules, max_ticks=3000)
    sim, decider = Simulation(shape, params), Decider(shape, params)
    checked = claims = 0
    while sim.outcome is None:
        moving = sim.moving_ids()
        d = decider.decide(sim.state, moving, sim.tick + 1, moving)
        bad = _check(sim, d)
        assert not bad.any(), (rules, sim.tick, d.ids[bad])
        checked += d.ids.size
        claims += int((d.claim >= 0).sum())
        sim.apply(d)
    assert checked > 10_000 and claims > shape.patches // 2  # the checks saw plenty of moves and claims


@pytest.fixture
def tick1():
    """A run's first decisions, honest: (simulation, decisions)."""
    shape = Shape.load("rectangle")
    params = RunParams(robots=shape.patches, seed=3)
    sim = Simulation(shape, params)
    moving = sim.moving_ids()
    return sim, Decider(shape, params).decide(sim.state, moving, 1, moving)


def _claim_row(sim: Simulation, d: Decisions, patch: int) -> int:
    """Make decision 0 a claim of ``patch`` from right next to it; return the row."""
    size = sim.shape.world.size
    px, py = patch % size - sim.shape.world.radius, patch // size - sim.shape.world.radius
    i = d.ids[0]
    sim.state.x[i], sim.state.y[i] = px + 1.0, float(py)
    d.x[0], d.y[0], d.claim[0] = px + 1.0, float(py), patch
    return 0


@pytest.mark.parametrize(
    "change,why",
    [
        (lambda sim, d: d.x.__setitem__(0, d.x[0] + 5.0), "a move of 5 patches"),
        (lambda sim, d: d.x.__setitem__(0, np.nan), "NaN"),
        (lambda sim, d: d.y.__setitem__(0, 1e300), "outside the world"),
        (lambda sim, d: d.heading.__setitem__(0, 7.0), "a heading over 2 pi"),
        (lambda sim, d: d.heading.__setitem__(0, -math.inf), "an infinite heading"),
        (lambda sim, d: d.claim.__setitem__(0, 10**8), "a claim outside the grid"),
        (lambda sim, d: d.claim.__setitem__(0, -7), "a claim code below -1"),
        (
            lambda sim, d: _claim_row(sim, d, int(np.flatnonzero(sim.shape.mask.ravel() & ~sim.state.frontier)[0])),
            "a claim on a shape patch off the frontier",
        ),
    ],
)
def test_a_wrong_decision_is_illegal_and_only_it(tick1, change, why):
    sim, d = tick1
    assert not _check(sim, d).any()
    change(sim, d)
    assert np.flatnonzero(_check(sim, d)).tolist() == [0], why


def test_a_frontier_claim_is_legal_within_reach_and_illegal_beyond(tick1):
    sim, d = tick1
    patch = int(np.flatnonzero(sim.state.frontier)[0])
    _claim_row(sim, d, patch)
    assert not _check(sim, d).any()
    i = d.ids[0]
    far = reach(sim.params) + 0.5
    sim.state.x[i] += far  # the robot stood too far away to claim it
    d.x[0] = sim.state.x[i]
    assert _check(sim, d)[0]


def test_the_bounds_follow_the_rule_set():
    assert max_step(RunParams(robots=10, rules="paper")) == 1.0
    assert max_step(RunParams(robots=10, rules="literal")) == 3.0
    assert reach(RunParams(robots=10, rules="local", vision_radius=4.0)) > reach(RunParams(robots=10, rules="paper"))


# The bounds as numpy statements (the implementation before it was compiled): the reference the kernel must equal.
def _reference(params, radius, frontier, x0, y0, claim, x, y, heading, z0=None, z=None, pitch=None) -> np.ndarray:
    """``illegal``'s mask, one numpy statement per bound (arguments as ``illegal``'s)."""
    size = 2 * radius + 1
    limit = radius + 0.5
    step = max_step(params) + SLACK
    solid = z0 is not None
    before = [x0, y0, z0] if solid else [x0, y0]
    after = [x, y, z] if solid else [x, y]
    bad = ~(np.isfinite(x) & np.isfinite(y) & (heading >= 0) & (heading <= 2 * math.pi))
    if solid:
        bad |= ~(np.isfinite(z) & (np.abs(np.nan_to_num(pitch, nan=np.inf)) <= math.pi / 2))
    for a in after:
        bad |= np.abs(np.nan_to_num(a, nan=np.inf)) > limit
    with np.errstate(invalid="ignore", over="ignore"):
        bad |= ~(np.sqrt(sum((a - b) ** 2 for a, b in zip(after, before))) <= step)
    claims = claim >= 0
    bad |= (claim < -1) | (claim >= size ** len(before))
    ok_claim = claims & ~bad
    p = claim[ok_claim]
    cells = (
        [p % size - radius, (p // size) % size - radius, p // (size * size) - radius]
        if solid
        else [p % size - radius, p // size - radius]
    )
    far = np.sqrt(sum((c - b[ok_claim]) ** 2 for c, b in zip(cells, before))) > reach(params, len(before)) + SLACK
    bad[np.flatnonzero(ok_claim)[far | ~frontier[p]]] = True
    return bad


@settings(max_examples=300, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), solid=st.booleans(), rules=st.sampled_from(["paper", "local", "literal"]))
def test_the_compiled_check_equals_the_bounds_stated_in_numpy(seed, solid, rules):
    rng = np.random.default_rng(seed)
    radius = int(rng.integers(3, 12))
    size, n = 2 * radius + 1, int(rng.integers(0, 30))
    params = RunParams(robots=100, rules=rules, vision_radius=float(rng.choice([1.0, 2.0, 3.5])))
    frontier = rng.random(size ** (3 if solid else 2)) < 0.3
    x0, y0 = rng.uniform(-radius, radius, n), rng.uniform(-radius, radius, n)
    x, y = x0 + rng.normal(0, 1.5, n), y0 + rng.normal(0, 1.5, n)
    x[rng.random(n) < 0.1] = rng.choice([np.nan, np.inf, -np.inf, radius + 3.0])
    heading = rng.uniform(-0.5, 7, n)
    heading[rng.random(n) < 0.05] = np.nan
    claim = np.where(rng.random(n) < 0.5, -1, rng.integers(-3, size ** (3 if solid else 2) + 3, n)).astype(np.int64)
    extra = {}
    if solid:
        z0 = rng.uniform(-radius, radius, n)
        pitch = rng.uniform(-2, 2, n)
        pitch[rng.random(n) < 0.05] = np.nan
        extra = {"z0": z0, "z": z0 + rng.normal(0, 1.5, n), "pitch": pitch}
    assert np.array_equal(
        illegal(params, radius, frontier, x0, y0, claim, x, y, heading, **extra),
        _reference(params, radius, frontier, x0, y0, claim, x, y, heading, **extra),
    )
