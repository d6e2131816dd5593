"""Checks of what every tick of a rubenstein run must keep (``swarm-ros simulate --algorithm rubenstein --check``).

:func:`check_tick` compares the robots before and after one tick of a :class:`~.run.RubensteinRun` and raises
:class:`~swarm_ros.core.errors.InvariantError` naming the first broken rule:

* **no overlap**: no two robots' centres are closer than one diameter (the world's settlement grants only such
  steps; the start pack touches, so the bound holds to within rounding);
* **steps**: a robot that was stationary at the last tick (``start``, ``wait_to_move``, joined) is where it was; a
  moving one went at most ``step_length``;
* **joined robots are fixed**: a joined robot stays joined, with its gradient and its estimate frozen;
* **states**: every code is one of the five, and no robot goes back to ``start``;
* **the count**: the tick's metrics row counts the joined robots there are, and covered pixels never uncover.

It costs O(N log N) a tick (a k-d tree for the overlap): for tests and for ``--check``, not for production runs.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from swarm_ros.core.errors import InvariantError

from .rule import JOINED, MOVE_INSIDE, MOVE_OUTSIDE, START, STATE_NAMES, Robots
from .run import RubensteinRun

_EPS = 1e-9


def snapshot(run: RubensteinRun) -> Robots:
    """A copy of the run's robots, to compare with after a tick."""
    return Robots(*(a.copy() for a in run.robots))


def _require(ok: bool, tick: int, rule: str) -> None:
    if not ok:
        raise InvariantError(f"tick {tick}: {rule}")


def check_tick(prev: Robots, covered: float, run: RubensteinRun) -> None:
    """Check the tick that took the robots from ``prev`` (with ``covered`` pixels) to ``run``'s now.

    Raises:
        InvariantError: the first rule broken, naming the tick and a robot.
    """
    now, tick = run.robots, run.tick
    state = now.state.astype(np.int64)
    bad = np.flatnonzero((state < START) | (state > JOINED))
    _require(bad.size == 0, tick, f"robot {bad[:1].tolist()} has a state code outside {STATE_NAMES}")
    back = np.flatnonzero((state == START) & (prev.state != START))
    _require(back.size == 0, tick, f"robot {back[:1].tolist()} went back to start")

    was_joined = prev.state == JOINED
    left = np.flatnonzero(was_joined & (state != JOINED))
    _require(left.size == 0, tick, f"joined robot {left[:1].tolist()} left the shape")
    for name in ("x", "y", "g", "ex", "ey"):
        moved = np.flatnonzero(was_joined & (getattr(now, name) != getattr(prev, name)))
        _require(moved.size == 0, tick, f"joined robot {moved[:1].tolist()} changed its {name}")

    step = np.hypot(now.x - prev.x, now.y - prev.y)
    was_moving = (prev.state == MOVE_OUTSIDE) | (prev.state == MOVE_INSIDE)
    still = np.flatnonzero(~was_moving & (step > 0.0))
    _require(still.size == 0, tick, f"stationary robot {still[:1].tolist()} moved")
    far = np.flatnonzero(step > run.params.step_length + _EPS)
    _require(far.size == 0, tick, f"robot {far[:1].tolist()} stepped {step[far[:1]].tolist()} d, more than a step")

    pairs = cKDTree(np.column_stack([now.x, now.y])).query_pairs(1.0 - _EPS, output_type="ndarray")
    _require(pairs.size == 0, tick, f"robots {pairs[:1].tolist()} overlap")

    row = run.metrics
    _require(int(row["tick"]) == tick, tick, f"the metrics row is of tick {int(row['tick'])}")
    joined = int(np.count_nonzero(state == JOINED))
    _require(int(row["joined"]) == joined, tick, f"the metrics count {int(row['joined'])} joined, not {joined}")
    _require(row["covered"] >= covered, tick, "a covered pixel was uncovered")


def checked_step(run: RubensteinRun) -> None:
    """One tick of ``run``, what every tick must keep checked over it (``simulate --check``).

    Raises:
        InvariantError: the first rule broken.
    """
    prev, covered = snapshot(run), run.metrics["covered"]
    run.step()
    check_tick(prev, covered, run)
