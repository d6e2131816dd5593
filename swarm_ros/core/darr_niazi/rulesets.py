"""Rule sets: the readings of the original study's pseudo-code that a run can choose.

The study's pseudo-code leaves three things open, and each is a switch here
(docs/model.md, "Rule sets", says why each value exists):

``join``      how a robot inside the shape finds a place to join:
              ``walk``  it targets the nearest frontier patch anywhere and walks there,
                        one patch a tick, claiming it once within one patch;
              ``local`` it claims the nearest frontier patch within its vision radius, if any.
``crowding``  what "any moving robot at vision-radius" blocks:
              ``ahead`` another moving robot on the patch at distance r straight ahead;
              ``disc``  another moving robot within r of the point one patch ahead.
``steps``     how far a wandering robot goes in a tick:
              ``one``     one wiggle and at most one step;
              ``literal`` the pseudo-code's Move calls as written: up to 3 steps outside
                          the shape, up to 2 inside (then a ``local`` join attempt).

Three named sets fix all three switches; a run names one (``rules``) and may override
single switches. Kernels take the switches as small integer codes (:meth:`RuleSet.codes`).
"""

from __future__ import annotations

from dataclasses import dataclass

from swarm_ros.core.errors import ParameterError

JOIN_VALUES = ("walk", "local")
CROWDING_VALUES = ("ahead", "disc")
STEPS_VALUES = ("one", "literal")
SWITCHES: dict[str, tuple[str, ...]] = {"join": JOIN_VALUES, "crowding": CROWDING_VALUES, "steps": STEPS_VALUES}

#: The named rule sets: name -> (join, crowding, steps). ``paper`` is the default.
RULE_SETS: dict[str, tuple[str, str, str]] = {
    "paper": ("walk", "ahead", "one"),
    "local": ("local", "ahead", "one"),
    "literal": ("local", "ahead", "literal"),
}
DEFAULT_RULES = "paper"

# Integer codes inside compiled kernels (the index of the value in its *_VALUES tuple).
JOIN_WALK, JOIN_LOCAL = 0, 1
CROWD_AHEAD, CROWD_DISC = 0, 1
STEPS_ONE, STEPS_LITERAL = 0, 1


@dataclass(frozen=True)
class RuleSet:
    """A named rule set with its three switches resolved.

    Attributes:
        name: the rule set the run named (``paper``, ``local`` or ``literal``).
        join, crowding, steps: the switch values in force (the set's own, or overrides).
    """

    name: str
    join: str
    crowding: str
    steps: str

    @staticmethod
    def resolve(
        name: str = DEFAULT_RULES, join: str | None = None, crowding: str | None = None, steps: str | None = None
    ) -> RuleSet:
        """The rule set ``name`` with any switch given (not None, not "") overriding its own value.

        Raises:
            ParameterError: an unknown rule set name or switch value (the message lists the known ones).
        """
        if not isinstance(name, str) or name not in RULE_SETS:
            raise ParameterError(f"rules must be one of {', '.join(RULE_SETS)}, got {name!r}")
        values = dict(zip(SWITCHES, RULE_SETS[name]))
        for switch, value in (("join", join), ("crowding", crowding), ("steps", steps)):
            if value is None or value == "":
                continue
            if not isinstance(value, str) or value not in SWITCHES[switch]:
                raise ParameterError(f"{switch} must be one of {', '.join(SWITCHES[switch])}, got {value!r}")
            values[switch] = value
        return RuleSet(name=name, **values)

    @property
    def overrides(self) -> dict[str, str]:
        """The switches whose value differs from the named set's own."""
        own = dict(zip(SWITCHES, RULE_SETS[self.name]))
        return {k: getattr(self, k) for k in SWITCHES if getattr(self, k) != own[k]}

    @property
    def label(self) -> str:
        """The name, plus any overrides: ``paper`` or ``local+crowding=disc``."""
        return "+".join([self.name, *(f"{k}={v}" for k, v in self.overrides.items())])

    def codes(self) -> tuple[int, int, int]:
        """(join, crowding, steps) as kernel codes."""
        return JOIN_VALUES.index(self.join), CROWDING_VALUES.index(self.crowding), STEPS_VALUES.index(self.steps)
