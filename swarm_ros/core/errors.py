"""Errors the core raises for bad input. Each message is one line a user can act on."""


class SwarmError(ValueError):
    """Base class for every user-facing input error of swarm_ros."""


class ShapeError(SwarmError):
    """A shape file or shape name cannot be used; the message names the file."""


class ParameterError(SwarmError):
    """A model or run parameter is out of range; the message names the parameter."""
