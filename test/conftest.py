"""Shared helpers: small worlds and shapes, and running a simulation with every invariant checked."""

from __future__ import annotations

import numpy as np
import pytest

from swarm_ros.core import RunParams, Shape, Simulation, World
from swarm_ros.core.invariants import check_state, check_tick

# Robot counts that complete each built-in shape in the original study (MODEL.md).
STUDY_PATCHES = {"star": 1036, "wrench": 566, "k-letter": 1352, "rectangle": 438, "tyre": 1282, "spinner": 1040}


def disc_shape(world: World, radius: float, name: str = "disc", hole: float = 0.0) -> Shape:
    """A disc (or ring, with ``hole`` > 0) centred on the origin."""
    r = world.radius
    c = np.arange(-r, r + 1)
    x, y = np.meshgrid(c, c)
    d = np.hypot(x, y)
    return Shape(name=name, mask=(d <= radius) & (d >= hole), world=world, source=f"test {name}")


def run_checked(sim: Simulation) -> Simulation:
    """Run ``sim`` to its end, checking every Z-spec invariant after every tick."""
    check_state(sim)
    while not sim.done:
        prev = sim.state.copy()
        sim.step()
        check_tick(prev, sim)
    return sim


@pytest.fixture(scope="session")
def small_world() -> World:
    return World(radius=10)


@pytest.fixture(scope="session")
def small_disc(small_world: World) -> Shape:
    return disc_shape(small_world, 5.0)


@pytest.fixture(scope="session")
def small_ring(small_world: World) -> Shape:
    return disc_shape(small_world, 6.5, name="ring", hole=3.0)


def params(robots: int, **kw) -> RunParams:
    return RunParams(robots=robots, **kw)
