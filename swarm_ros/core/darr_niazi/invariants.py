"""Checks of the original study's Z-schema invariants (docs/model.md, "Formal specification"),
and of the rule set's moves.

:func:`check_tick` compares the state before and after one tick of a
:class:`~swarm_ros.core.darr_niazi.engine.Simulation` and raises :class:`InvariantError` naming
the first broken rule. Besides the Z schemas it checks each robot's move against its
rule set, with plain numpy re-statements of the rules (the nearest frontier patch by
brute force, not the engine's block search). It costs O(N + W^2 + walkers x frontier)
per tick: for tests and for ``swarm-ros simulate --check``, not for production runs.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from swarm_ros.core.darr_niazi.arbitration import JoinOutcome
from swarm_ros.core.darr_niazi.engine import Simulation
from swarm_ros.core.darr_niazi.metrics import tick_metrics
from swarm_ros.core.darr_niazi.state import MOVING_STATES, RobotState, SwarmState, frontier_blocks_of, frontier_of
from swarm_ros.core.errors import InvariantError
from swarm_ros.core.metrics import Outcome

_STATIONARY = (RobotState.SEED, RobotState.LOCALIZED)
_MOVING = MOVING_STATES
_EPS = 1e-9


def _table(*states: RobotState) -> np.ndarray:
    """Which state codes are one of ``states``: indexed by a state array whose codes were checked in range
    (:func:`check_state` checks them first), it is ``np.isin`` at a tenth of its cost per tick."""
    table = np.zeros(len(RobotState), dtype=bool)
    table[[int(k) for k in states]] = True
    return table


_IS_STATIONARY, _IS_MOVING = _table(*_STATIONARY), _table(*_MOVING)
_IS_WANDERING = _table(RobotState.MOVING_INSIDE, RobotState.MOVING_OUTSIDE)
# state codes as ints: an enum member's lookup costs more than the comparison it feeds, 40 times a tick
_MOVING_INSIDE = int(RobotState.MOVING_INSIDE)
_REMOVED = int(RobotState.REMOVED)
_SEED = int(RobotState.SEED)
_SEPARATED = int(RobotState.SEPARATED)
_WALKING = int(RobotState.WALKING)


def _require(ok: bool, tick: int, rule: str) -> None:
    if not ok:
        raise InvariantError(f"tick {tick}: {rule}")


def coords(s: SwarmState) -> list[np.ndarray]:
    """The robots' positions, one array per axis: [x, y], or [x, y, z] in 3D."""
    return [s.x, s.y] if s.z is None else [s.x, s.y, s.z]


def _present(*arrays: np.ndarray | None) -> list[np.ndarray]:
    """The arrays that are there: a 2D world's z and pitch (None) drop out."""
    return [a for a in arrays if a is not None]


def _distance(a: list[np.ndarray], b: Sequence[np.ndarray]) -> np.ndarray:
    return np.sqrt(sum((u - v) ** 2 for u, v in zip(a, b)))


def shape_status(localized_on_shape: int, shape_patches: int) -> int:
    """0 empty, 1 partial, 2 complete."""
    return 0 if localized_on_shape == 0 else (2 if localized_on_shape == shape_patches else 1)


