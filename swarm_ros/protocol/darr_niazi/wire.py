"""The study's model in a central world's graph (:mod:`swarm_ros.core.strips`): its rows and their checks (a
:class:`~swarm_ros.protocol.central_rows.Wire`), and its robot batch.

A batch decides for the moving robots of its strip of patch columns from what it is sent after each tick: the robots
of its area (its strip and :func:`~swarm_ros.core.darr_niazi.legality.halo` columns either side) and every stationary
robot (:meth:`~swarm_ros.core.darr_niazi.engine.Simulation.seen_by_all`: the ``walk`` rule finds the frontier
anywhere), whole at first and then the rows that changed. It keeps a regional view of the swarm from them (loaded
from a whole view, then updated with each tick's changes: :class:`~swarm_ros.core.darr_niazi.swarm_view.SwarmView`)
and runs the core's rule (:class:`~swarm_ros.core.darr_niazi.rules.Decider`), so it decides as the in-process engine
does. The rows are :mod:`swarm_ros.protocol.darr_niazi.rows`': a robot's pose and state, a decision's claim and pose.
"""

from __future__ import annotations

import numpy as np

from swarm_ros.core.darr_niazi.engine import Simulation
from swarm_ros.core.darr_niazi.legality import illegal
from swarm_ros.core.darr_niazi.rules import Decided, Decided3D, Decider, Decisions
from swarm_ros.core.darr_niazi.state import STATE_COUNT, Poses, Poses3D
from swarm_ros.core.darr_niazi.swarm_view import SwarmView
from swarm_ros.core.errors import ContractError, Rejected
from swarm_ros.core.strips import Strips

from .. import checks
from .rows import decision_row, decision_rows, inside_world, pose_of, robot_row, robot_rows


class StudyStrip:
    """One robot batch of the study's model: decides for the moving robots of strip ``k`` from what it sees."""

    def __init__(self, run: Simulation, strips: Strips, k: int) -> None:
        self.strips, self.k, self.grid = strips, k, run.grid
        self.view = SwarmView(run.shape, run.params.robots, strips.area(k))  # its area's moving robots, and the rest
        self.decider = Decider(run.shape, run.params)

    def decide(
        self, tick: int, seen: np.ndarray, changed: np.ndarray | None, robots: Poses | Poses3D
    ) -> tuple[np.ndarray, Decided | Decided3D]:
        """Decide ``tick`` for the moving robots of its strip from ``robots`` (every robot's arrays, of which those
        ``seen`` hold their rows after ``tick - 1``; ``changed``: those that changed in it, None for a whole view):
        their ids (ascending) and decisions.

        Raises:
            Rejected: rows its view cannot take (a robot localized on a patch that is not an empty shape patch).
        """
        ids = seen if changed is None else changed
        pose = {name: a[ids] for name, a in robots._asdict().items()}
        state = pose.pop("state")
        try:
            if changed is None:
                self.view.load(tick - 1, ids, state, **pose)
            else:
                self.view.update(tick - 1, ids, state, **pose)
        except ContractError as exc:
            raise Rejected("inconsistent rows", str(exc)) from None
        moving = self.view.moving_ids()
        own = moving[self.strips.in_strip(self.grid.columns(self.view.state.x[moving]), self.k)]
        return own, self.decider.decide(self.view.state, own, tick, moving).decided


class StudyWire:
    """The study's model's rows in a world of ``dims`` dimensions (a :class:`~swarm_ros.protocol.central_rows.Wire`)."""

    batch = StudyStrip

    def __init__(self, dims: int) -> None:
        self.row, self.decision_row = robot_row(dims), decision_row(dims)

    @staticmethod
    def rows(ids: np.ndarray, robots: Poses | Poses3D) -> np.ndarray:
        solid = robots if isinstance(robots, Poses3D) else None
        return robot_rows(
            ids,
            robots.state,
            robots.x,
            robots.y,
            robots.heading,
            solid.z if solid else None,
            solid.pitch if solid else None,
        )

    @staticmethod
    def decision_rows(ids: np.ndarray, decided: Decided | Decided3D) -> np.ndarray:
        return decision_rows(Decisions.of(-1, ids, decided))

    @staticmethod
    def robots_of(rows: np.ndarray) -> tuple[np.ndarray, Poses | Poses3D]:
        pose = pose_of(rows)
        state = rows["state"].astype(np.int8)
        robots = Poses3D(**pose, state=state) if "z" in pose else Poses(**pose, state=state)
        return rows["id"].astype(np.int64), robots

    @staticmethod
    def decisions_of(rows: np.ndarray) -> tuple[np.ndarray, Decided | Decided3D]:
        """(ids, decisions) of checked decision rows."""
        ids = rows["id"].astype(np.int64)
        return ids, Decisions(tick=-1, ids=ids, claim=rows["claim"].astype(np.int64), **pose_of(rows)).decided

    @staticmethod
    def check_rows(run: Simulation, rows: np.ndarray, tick: int) -> None:
        """Whether rows can be robots of ``run`` (or their decisions, a world shard's peer's): ids ascending within
        the run's, states in their set (claims, a patch of the world or none), poses inside the world.

        Raises:
            Rejected: by kind.
        """
        ids = rows["id"].astype(np.int64)
        checks.ids_in_range(ids, 0, run.params.robots)
        if np.any(np.diff(ids) <= 0):
            raise Rejected("bad ids", "robot ids must ascend")
        decisions = "claim" in (rows.dtype.names or ())
        if rows.size and not decisions and rows["state"].max() >= STATE_COUNT:
            raise Rejected("robot state out of range", f"state {int(rows['state'].max())}")
        cells = run.shape.world.patch_count
        if rows.size and decisions and (rows["claim"].min() < -1 or rows["claim"].max() >= cells):
            raise Rejected("claim out of range", f"a claim outside the world's {cells} patches")
        inside_world(rows, run.shape.world.radius)

    @staticmethod
    def check_decisions(
        run: Simulation, rows: np.ndarray, tick: int, own: np.ndarray
    ) -> tuple[np.ndarray, Decided | Decided3D]:
        """(ids, decisions) of decision rows for ``tick`` that must be exactly the robots ``own``, each within the
        rule's bounds from where it stands in ``run`` (:func:`~swarm_ros.core.darr_niazi.legality.illegal`).

        Raises:
            Rejected: by kind.
        """
        ids = rows["id"].astype(np.int64)
        if not np.array_equal(ids, own):
            raise Rejected("not its robots", f"{ids.size} decisions for the batch's {own.size} robots")
        inside_world(rows, run.shape.world.radius)
        s = run.state
        solid = {"z0": s.z[ids], "z": rows["z"], "pitch": rows["pitch"]} if s.z is not None else {}
        claim = rows["claim"].astype(np.int64)
        bad = illegal(run.params, run.shape.world.radius, s.frontier, s.x[ids], s.y[ids], claim, rows["x"],
                      rows["y"], rows["heading"], **solid)  # fmt: skip
        if bad.any():
            raise Rejected("illegal decision", f"robot {int(ids[np.flatnonzero(bad)[0]])}")
        return StudyWire.decisions_of(rows)
