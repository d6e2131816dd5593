"""Load the compiled kernels of the distributed engine's code path before a run needs them.

numba keeps compiled kernels in an on-disk cache, but loading them costs time on the
first call in each process: about 0.3 s for the first kernel (numba sets up its typing
machinery) and milliseconds for each further one. A ROS node that paid this on its
first tick would hold up the lockstep for every other node. Each node therefore calls
:func:`warm_up` once it has announced itself, so the loading overlaps the discovery of
its peers instead.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from swarm_ros.core.darr_niazi.engine import Simulation
from swarm_ros.core.darr_niazi.legality import illegal
from swarm_ros.core.darr_niazi.metrics import tick_metrics
from swarm_ros.core.darr_niazi.rules import Decider
from swarm_ros.core.darr_niazi.state import STATE_COUNT
from swarm_ros.core.darr_niazi.swarm_view import SwarmView
from swarm_ros.core.params import RunParams
from swarm_ros.core.shapes import Shape

#: robots of the throw-away run: the kernels' types do not depend on the swarm's size, and placing 50,000
#: robots took a monitor 1.4 s of its start-up
WARM_ROBOTS = 1000


def warm_up(shape: Shape, params: RunParams, ticks: int = 2) -> None:
    """Run ``ticks`` ticks of the graph's code path in this process and throw the result away:
    a robot batch's decisions, the world's check of them and :meth:`Simulation.apply`, a view's rows
    and the monitor's metrics, with at most :data:`WARM_ROBOTS` of the run's robots. Nothing is shared with the
    caller's own objects."""
    params = replace(params, robots=min(params.robots, WARM_ROBOTS))
    sim = Simulation(shape, params)
    decider = Decider(shape, params)
    view = SwarmView(shape, params.robots)
    s = sim.state
    everyone = np.arange(s.robots)
    view.load(0, everyone, s.state, s.x, s.y, s.heading, s.z, s.pitch)
    for _ in range(ticks):
        if sim.done:
            break
        moving = sim.moving_ids()
        d = decider.decide(sim.state, moving, sim.tick + 1, moving)
        before = {"z0": s.z[d.ids], "z": d.z, "pitch": d.pitch} if s.z is not None else {}
        illegal(
            params, shape.world.radius, s.frontier, s.x[d.ids], s.y[d.ids], d.claim, d.x, d.y, d.heading, **before
        )  # the world's check of a batch's decisions
        sim.apply(d)
        changed = sim.last_joins()[0]  # the deciders: the rows the world would publish
        solid = (s.z[changed], s.pitch[changed]) if s.z is not None and s.pitch is not None else (None, None)
        view.update(sim.tick, changed, s.state[changed], s.x[changed], s.y[changed], s.heading[changed], *solid)
        tick_metrics(sim.tick, np.bincount(view.state.state, minlength=STATE_COUNT), shape.patches)


def compile_kernels() -> None:
    """The study's model's kernels into numba's cache (core.kernels): two ticks of the graph's code path and a few
    of the in-process engine's, on the star and on the 3D k-block (the 3D kernels are compiled apart), with the
    default parameters (the kernels' types do not depend on them)."""
    from swarm_ros.core.grid import World

    for shape_name in ("star", "k-block"):
        shape = Shape.load(shape_name, World())
        params = RunParams(robots=shape.patches)
        warm_up(shape, params)
        Simulation(shape, params).run(max_ticks=5)
