"""What every algorithm's run reports alike: how it ended (:class:`Outcome`, and its integer codes inside compiled
code), the engine that ran it, and the ticks at which a shape was half and 90% filled (:func:`fill_ticks`). An
algorithm's own measures live with it (the study's model's: :mod:`swarm_ros.core.darr_niazi.metrics`)."""

from __future__ import annotations

from enum import Enum

INPROCESS, ROS2 = "inprocess", "ros2"
ENGINES = (INPROCESS, ROS2)  #: the engines, as summary.json and results.csv name them


class Outcome(str, Enum):
    """How a run ended (docs/model.md, "Termination")."""

    COMPLETE = "complete"  #: every shape patch localized, no robot left over
    COMPLETE_WITH_EXTRAS = "complete_with_extras"  #: shape complete; left-over robots separated
    INCOMPLETE = "incomplete"  #: no robot moving, shape patches still empty
    TIMEOUT = "timeout"  #: the tick limit was reached first
    INTERRUPTED = "interrupted"  #: stopped from outside (Ctrl-C, SIGTERM) before any of the above

    def __str__(self) -> str:
        return self.value


# Integer codes of the outcomes inside compiled code; 0 = the run goes on.
RUNNING, END_COMPLETE, END_EXTRAS, END_INCOMPLETE, END_TIMEOUT = range(5)
OUTCOME_OF_CODE: dict[int, Outcome | None] = {
    RUNNING: None,
    END_COMPLETE: Outcome.COMPLETE,
    END_EXTRAS: Outcome.COMPLETE_WITH_EXTRAS,
    END_INCOMPLETE: Outcome.INCOMPLETE,
    END_TIMEOUT: Outcome.TIMEOUT,
}


def fill_ticks(ticks, filled, total: int) -> tuple[int | None, int | None]:
    """The first of ``ticks`` at whose end ``filled`` (the same length: patches localized, pixels covered) reached
    half and 90% of ``total``, or None: the times both algorithms are compared on."""
    import numpy as np  # (a reader of outcomes alone needs no numpy)

    ticks, filled = np.asarray(ticks), np.asarray(filled)
    out = []
    for share in (0.5, 0.9):
        hit = np.flatnonzero(filled >= share * total)
        out.append(int(ticks[hit[0]]) if hit.size else None)
    return out[0], out[1]
