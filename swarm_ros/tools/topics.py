"""``swarm-ros topics``: look inside a running swarm without a ROS 2 install (ros2cli is not on PyPI).

Lists the graph's topics with their types, publisher and subscriber counts and
measured rates, or prints a topic's messages as YAML-like text, arrays shortened
unless asked, and the robot rows of a PointCloud2 decoded into a small table.
"""

from __future__ import annotations

import array
import sys
import time
from typing import Any

import numpy as np
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

from swarm_ros.core.errors import ContractError, InputError
from swarm_ros.protocol.rows import VOXEL_ROW, check_fields
from swarm_ros.ros.graph import message_class
from swarm_ros.ros.runtime import signals_held, tool_node

_SHOWN_ITEMS = 8  # array items printed without --full
_SHOWN_ROWS = 5  # decoded point-cloud rows printed without --full
_LIVE_S = 1.0  #: --echo waits this long for a live message once a latched topic's history stops arriving


def _message_class(type_name: str) -> type:
    found = message_class(type_name)
    if found is None:
        raise InputError(f"message type {type_name} is not installed here")
    return found


def to_yaml(msg: Any, full: bool = False, indent: int = 0) -> str:
    """A message as YAML-like text, in field order; long arrays shortened unless ``full``."""
    pad = "  " * indent
    lines = []
    for name in msg.get_fields_and_field_types():
        value = getattr(msg, name)
        if hasattr(value, "get_fields_and_field_types"):
            lines.append(f"{pad}{name}:")
            lines.append(to_yaml(value, full, indent + 1))
        elif isinstance(value, (list, tuple, array.array, np.ndarray)):
            items = list(value)
            if items and hasattr(items[0], "get_fields_and_field_types"):
                lines.append(f"{pad}{name}:")
                for item in items if full else items[:_SHOWN_ITEMS]:
                    body = to_yaml(item, full).splitlines()
                    lines.append(f"{pad}- {body[0]}")
                    lines.extend(f"{pad}  {line}" for line in body[1:])
                if not full and len(items) > _SHOWN_ITEMS:
                    lines.append(f"{pad}- '... {len(items) - _SHOWN_ITEMS} more'")
            else:
                shown = items if full else items[:_SHOWN_ITEMS]
                more = [] if full or len(items) <= _SHOWN_ITEMS else [f"'... {len(items) - _SHOWN_ITEMS} more'"]
                lines.append(f"{pad}{name}: [{', '.join([repr(v) for v in shown] + more)}]")
        else:
            lines.append(f"{pad}{name}: {value!r}" if isinstance(value, str) else f"{pad}{name}: {value}")
    return "\n".join(lines)


#: PointField datatype -> numpy type (sensor_msgs/PointField's constants, little-endian)
_POINT_TYPES = {1: "i1", 2: "u1", 3: "<i2", 4: "<u2", 5: "<i4", 6: "<u4", 7: "<f4", 8: "<f8"}


def _layout(fields: list[tuple[str, int, int, int]], step: int) -> np.dtype | None:
    """The rows' numpy type as a cloud's fields give it (an algorithm's rows, its metrics rows), or None if a
    field is not one number; fields of no bytes (a tag) are left out."""
    kept = [(name, offset, kind) for name, offset, kind, count in fields if count != 0]
    if not kept or any(kind not in _POINT_TYPES for _, _, kind in kept) or any(c > 1 for *_, c in fields):
        return None
    return np.dtype(
        {
            "names": [n for n, _, _ in kept],
            "formats": [_POINT_TYPES[k] for _, _, k in kept],
            "offsets": [o for _, o, _ in kept],
            "itemsize": step,
        }
    )


def decoded_rows(msg: Any, full: bool = False) -> str:
    """The rows of a swarm_ros PointCloud2 as a table, or '' for any other message."""
    if type(msg).__name__ != "PointCloud2":
        return ""
    fields = [(f.name, f.offset, f.datatype, f.count) for f in msg.fields]
    generic = _layout(fields, msg.point_step)
    for dtype in (VOXEL_ROW, *([generic] if generic is not None else [])):  # the voxels, or the fields given
        try:
            check_fields(fields, msg.point_step, dtype)
            rows = np.frombuffer(msg.data, dtype=dtype)
        except (ContractError, ValueError, TypeError):
            continue
        fields_of = dtype.names or ()
        names = [n for n in fields_of if n != "z" or "pitch" in fields_of or dtype is VOXEL_ROW]
        out = [f"# {rows.size} rows decoded: " + "  ".join(f"{n:>10}" for n in names)]
        for r in rows if full else rows[:_SHOWN_ROWS]:
            out.append(
                "#" + " " * 19 + "  ".join(f"{r[n]:>10.4f}" if r.dtype[n].kind == "f" else f"{r[n]:>10}" for n in names)
            )
        if not full and rows.size > _SHOWN_ROWS:
            out.append(f"# ... {rows.size - _SHOWN_ROWS} more rows (--full shows all)")
        return "\n".join(out)
    return ""


