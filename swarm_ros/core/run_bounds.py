"""What bounds a run, checked in one place for every algorithm and every entry point (a run's settings, each grid
point of an experiment, a row the report runs again): the shape the algorithm can form, the vision radius, the
robots the world holds, and the memory they need; and the parameters a run's algorithm takes."""

from __future__ import annotations

from .errors import ParameterError
from .params import RUBENSTEIN, RUN_PARAMETER, RunParams
from .resources import check_robot_memory
from .shapes import Shape


def check_run(shape: Shape, params: RunParams) -> None:
    """Refuse, in one line, a shape and parameters that cannot make a run together (every run and every grid point
    of an experiment is checked here): a shape the algorithm cannot form, a vision radius beyond the world, more
    robots than the world holds (one a free patch, under every algorithm: :meth:`Shape.check_room`), or more than
    this machine's memory holds.

    Raises:
        ParameterError: the first of these.
    """
    if params.algorithm == RUBENSTEIN:
        from .rubenstein.layout import check_shape

        check_shape(shape)
    else:
        params.check_vision(shape.world.radius)
    try:
        shape.check_room(params.robots)
    except ParameterError as exc:
        raise ParameterError(f"{shape.source}: {exc}") from None
    check_robot_memory(params.robots, params.algorithm)


def check_given(given: dict[str, object], algorithm: str, where: str = "") -> None:
    """Refuse a run parameter of the other algorithm that was given (a flag, a launch argument), even at its default
    value: it would do nothing. (A parameter file may hold the other algorithm's at their defaults, so that one file
    holds them all; RunParams refuses another value.)

    Raises:
        ParameterError: the first such parameter, ``where`` (if any) before it.
    """
    for name, value in given.items():
        p = RUN_PARAMETER[name]
        if value is not None and p.algorithm not in ("", algorithm):
            said = f"{where}: " if where else ""
            raise ParameterError(
                f"{said}{name} is a parameter of the {p.algorithm} algorithm, not of {algorithm}, got {value!r}"
            )