def check_state(sim: Simulation) -> None:
    """Invariants of a single state: partition, occupancy, counts, metrics, frontier."""
    s, shape, t = sim.state, sim.shape, sim.state.tick
    world = shape.world
    n, patches = s.robots, shape.patches
    _require(bool(np.all((s.state >= 0) & (s.state < len(RobotState)))), t, "unknown robot state code")
    localized = _IS_STATIONARY[s.state]
    seeds = s.state[:4]
    _require(
        bool(np.all((seeds == _SEED) | (seeds == _REMOVED)))
        and int(np.sum(s.state == _SEED)) == int(np.sum(seeds == _SEED)),
        t,
        "robots 0-3, and only they, are seeds (or removed)",
    )
    # at most one localized robot per patch, only on shape patches
    position = coords(s)
    cells = [np.floor(c + 0.5).astype(np.int64) for c in position]
    _require(bool(np.all(np.max(np.abs(cells), axis=0) < world.radius)), t, "a robot is on a wall")
    flat = np.asarray(world.flat_of(*cells))
    loc_ids = np.flatnonzero(localized)
    _require(np.unique(flat[loc_ids]).size == loc_ids.size, t, "two localized robots on one patch")
    _require(bool(np.all(shape.mask.ravel()[flat[loc_ids]])), t, "a localized robot is off the shape")
    occupied = np.flatnonzero(s.occupancy >= 0)
    _require(occupied.size == loc_ids.size, t, "occupancy count differs from localized robots")
    _require(bool(np.array_equal(s.occupancy[flat[loc_ids]], loc_ids)), t, "occupancy names the wrong robot")
    _require(
        all(bool(np.all(c[loc_ids] == p[loc_ids])) for c, p in zip(position, cells)),
        t,
        "a localized robot is off its patch centre",
    )
    alive = n - int(np.sum(s.state == _REMOVED))
    _require(alive == n - sim.removed, t, "removed robots miscounted")
    _require(loc_ids.size <= min(alive, patches), t, "#localized > min(N, shape patches)")
    _require(bool(np.array_equal(s.frontier, frontier_of(shape, s.occupancy))), t, "frontier out of date")
    _require(
        bool(np.array_equal(s.frontier_blocks, frontier_blocks_of(s.frontier, world.size, world.dims))),
        t,
        "frontier block counts out of date",
    )
    _require(
        sim.params.join == "walk" or not np.any(s.state == _WALKING),
        t,
        "a robot walks, yet the rule set's join is not 'walk'",
    )
    counts = s.counts()
    _require(sim.metrics == tick_metrics(t, counts, patches), t, f"metrics {sim.metrics} do not match the state")
    wandering = _IS_WANDERING[s.state]
    inside_ok = shape.mask.ravel()[flat] == (s.state == _MOVING_INSIDE)
    _require(bool(np.all(inside_ok | ~wandering)), t, "moving inside/outside mislabelled")
    if sim.outcome is Outcome.COMPLETE_WITH_EXTRAS:
        _require(bool(np.all(localized | (s.state == _SEPARATED))), t, "extras not separated")
    _require(
        not np.any(s.state == _SEPARATED) or sim.outcome is Outcome.COMPLETE_WITH_EXTRAS,
        t,
        "separated robots before the shape completed",
    )
    if sim.outcome is Outcome.COMPLETE:
        _require(alive == patches == loc_ids.size, t, "complete, yet robots or patches left over")
    if sim.outcome is Outcome.INCOMPLETE:
        _require(not np.any(_IS_MOVING[s.state]) and loc_ids.size < patches, t, "incomplete, yet robots moving")


def check_tick(prev: SwarmState, sim: Simulation) -> None:
    """Invariants across one tick: ``prev`` is a copy of the state before ``sim``'s last tick."""
    s, shape, t = sim.state, sim.shape, sim.state.tick
    check_state(sim)
    _require(t == prev.tick + 1, t, "tick did not advance by one")
    # Robots removed at the end of this tick (failures) are the one exception to "localized stays
    # localized" and "the shape state never goes back": the rules below are checked without them.
    removed = np.zeros(s.robots, dtype=bool)
    removed[sim.last_removed] = True
    _require(bool(np.all(s.state[removed] == _REMOVED)), t, "a removed robot is still in the world")
    _require(bool(np.all(prev.state[removed] != _REMOVED)), t, "a robot was removed twice")
    _require(
        bool(np.all((s.state == _REMOVED) == (removed | (prev.state == _REMOVED)))),
        t,
        "a robot left the world without a failure",
    )
    _require(bool(np.all((prev.state >= 0) & (prev.state < len(RobotState)))), t, "unknown robot state code before")
    was_loc = _IS_STATIONARY[prev.state] & ~removed
    now_loc = _IS_STATIONARY[s.state]
    _require(bool(np.all(now_loc[was_loc])), t, "a localized robot became unlocalized")
    _require(
        all(bool(np.all(a[was_loc] == b[was_loc])) for a, b in zip(coords(s), coords(prev))),
        t,
        "a localized robot moved",
    )
    before, after = int(was_loc.sum()), int(now_loc.sum())
    if not removed.any():
        _require(
            shape_status(after, shape.patches) >= shape_status(before, shape.patches), t, "shape state went backwards"
        )
    # joins: success only for an unlocalized robot while #localized < patches, on a frontier patch
    ids, claim, outcome = sim.last_joins()
    _require(bool(np.all(_IS_MOVING[prev.state[ids]])), t, "a non-moving robot decided")
    valid = {int(o) for o in JoinOutcome}
    _require(
        set(np.unique(outcome).tolist()) <= valid, t, "join outcome outside {success, already complete, incomplete}"
    )
    won = outcome == JoinOutcome.SUCCESS
    kept = won & ~removed[ids]  # a robot may join and then fail at the end of the same tick
    _require(int(kept.sum()) == after - before, t, "successful joins differ from new localized robots")
    _require(before + int(won.sum()) <= shape.patches, t, "a join succeeded on a complete shape")
    _require(bool(np.all(prev.frontier[claim[won]])), t, "a join succeeded off the frontier")
    _require(bool(np.all(s.occupancy[claim[kept]] == ids[kept])), t, "a winner is not on its patch")
    tried = claim >= 0
    _require(bool(np.all((outcome == JoinOutcome.NO_CLAIM) == ~tried)), t, "claim and outcome disagree")
    refused = tried & ~won
    expected = JoinOutcome.ALREADY_COMPLETE if after == shape.patches else JoinOutcome.INCOMPLETE
    _require(bool(np.all(outcome[refused] == expected)), t, "wrong outcome for a refused join")
    _check_moves(prev, sim, removed)


