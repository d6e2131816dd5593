"""Run parameters, validated on construction."""

from __future__ import annotations

import math
import numbers
from dataclasses import asdict, dataclass

from swarm_ros.core.errors import ParameterError
from swarm_ros.core.rulesets import DEFAULT_RULES, RuleSet

DEFAULT_SEED = 1
DEFAULT_VISION = 1.0
DEFAULT_WIGGLE_DEG = 45.0
DEFAULT_MAX_TICKS = 100_000
MAX_SEED = 2**63 - 1


@dataclass(frozen=True)
class RunParams:
    """Everything that, with the shape, fixes a run.

    Attributes:
        robots: N, all robots including the four seeds.
        vision_radius: patches; how far a robot sees join targets and other robots.
        seed: run seed, 0 <= seed < 2**63.
        max_ticks: tick limit; a run still going then ends with outcome ``timeout``.
        wiggle_deg: a wandering robot turns by a uniform angle in [-wiggle, +wiggle] degrees per tick.
        fail_fraction: the fraction of the robots that fail at the end of tick ``fail_tick``
            and are removed (0 = none): damage for studying self-repair.
        fail_tick: the tick at whose end they fail (>= 1 when ``fail_fraction`` > 0).
        rules: the named rule set (:mod:`swarm_ros.core.rulesets`): ``paper``, ``local`` or ``literal``.
        join, crowding, steps: the switches in force. Given as "" (the default), each takes
            the rule set's own value; given a value, it overrides it. After construction
            they always hold the resolved values.
    """

    robots: int
    vision_radius: float = DEFAULT_VISION
    seed: int = DEFAULT_SEED
    max_ticks: int = DEFAULT_MAX_TICKS
    wiggle_deg: float = DEFAULT_WIGGLE_DEG
    fail_fraction: float = 0.0
    fail_tick: int = 0
    rules: str = DEFAULT_RULES
    join: str = ""
    crowding: str = ""
    steps: str = ""

    def __post_init__(self) -> None:
        ruleset = RuleSet.resolve(self.rules, self.join, self.crowding, self.steps)
        for name in ("join", "crowding", "steps"):
            object.__setattr__(self, name, getattr(ruleset, name))
        for name, low, high in (("robots", 4, None), ("seed", 0, MAX_SEED), ("max_ticks", 1, None),
                                ("fail_tick", 0, None)):
            object.__setattr__(self, name, _int(name, getattr(self, name), low, high))
        # below one patch a robot sees not even its neighbours' patches (check_vision bounds it by the world)
        object.__setattr__(self, "vision_radius", _real("vision_radius", self.vision_radius, 1.0, 100.0, True))
        object.__setattr__(self, "wiggle_deg", _real("wiggle_deg", self.wiggle_deg, 0.0, 180.0, True))
        object.__setattr__(self, "fail_fraction", _real("fail_fraction", self.fail_fraction, 0.0, 1.0, True))
        if self.fail_fraction > 0 and self.fail_tick < 1:
            raise ParameterError(f"fail_tick must be >= 1 when fail_fraction > 0, got {self.fail_tick}")
        if self.fail_fraction > 0 and self.fail_tick >= self.max_ticks:
            raise ParameterError(f"fail_tick must be before max_ticks ({self.max_ticks}) when fail_fraction > 0, "
                                 f"got {self.fail_tick}: no robot would fail")

    def check_vision(self, world_radius: int) -> None:
        """Refuse a vision radius beyond the world's radius: a robot would see across the whole world.

        Raises:
            ParameterError: ``vision_radius > world_radius``.
        """
        if self.vision_radius > world_radius:
            raise ParameterError(f"vision_radius must be <= the world radius {world_radius} (a robot would see "
                                 f"across the whole world), got {self.vision_radius:g}")

    @property
    def failures(self) -> int:
        """How many robots fail at ``fail_tick``: ``round(fail_fraction * robots)``."""
        return round(self.fail_fraction * self.robots)

    @property
    def ruleset(self) -> RuleSet:
        """The rule set in force, switches resolved."""
        return RuleSet(self.rules, self.join, self.crowding, self.steps)

    @property
    def wiggle_rad(self) -> float:
        return math.radians(self.wiggle_deg)

    def as_dict(self) -> dict:
        return asdict(self)


def _int(name: str, value: object, low: int, high: int | None) -> int:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise ParameterError(f"{name} must be an integer, got {value!r}")
    if value < low or (high is not None and value > high):
        bound = f">= {low}" if high is None else f"in [{low}, {high}]"
        raise ParameterError(f"{name} must be {bound}, got {value}")
    return int(value)


def _real(name: str, value: object, low: float, high: float, inclusive_low: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(value):
        raise ParameterError(f"{name} must be a finite number, got {value!r}")
    too_low = value < low if inclusive_low else value <= low
    if too_low or value > high:
        op = ">=" if inclusive_low else ">"
        raise ParameterError(f"{name} must be {op} {low:g} and <= {high:g}, got {value:g}")
    return float(value)
