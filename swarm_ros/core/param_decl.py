"""A parameter's declaration (:class:`Param`): its meaning, type, bounds or choices, and where it goes.

:mod:`swarm_ros.core.params` declares every run and node parameter with it.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from .errors import ParameterError

INT64_MAX = 2**63 - 1  #: every integer parameter fits in 64 bits: a ROS parameter's and the kernels' integers

_KIND_WORDS = {bool: "a boolean", int: "an integer", float: "a number", str: "a string"}


@dataclass(frozen=True)
class Param:
    """One parameter: its name, default (whose type is the parameter's type), meaning and bounds.

    Attributes:
        low, high: bounds of a number (None: unbounded); ``low_open``: ``low`` itself is out.
        choices: the values a string may take ("" always allowed when ``blank`` is set).
        blank: meaning of the empty string or of 0, if that is a value of its own.
        flag: the command-line flag ("" = none; None = ``--`` and the name with dashes).
        experiment: ``"axis"`` (an experiment file may list several values), ``"fixed"``
            (one value for the whole experiment), or ``""`` (not an experiment file key).
        model: whether it is a field of :class:`RunParams` (the shape and the world are not): set from the class
            that declares it (``swarm_ros.core.params``).
        recorded: whether summary.json and results.csv have it as a field or column (``mesh_scale``
            is recorded only where it applies, :func:`swarm_ros.core.metrics.run_summary`).
        algorithm: the shape-formation algorithm the parameter belongs to ("" = every one); another
            algorithm's run refuses a value other than its default.
    """

    name: str
    default: Any
    help: str
    low: float | None = None
    high: float | None = None
    low_open: bool = False
    choices: tuple[str, ...] | Callable[[], tuple[str, ...]] = ()
    blank: str = ""
    flag: str | None = None
    experiment: str = "fixed"
    model: bool = True
    recorded: bool = True
    algorithm: str = ""
    list_text: bool = False  #: a comma-separated list: one whole number (ROS 2 reads ``-p p:=5`` so) is its text

    @property
    def options(self) -> tuple[str, ...]:
        """The values a string may take (``choices``, or what it returns when asked: the algorithms registered)."""
        return self.choices() if callable(self.choices) else self.choices

    @property
    def kind(self) -> type:
        return type(self.default)

    @property
    def cli_flag(self) -> str:
        return "--" + self.name.replace("_", "-") if self.flag is None else self.flag

    def describe(self) -> str:
        """What a valid value is, in words: ``an integer >= 3``, ``one of paper, local, literal``."""
        if self.options:
            text = f"one of {', '.join(self.options)}"
        else:
            text = _KIND_WORDS[self.kind]
            if self.low is not None:
                text += f" {'>' if self.low_open else '>='} {_number(self.low)}"
            if self.high is not None:
                text += f" and <= {_number(self.high)}"
        return text + (f" ({self.blank_value!r} = {self.blank})" if self.blank else "")

    @property
    def blank_value(self) -> object:
        return self.kind()

    def check(self, value: Any) -> Any:
        """``value`` as this parameter's type, if it is one this parameter takes.

        Raises:
            ParameterError: ``<name> must be <describe()>, got <value>``, in one line.
        """
        kind = self.kind
        if self.list_text and isinstance(value, numbers.Integral) and not isinstance(value, bool):
            value = str(value)
        if kind is bool:
            ok = isinstance(value, bool)
        elif kind is str:
            ok = isinstance(value, str)
        elif kind is int:
            ok = isinstance(value, numbers.Integral) and not isinstance(value, bool)
        else:
            ok = isinstance(value, numbers.Real) and not isinstance(value, bool) and math.isfinite(value)
        if ok and not (self.blank and value == self.blank_value):
            if self.options:
                ok = value in self.options
            elif kind in (int, float):
                ok = (self.low is None or (value > self.low if self.low_open else value >= self.low)) and (
                    self.high is None or value <= self.high
                )
        if ok and kind is int and value > INT64_MAX and (self.high is None or self.high > INT64_MAX):
            raise ParameterError(
                f"{self.name} must be {self.describe()} and <= {INT64_MAX} (a 64-bit integer), got {value}"
            )
        if not ok:
            shown = (
                _number(value) if isinstance(value, float) and math.isfinite(value) and kind is float else repr(value)
            )  # an integer's 442.0 stays 442.0: the '.0' is what is wrong
            raise ParameterError(f"{self.name} must be {self.describe()}, got {shown}")
        return kind(value)


def _number(x: float) -> str:
    """``3``, ``0.5``, ``9223372036854775807``: a bound or value as a user would write it."""
    if isinstance(x, numbers.Integral):
        return str(x)
    return str(int(x)) if float(x).is_integer() else f"{x:g}"
