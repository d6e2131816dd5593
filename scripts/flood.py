#!/usr/bin/env python3
"""Flood a run's ROS domain: messages without a valid tag, on every topic of the run, at a set rate.

What a stranger on the domain (or a buggy tool) can do to a run: publish, on each of its topics,
with that topic's own QoS (read from the run's writers, so the run's readers match), as fast as
asked. Per topic, the messages cycle through: bytes that do not parse as the type; a well-formed
message of the type without a tag (for a cloud, the rows' layout with nonsense rows; a status
saying the run is complete); the same with a tag under another key. Topics that appear later
(a batch's decisions topic, its snapshot) are picked up as they appear.

It runs until it gets SIGINT/SIGTERM or ``--seconds`` pass, then prints one JSON line: the
messages sent per topic, the seconds, and the rate reached per topic. Used by
test/test_flood.py and ``scripts/bench_ros.py --only flood``; docs/security.md has the numbers.

    .venv/bin/python scripts/flood.py --domain-id 61 --rate 5000 [--seconds 30]
"""

from __future__ import annotations

import argparse
import json
import signal
import sys
import time

import numpy as np

RUN_TOPIC_PREFIXES = ("/swarm/", "/clock")
DISCOVER_EVERY = 0.5  #: seconds between looks for new topics


def _messages(type_name: str, topic: str) -> list[bytes]:
    """Serialized messages of ``type_name`` that no run node may take."""
    from rclpy.serialization import serialize_message

    from swarm_ros.protocol.cdr import encode_cloud
    from swarm_ros.protocol.darr_niazi.rows import DECISION_ROW, ROBOT_ROW
    from swarm_ros.protocol.tag import Sealer
    from swarm_ros.ros import graph as msgs
    from swarm_ros.ros.auth import put_tag

    garbage = b"\x00\x01\x00\x00" + bytes(range(256)) * 2
    out = [garbage]
    if type_name == "sensor_msgs/msg/PointCloud2":
        dtype = DECISION_ROW if "decisions" in topic else ROBOT_ROW
        rows = np.zeros(64, dtype=dtype)
        rows["id"] = np.arange(4, 68)
        rows["x"] = 1e300
        out.append(encode_cloud(rows, 3))
        blank = Sealer(b"not the run's key", "world").blank()
        out.append(encode_cloud(rows, 3, tag=blank.replace("0" * 32, "f" * 32)))
    elif type_name in ("diagnostic_msgs/msg/DiagnosticArray", "std_msgs/msg/Int64MultiArray"):
        if type_name.startswith("diagnostic"):
            msg = msgs.status_message(3, "complete", "complete at tick 3")
        else:
            msg = msgs.ids_message(np.arange(4, 40))
            msg.layout.dim[0].label = "robot_batch_0/9"
        out.append(serialize_message(msg))
        put_tag(msg, Sealer(b"not the run's key", "world").blank())
        out.append(serialize_message(msg))
    else:
        cls = msgs.message_class(type_name)
        if cls is not None:
            out.append(serialize_message(cls()))
    return out


class Flood:
    def __init__(self, domain_id: int, rate: float) -> None:
        import rclpy
        from rclpy.context import Context
        from rclpy.node import Node

        from swarm_ros.ros.dds import apply_dds_defaults

        apply_dds_defaults()
        self.context = Context()
        rclpy.init(args=[], context=self.context, domain_id=domain_id)
        self.node = Node("flood", context=self.context, start_parameter_services=False)
        self.rate = rate
        self.pubs: dict[str, tuple[object, list[bytes]]] = {}
        self.sent: dict[str, int] = {}
        self.since: dict[str, float] = {}  # topic -> when its publisher was made
        self.failed: dict[str, int] = {}  # topic -> samples DDS refused
        self.errors: set[str] = set()

    def discover(self) -> None:
        from rclpy.qos import HistoryPolicy, QoSProfile

        from swarm_ros.ros import graph as msgs

        for topic, types in self.node.get_topic_names_and_types():
            if topic in self.pubs or not topic.startswith(RUN_TOPIC_PREFIXES):
                continue
            writers = [w for w in self.node.get_publishers_info_by_topic(topic) if w.node_name != "flood"]
            cls = msgs.message_class(types[0])
            if not writers or cls is None:
                continue
            q = writers[0].qos_profile
            qos = QoSProfile(
                history=HistoryPolicy.KEEP_LAST,
                depth=64,
                reliability=q.reliability,
                durability=q.durability,
                liveliness=q.liveliness,
                liveliness_lease_duration=q.liveliness_lease_duration,
            )
            self.pubs[topic] = (self.node.create_publisher(cls, topic, qos), _messages(types[0], topic))
            self.sent[topic] = 0
            self.since[topic] = time.monotonic()

    def run(self, seconds: float) -> float:
        stop = []
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, lambda *_: stop.append(1))
        start = self.start = time.monotonic()
        looked = -DISCOVER_EVERY
        print("flood: ready", file=sys.stderr, flush=True)  # its participant is up (what a caller may wait for)
        while not stop and time.monotonic() - start < seconds:
            now = time.monotonic()
            if now - looked >= DISCOVER_EVERY:
                self.discover()
                looked = now
            for topic, (pub, variants) in self.pubs.items():  # each topic up to its share of the rate by now
                due = int(self.rate * (now - self.since[topic])) - self.sent[topic]
                for i in range(min(due, 1000)):
                    try:
                        pub.publish(variants[(self.sent[topic] + i) % len(variants)])
                    except Exception as exc:  # rclpy's RCLError: DDS refused the sample (its writer is full)
                        self.failed[topic] = self.failed.get(topic, 0) + 1
                        self.errors.add(str(exc).split(",")[0])
                self.sent[topic] += max(0, min(due, 1000))
            time.sleep(0.001)
        return time.monotonic() - start

    def close(self) -> None:
        import rclpy

        self.node.destroy_node()
        rclpy.shutdown(context=self.context)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--domain-id", type=int, required=True)
    parser.add_argument("--rate", type=float, default=5000.0, help="messages per second on each topic")
    parser.add_argument("--seconds", type=float, default=3600.0)
    args = parser.parse_args(argv)
    flood = Flood(args.domain_id, args.rate)
    try:
        seconds = flood.run(args.seconds)
    finally:
        flood.close()
    busy = {t: n for t, n in flood.sent.items() if n}
    rates = {t: round(n / max(seconds - (flood.since[t] - flood.start), 1e-9)) for t, n in busy.items()}
    print(
        json.dumps(
            {
                "seconds": round(seconds, 2),
                "sent": busy,
                "total": sum(busy.values()),
                "rate_per_topic": rates,
                "refused": flood.failed,
                "errors": sorted(flood.errors),
            }
        ),
        flush=True,
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
