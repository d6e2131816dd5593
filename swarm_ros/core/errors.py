"""The errors swarm_ros raises on purpose: one family, one meaning per class.

Every class below derives from :class:`SwarmError`, and nothing in the package raises a
built-in exception for a condition it checks (``test/test_errors.py`` holds the package to
it). Who catches what:

================  ==========================================================  ==============================
class             meaning                                                     caught by
================  ==========================================================  ==============================
InputError        the user's input cannot be used (a file, a flag, a value):  the command line and each node:
                  ShapeError, ParameterError, ConfigError and the app's own   one line, exit status 2
ContractError     a call handed the core data that does not fit its state     the node that handed it: a run
                  (decisions for another tick, rows out of order): a bug, or  failure (a message the checks
                  a message the protocol checks let through                   let through is a gap in them)
Rejected          a received message that must be dropped, ``kind`` names     the node's ``Rejections``:
                  the fault                                                   counted, logged, never raised on
RunFailed         the run cannot go on (something the graph did, not input)   the node, the command line: exit 1
InvariantError    a model invariant does not hold after a tick (``--check``)  nothing: it is a bug to report
================  ==========================================================  ==============================
"""


class SwarmError(Exception):
    """Base of every error swarm_ros raises on purpose.

    Its text is always one line: characters that are not printable (a newline in a YAML
    key, say) are shown escaped, as in ``'\\n'``.
    """

    def __str__(self) -> str:
        text = super().__str__()
        if text.isprintable():
            return text
        return "".join(c if c.isprintable() else c.encode("unicode_escape").decode("ascii") for c in text)


class InputError(SwarmError):
    """The user's input cannot be used; the message names the file, flag or value and says why."""


class ShapeError(InputError):
    """A shape file or shape name cannot be used; the message names the file."""


class ParameterError(InputError):
    """A model or run parameter is out of range; the message names the parameter."""


class ConfigError(InputError):
    """A parameter file is unreadable or holds an unknown or ill-typed key; the message names both."""


class ContractError(SwarmError):
    """A call handed the core data that does not fit its state or its documented form."""


class Rejected(SwarmError):
    """A message that must be dropped: ``kind`` names the fault (a key of the counts)."""

    def __init__(self, kind: str, detail: str = "") -> None:
        super().__init__(f"{kind}: {detail}" if detail else kind)
        self.kind = kind


class RunFailed(SwarmError):
    """The run cannot go on (not bad input: something the graph did)."""


class InvariantError(SwarmError):
    """A model invariant does not hold after a tick."""