def nearest_frontier_patch(frontier: np.ndarray, x: float, y: float, world, z: float = 0.0) -> int:
    """The nearest frontier patch to (x, y) (3D: (x, y, z)) by brute force (ties to the lowest flat index), or -1."""
    cells = np.flatnonzero(frontier)
    if cells.size == 0:
        return -1
    d2 = sum((c - v) * (c - v) for c, v in zip(world.patch_coords(cells), (x, y, z)))
    return int(cells[np.lexsort((cells, d2))[0]])


def _check_moves(prev: SwarmState, sim: Simulation, removed: np.ndarray) -> None:
    """Each decider's move against its rule set: claims within reach, walkers towards the nearest
    frontier patch, wanderers' step lengths, and the state the world gave it."""
    s, shape, t, p = sim.state, sim.shape, sim.state.tick, sim.params
    world = shape.world
    d = sim.last_decisions()
    _, _, outcome = sim.last_joins()
    ids = d.ids
    won = outcome == JoinOutcome.SUCCESS
    keep = ~removed[ids]
    # a robot that did not win takes exactly the pose it decided
    lost = ~won & keep
    solid = world.dims == 3
    pose_now = _present(s.x, s.y, s.heading, s.z, s.pitch)
    pose_decided = _present(d.x, d.y, d.heading, d.z, d.pitch)
    _require(
        all(bool(np.all(a[ids[lost]] == b[lost])) for a, b in zip(pose_now, pose_decided)),
        t,
        "a robot is not at the pose it decided",
    )
    before = [c[ids] for c in coords(prev)]
    decided = _present(d.x, d.y, d.z)
    was_inside = shape.mask.ravel()[world.flat_of(*(np.floor(c + 0.5).astype(np.int64) for c in before))]
    prev_state = prev.state[ids]
    step = _distance(decided, before)
    tried = d.claim >= 0
    reach = _distance(decided, world.patch_coords(np.where(tried, d.claim, 0)))
    walk = p.join == "walk" and bool(prev.frontier.any())
    walkers = ((prev_state == _WALKING) | was_inside) if walk else np.zeros(ids.size, dtype=bool)
    for k in np.flatnonzero(walkers):
        here = [float(c[k]) for c in before]
        target = nearest_frontier_patch(prev.frontier, here[0], here[1], world, here[2] if solid else 0.0)
        delta = [float(c) - h for c, h in zip(world.patch_coords(target), here)]
        d2 = 0.0
        for v in delta:  # "within 1 patch" is d2 <= 1 with d2 computed so, as the rule states it
            d2 += v * v
        if tried[k]:
            _require(
                int(d.claim[k]) == target and d2 <= 1.0 and step[k] == 0.0,
                t,
                f"robot {ids[k]} claimed other than the nearest frontier patch within 1 patch",
            )
        else:
            toward = math.sqrt(sum((float(c) - float(e[k])) ** 2 for c, e in zip(world.patch_coords(target), decided)))
            _require(
                d2 > 1.0 and abs(step[k] - 1.0) < _EPS and abs(toward - (math.sqrt(d2) - 1.0)) < _EPS,
                t,
                f"robot {ids[k]} did not step 1 patch towards the nearest frontier patch",
            )
    wander = ~walkers
    if p.steps == "one":
        _require(
            bool(np.all((step[wander & ~tried] < 1e-12) | (np.abs(step[wander & ~tried] - 1.0) < _EPS))),
            t,
            "a wandering robot moved other than one patch",
        )
        _require(bool(np.all(step[wander & tried] == 0.0)), t, "a claiming robot moved")
        _require(bool(np.all(reach[wander & tried] <= p.vision_radius + _EPS)), t, "a claim beyond the vision radius")
        _require(bool(np.all(was_inside[wander & tried])), t, "a robot outside the shape claimed")
    else:
        limit = np.where(was_inside, 2.0, 3.0)
        _require(
            bool(np.all(step[wander] <= limit[wander] + _EPS)),
            t,
            "a robot moved more than 3 patches outside or 2 inside the shape",
        )
        _require(bool(np.all(reach[wander & tried] <= p.vision_radius + _EPS)), t, "a claim beyond the vision radius")
        _require(bool(np.all(was_inside[wander & tried])), t, "a robot outside the shape claimed")
    # the state the world gave each robot that did not win (unless the end separated it)
    after = s.state[ids]
    should_walk = walkers & (~tried | (prev_state == _WALKING))
    open_ = lost & (after != _SEPARATED)
    _require(
        bool(np.all((after[open_] == _WALKING) == should_walk[open_])),
        t,
        "a robot walks against the rule set, or stopped walking",
    )


def checked_step(sim: Simulation) -> None:
    """One tick of ``sim``, every invariant checked over it (``simulate --check``); the state at tick 0 first.

    Raises:
        InvariantError: the first invariant that does not hold.
    """
    if sim.tick == 0:
        check_state(sim)
    prev = sim.state.copy()
    sim.step()
    check_tick(prev, sim)
