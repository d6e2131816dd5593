"""Errors the core raises for bad input. Each message is one line a user can act on."""


class SwarmError(ValueError):
    """Base class for every user-facing input error of swarm_ros.

    Its text is always one line: characters that are not printable (a newline in a YAML
    key, say) are shown escaped, as in ``'\\n'``.
    """

    def __str__(self) -> str:
        text = super().__str__()
        if text.isprintable():
            return text
        return "".join(c if c.isprintable() else c.encode("unicode_escape").decode("ascii") for c in text)


class ShapeError(SwarmError):
    """A shape file or shape name cannot be used; the message names the file."""


class ParameterError(SwarmError):
    """A model or run parameter is out of range; the message names the parameter."""


class ConfigError(SwarmError):
    """A parameter file is unreadable or holds an unknown or ill-typed key; the message names both."""
