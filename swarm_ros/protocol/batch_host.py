"""What an algorithm's robot batch does between the messages it takes and the decisions it sends: its host.

The robot-batch node (:mod:`swarm_ros.nodes.robot_batch`) is one class for every algorithm. It makes the
endpoints, announces the batch's strip on /swarm/batches, keeps its liveliness, drops and counts what fails a
check, stops once /swarm/status reports the run's outcome and its last decisions are acknowledged. What the batch
hears and how it decides is the algorithm's: its registry entry's ``batch_host`` hook, a class called with
``(shape, params, own, drop)`` that gives a :class:`BatchHost`. ``own`` holds the robot_batch node's parameters
(``batch``, ``batches``, ``region_cuts``, ``incarnation``) and the node's ``name``; ``drop(topic, fault)`` drops
and counts a message that fails a check the host makes after its inbox took it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from swarm_ros.protocol.cdr import Cloud

#: a host's reply to a message: the rows to publish on the batch's decisions topic and the tick they decide; None:
#: nothing to send yet
Reply = tuple[np.ndarray, int] | None


@dataclass(frozen=True)
class Inbox:
    """A topic the batch takes rows from (PointCloud2, tagged by the world, latched: kept for a batch that comes
    late): ``take`` checks a message, raising :class:`~swarm_ros.core.errors.Rejected` if it fails (the node drops
    and counts it), and gives what to send."""

    topic: str
    take: Callable[[Cloud], Reply]


class BatchHost(Protocol):
    #: ``[first, last]``, the cell columns it decides for: what the batch announces on /swarm/batches
    strip: tuple[int, int]
    decisions: str  #: the topic its decisions go out on
    inboxes: tuple[Inbox, ...]

    def describe(self) -> str:
        """The batch's strip, for its first log line."""

    def load(self) -> None:
        """The heavy part, once the node's endpoints exist (the world and the other batches are found meanwhile)."""

    def summary(self) -> str:
        """What the batch took and decided, for its last log line."""
