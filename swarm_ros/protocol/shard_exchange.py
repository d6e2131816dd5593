"""A world shard's side of the exchanges between shards, as a plain class: messages in any order, repeated, or
missing until a restarted peer sends them again.

:class:`ShardExchange` wraps one :class:`~swarm_ros.core.shards.WorldShard`. It is told its own robots'
decisions for a tick, the claims and the parts its peers send, in whatever order the transport delivers them,
and answers through a :class:`ShardPort`: its claims once its robots' decisions are in, its part once the claims
of every peer whose robots can reach its claim window are in too (peers beyond it send none, and are sent none:
:meth:`ShardPlan.reaches`), and the tick once every peer's part is in. A message of a tick already closed is a
repeat and is ignored; one of the next tick is kept for when it is due. What it sent for the last two ticks it
keeps, so that a peer's restarted process, which goes on from its last save (:meth:`WorldShard.saved`), gets
them again (:meth:`resend`). A part that fails its checks is dropped and counted; the tick waits for the
genuine one, which it asks the peer for again. Nothing here knows of ROS: the graph's world shard node
(:mod:`swarm_ros.nodes.darr_niazi.world`, through :mod:`swarm_ros.ros.shard_links`) turns topics into these calls.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from swarm_ros.core.errors import ContractError, Rejected, RunFailed
from swarm_ros.core.metrics import Outcome, TickMetrics
from swarm_ros.core.rules import Decisions
from swarm_ros.core.shards import Part, ShardSaved, WorldShard
from swarm_ros.core.state import SwarmState
from swarm_ros.protocol.checks import Rejections

KEPT_TICKS = 2  #: ticks of sent messages kept for a restarted peer: the one being decided and the one before


class ShardPort(Protocol):
    """What a :class:`ShardExchange` sends, and to whom (peers by shard index)."""

    def send_claims(self, peer: int, tick: int, claims: Decisions) -> None: ...

    def send_part(self, peer: int, tick: int, part: Part) -> None: ...

    def ask_again(self, peer: int) -> None:
        """Ask ``peer`` to send its kept messages again (:meth:`ShardExchange.resend`): its part failed here."""
        ...

    def closed(self, tick: int, part: Part, sent: dict[int, tuple[list[Decisions], list[Part] | None]]) -> None:
        """Tick ``tick`` is closed: ``part`` is what this shard applied (its rows, for its batches and the
        monitor). A restarted process goes on from ``ExchangeSaved(shard.saved(), sent)`` (the shard as it is
        now, and the messages kept for its peers), to be saved before anything of the next tick is sent: the
        port saves what it needs of it (a world shard node, only the rows that changed)."""
        ...


@dataclass
class ExchangeSaved:
    """A shard's save (:meth:`WorldShard.saved`) and the messages it sent for the kept ticks: a restarted process
    sends them again to a peer that asks (a peer restarted too, from a save older than its peers' ticks)."""

    shard: ShardSaved
    sent: dict[int, tuple[list[Decisions], list[Part] | None]]


class ShardExchange:
    """One shard's exchanges with its peers (see the module's docstring)."""

    def __init__(self, shard: WorldShard, port: ShardPort, rejections: Rejections) -> None:
        self.shard, self.port, self.rejections = shard, port, rejections
        self.peers = [j for j in range(shard.plan.shards) if j != shard.index]
        self.decisions: dict[int, Decisions] = {}  # own robots' decisions, by tick
        self.removing: dict[int, np.ndarray | None] = {}  # own robots removed at a tick's end, by tick
        self.claims: dict[int, dict[int, Decisions]] = {}  # by tick, by peer
        self.parts: dict[int, dict[int, Part]] = {}  # by tick, by peer
        self.applied: Part | None = None  # this shard's part of the tick being closed
        self.sent: dict[int, tuple[list[Decisions], list[Part] | None]] = {}  # by tick: claims and parts sent

    @property
    def tick(self) -> int:
        """The last tick closed."""
        return self.shard.tick if self.applied is None else self.shard.tick - 1

    def _due(self, tick: int) -> bool | None:
        """True: the tick being worked on; False: one of the next (kept: a restarted process can be
        ``KEPT_TICKS`` behind its peers, which are then that far ahead of it); None: a repeat, or beyond."""
        if tick == self.tick + 1:
            return True
        return False if self.tick + 1 < tick <= self.tick + 1 + KEPT_TICKS else None

    def own_decisions(self, decisions: Decisions, removing: np.ndarray | None = None) -> None:
        """This shard's robots' decisions (all of them) for ``decisions.tick``; ``removing``: its robots removed
        at that tick's end (a lost batch's).

        Raises:
            ContractError: decisions of a tick neither due nor next.
        """
        due = self._due(decisions.tick)
        if due is None:
            if decisions.tick <= self.tick:
                return  # a repeat: a batch's history handed over again
            raise ContractError(f"shard {self.shard.index}: decisions of tick {decisions.tick} at {self.tick}")
        self.decisions[decisions.tick] = decisions
        self.removing[decisions.tick] = removing
        self._go()

    def peer_claims(self, peer: int, tick: int, claims: Decisions) -> None:
        """Peer ``peer``'s claims on this shard's window for ``tick`` (dropped and counted if not one; checked
        when due, and then dropped, counted and asked for again if they fail; a later one replaces one held)."""
        if peer not in self.shard.claims_from:  # no shard, or one whose robots cannot reach this one's window
            self.rejections.drop("claims", Rejected("unknown shard", f"{peer} (claims on shard {self.shard.index})"))
        elif self._due(tick) is not None:
            self.claims.setdefault(tick, {})[peer] = claims
            self._go()

    def peer_part(self, peer: int, tick: int, part: Part) -> None:
        """Peer ``peer``'s part of ``tick``, as routed to this shard (a later one replaces one held: a peer asked
        again sends its part again)."""
        if peer not in self.peers or part.source != peer or part.tick != tick:
            self.rejections.drop("parts", Rejected("unknown shard", f"{peer} (part of {part.source}, {part.tick})"))
        elif self._due(tick) is not None:
            self.parts.setdefault(tick, {})[peer] = part
            self._go()

    def resend(self, peer: int) -> None:
        """Send ``peer`` again what it was sent for the kept ticks (a restarted process of it asks)."""
        for tick in sorted(self.sent):
            claims, parts = self.sent[tick]
            if peer in self.shard.claims_to:
                self.port.send_claims(peer, tick, claims[peer])
            if parts is not None:
                self.port.send_part(peer, tick, parts[peer])

    def restore(self, saved: ExchangeSaved) -> None:
        """A restarted process: go on from ``saved``, and send every peer the kept messages again (what was in
        flight to a peer that died meanwhile is lost). What its process before held it is given again: its peers
        send again when it asks (:meth:`resend`), its batches their decisions."""
        self.shard.restore(saved.shard)
        self.decisions, self.removing, self.claims, self.parts, self.applied = {}, {}, {}, {}, None
        self.sent = dict(saved.sent)
        for j in self.peers:
            self.resend(j)

    def _go(self) -> None:
        """Apply and close what is due, as far as the messages in hand allow."""
        shard = self.shard
        while shard.outcome is None:
            tick = self.tick + 1
            if self.applied is None:
                if tick not in self.decisions:
                    return
                if tick not in self.sent:
                    claims = shard.claims(self.decisions[tick])
                    self.sent[tick] = (claims, None)
                    for j in shard.claims_to:  # none to a shard beyond its robots' reach
                        self.port.send_claims(j, tick, claims[j])
                rivals, claimants = self.claims.get(tick, {}), shard.claims_from
                if len(rivals) < len(claimants):
                    return
                for j in claimants:
                    try:
                        shard.check_claims(j, rivals[j])
                    except Rejected as fault:  # dropped, counted, and asked for again
                        self.rejections.drop("claims", fault)
                        del rivals[j]
                        self.port.ask_again(j)
                if len(rivals) < len(claimants):
                    return
                rival = [rivals[j] for j in claimants]
                self.applied = shard.apply(self.decisions[tick], rival, self.removing.get(tick))
                routed = shard.routes(self.applied)
                self.sent[tick] = (self.sent[tick][0], routed)
                for j in self.peers:
                    self.port.send_part(j, tick, routed[j])
            parts = self.parts.get(tick, {})
            if len(parts) < len(self.peers):
                return
            received = [parts[j] for j in self.peers]
            try:
                shard.close(self.applied, received)
            except Rejected as fault:
                self._drop_bad(tick, received, fault)
                continue
            part, self.applied = self.applied, None
            for held in (self.decisions, self.removing, self.claims, self.parts):
                held.pop(tick, None)
            for old in [t for t in self.sent if t <= tick - KEPT_TICKS]:
                del self.sent[old]
            self.port.closed(tick, part, dict(self.sent))

    def _drop_bad(self, tick: int, received: list[Part], fault: Rejected) -> None:
        """Drop the parts that fail alone (counted); if none does, two peers contradict each other: the run fails."""
        bad = []
        for q in received:
            try:
                self.shard.check([q], whole=False)
            except Rejected as why:
                bad.append((q.source, why))
        if not bad:
            raise RunFailed(f"shard {self.shard.index}, tick {tick}: the parts of its peers disagree: {fault}")
        for source, reason in bad:
            self.rejections.drop("parts", reason)
            del self.parts[tick][source]
            self.port.ask_again(source)


class RunView:
    """The run as a world process holds it, for its lockstep: the last tick its exchange closed, its shard's
    view (exact in its area; the world's: everywhere), the metrics every shard holds alike, and its own moving
    robots."""

    def __init__(self, exchange: ShardExchange) -> None:
        self.exchange, self.shard = exchange, exchange.shard
        self.shape, self.params = self.shard.shape, self.shard.params

    @property
    def tick(self) -> int:
        return self.exchange.tick

    @property
    def done(self) -> bool:
        return self.shard.outcome is not None

    @property
    def outcome(self) -> Outcome | None:
        return self.shard.outcome

    @property
    def state(self) -> SwarmState:
        return self.shard.state

    @property
    def history(self) -> list[tuple[int, ...]]:
        return self.shard.history

    @property
    def losses(self) -> list[tuple[int, int]]:
        return self.shard.losses

    @property
    def removed(self) -> int:
        """Robots removed so far (failures, lost batches' robots)."""
        return sum(n for _, n in self.shard.losses)

    @property
    def metrics(self) -> TickMetrics:
        return TickMetrics(*self.shard.history[-1])

    def moving_ids(self) -> np.ndarray:
        return self.shard.own_moving()