class _Inspector:
    def __init__(self, node: Node) -> None:
        self.node = node
        self.executor = SingleThreadedExecutor(context=node.context)
        self.executor.add_node(node)

    def spin_for(self, seconds: float, until=lambda: False) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end and not until():
            self.executor.spin_once(timeout_sec=min(0.05, max(0.0, end - time.monotonic())))

    def discover(self, seconds: float) -> None:
        """Spin until the set of topics has not changed for half a second (at most ``seconds``)."""
        end = time.monotonic() + seconds
        seen, stable_since = None, time.monotonic()
        while time.monotonic() < end and time.monotonic() - stable_since < 1.0:
            self.spin_for(0.1)
            now = self.topics()
            if now != seen:
                seen, stable_since = now, time.monotonic()

    def topics(self) -> dict[str, str]:
        own = {"/parameter_events", "/rosout"}
        return {name: types[0] for name, types in self.node.get_topic_names_and_types() if name not in own}

    def publisher_qos(self, topic: str) -> QoSProfile:
        """A QoS that receives what the topic's publishers keep: reliable and latched if they all are."""
        infos = self.node.get_publishers_info_by_topic(topic)
        reliable = bool(infos) and all(i.qos_profile.reliability == ReliabilityPolicy.RELIABLE for i in infos)
        latched = bool(infos) and all(i.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL for i in infos)
        return QoSProfile(
            depth=1000,
            reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
            durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE,
        )


def run_topics(
    domain_id: int, echo: str | None = None, count: int = 1, seconds: float = 2.0, full: bool = False
) -> int:
    """List the topics on ``domain_id`` with rates, or echo ``count`` messages of one. Returns an exit code."""
    deadline = time.monotonic() + seconds
    with tool_node("swarm_ros_topics", domain_id) as node:
        inspector = _Inspector(node)
        try:
            if echo:
                return _echo(inspector, echo, count, seconds, deadline, full)
            inspector.discover(seconds)
            return _list(inspector, domain_id, seconds)
        finally:
            inspector.executor.shutdown()


def _list(inspector: _Inspector, domain_id: int, seconds: float) -> int:
    topics = inspector.topics()
    if not topics:
        print(f"no topics on ROS domain {domain_id} (is a run going? 'swarm-ros run' prints its domain id)")
        return 1
    counts = dict.fromkeys(topics, 0)
    best_effort = QoSProfile(
        depth=1000, reliability=ReliabilityPolicy.BEST_EFFORT, durability=DurabilityPolicy.VOLATILE
    )
    with signals_held():  # (each subscription makes a logger: a Ctrl-C then is acted on after them)
        for name, type_name in topics.items():

            def bump(_msg: bytes, name: str = name) -> None:
                counts[name] += 1

            inspector.node.create_subscription(_message_class(type_name), name, bump, best_effort, raw=True)
    start = time.monotonic()
    inspector.spin_for(seconds)
    elapsed = time.monotonic() - start
    node = inspector.node
    wide = max(22, *(len(name) for name in topics))  # columns as wide as the longest name
    kinds = max(34, *(len(type_name) for type_name in topics.values()))
    print(f"{'topic':<{wide}} {'type':<{kinds}} {'pubs':>4} {'subs':>4} {'rate (Hz)':>10}  qos")
    for name, type_name in sorted(topics.items()):
        infos = node.get_publishers_info_by_topic(name)
        qos = infos[0].qos_profile if infos else None
        kind = "" if qos is None else f"{qos.reliability.name.lower()}, {qos.durability.name.lower()}"
        print(
            f"{name:<{wide}} {type_name:<{kinds}} {len(infos):>4} {node.count_subscribers(name) - 1:>4} "
            f"{counts[name] / elapsed:>10.1f}  {kind}"
        )
    return 0


def _show(msg: object, full: bool) -> None:
    print(to_yaml(msg, full))
    rows = decoded_rows(msg, full)
    if rows:
        print(rows)
    print("---")
    sys.stdout.flush()


def _echo(inspector: _Inspector, topic: str, count: int, wait: float, deadline: float, full: bool) -> int:
    """Print ``count`` messages of ``topic``; give up at ``deadline`` (``wait`` seconds after the start)."""
    # A busy graph can take seconds to show every participant: wait for the topic's publishers.
    inspector.spin_for(
        deadline - time.monotonic(),
        until=lambda: inspector.node.count_publishers(topic) > 0 and topic in inspector.topics(),
    )
    topics = inspector.topics()
    if topic not in topics or inspector.node.count_publishers(topic) == 0:
        raise InputError(
            f"no publisher of {topic} on this domain within {wait:g} s "
            f"(topics seen: {', '.join(sorted(topics)) or 'none'})"
        )
    # A latched stream replays its history first, oldest first, and on a loaded machine that burst can take longer
    # than any wait guessed for it (CI once printed a status from before tick 0). Each message's publisher says when
    # it sent it: those sent after this subscription are live, the rest the history. Echo prints live messages; a
    # topic that sends none once its history is in (the shape, sent once), the newest of its history.
    live: list[object] = []
    kept: list[object] = []
    since = time.time_ns()

    def take(msg: object, info: dict) -> None:
        (live if info.get("source_timestamp", 0) >= since else kept).append(msg)

    with signals_held():  # (rclpy's hint names only the one-argument callback; it passes the info to two)
        inspector.node.create_subscription(
            _message_class(topics[topic]),
            topic,
            take,  # type: ignore[arg-type]
            inspector.publisher_qos(topic),
        )
    while not live and time.monotonic() < deadline:  # (a history still pouring in: a live message is near)
        before = len(kept)
        inspector.spin_for(min(_LIVE_S, max(0.0, deadline - time.monotonic())), until=lambda: bool(live))
        if kept and len(kept) == before:
            break
    printed = 0
    if not live:
        for msg in kept[-count:]:
            _show(msg, full)
            printed += 1
    while live and printed < count:
        _show(live.pop(0), full)
        printed += 1
        if not live and printed < count:
            inspector.spin_for(max(0.0, deadline - time.monotonic()), until=lambda: bool(live))
    if printed == 0:
        print(f"no message on {topic} within {wait:g} s", file=sys.stderr)
        return 1
    return 0
