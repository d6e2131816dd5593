"""What the run's nodes ask of the ROS graph, on a fake node: no DDS participant."""

from __future__ import annotations

import types

import pytest

from swarm_ros.ros import graph as msgs

pytestmark = pytest.mark.unit

TOPICS = ("/swarm/darr_niazi/robots", "/swarm/darr_niazi/metrics", "/swarm/status")


def _node(readers: dict[str, list[str]]):
    """A node whose graph holds, for each topic, readers of the named nodes."""

    def info(topic: str):
        return [types.SimpleNamespace(node_name=name) for name in readers.get(topic, [])]

    return types.SimpleNamespace(get_subscriptions_info_by_topic=info)


def test_the_world_waits_until_the_monitor_reads_every_topic_named_or_not_yet_named():
    """A reader whose participant has not yet said its node's name (rmw_dds_common's placeholder) counts: a full run of
    the suite saw the monitor's readers stay unnamed for 120 s. Another node's reader does not."""
    named = dict.fromkeys(TOPICS, ["monitor"])
    assert msgs.monitor_reads(_node(named), TOPICS)
    assert not msgs.monitor_reads(_node({**named, "/swarm/status": []}), TOPICS)
    assert not msgs.monitor_reads(_node({**named, "/swarm/status": ["robot_batch_0"]}), TOPICS)
    assert msgs.monitor_reads(_node({**named, "/swarm/status": ["robot_batch_0", "_NODE_NAME_UNKNOWN_"]}), TOPICS)


def test_a_world_waiting_for_its_monitor_can_say_who_reads_each_topic():
    readers = {TOPICS[0]: ["monitor"], TOPICS[2]: ["_NODE_NAME_UNKNOWN_", "echo"]}
    assert msgs.readers_seen(_node(readers), TOPICS) == (
        "/swarm/darr_niazi/robots: monitor; /swarm/darr_niazi/metrics: none; /swarm/status: _NODE_NAME_UNKNOWN_, echo"
    )
