"""What bounds a run, checked in one place for every algorithm and every entry point (a run's settings, each grid
point of an experiment, a row the report runs again): the shape the algorithm can form, the vision radius, the
robots the world holds, and the memory they need. (``RunParams`` calls it from ``Settings.resolve``: this module
does not import it back.)"""

from __future__ import annotations

from typing import Protocol

from .errors import ParameterError
from .resources import check_robot_memory
from .shapes import Shape


class Run(Protocol):
    """What of a run's parameters the bounds read (:class:`~swarm_ros.core.params.RunParams`)."""

    @property
    def robots(self) -> int: ...

    @property
    def algorithm(self) -> str: ...

    def check_shape(self, shape: Shape) -> None: ...


def check_run(shape: Shape, params: Run) -> None:
    """Refuse, in one line, a shape and parameters that cannot make a run together (every run and every grid point
    of an experiment is checked here): a shape the algorithm cannot form, a vision radius beyond the world, more
    robots than the world holds (one a free patch, under every algorithm: :meth:`Shape.check_room`), or more than
    this machine's memory holds.

    Raises:
        ParameterError: the first of these.
    """
    params.check_shape(shape)
    try:
        shape.check_room(params.robots)
    except ParameterError as exc:
        raise ParameterError(f"{shape.source}: {exc}") from None
    check_robot_memory(params.robots, params.algorithm)
