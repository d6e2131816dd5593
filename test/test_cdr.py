"""PointCloud2 (and Int64MultiArray) serialized with numpy alone (swarm_ros.protocol.cdr): the same messages as
rclpy's serializer, read back in place, and bytes from anybody refused cleanly."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

pytest.importorskip("rclpy")
from rclpy.serialization import deserialize_message, serialize_message
from runs import make_cloud
from sensor_msgs.msg import PointCloud2
from std_msgs.msg import Int64MultiArray, MultiArrayDimension

from swarm_ros.core.errors import Rejected
from swarm_ros.protocol import checks
from swarm_ros.protocol.cdr import decode_cloud, encode_cloud, encode_ints
from swarm_ros.protocol.darr_niazi.rows import DECISION_ROW, ROBOT_ROW
from swarm_ros.protocol.tag import aligned

pytestmark = pytest.mark.unit


def _rows(dtype: np.dtype, n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    rows = np.zeros(n, dtype=dtype)
    for name in dtype.names:
        rows[name] = rng.integers(0, 100, n) if dtype[name].kind in "iu" else rng.random(n)
    return rows


@pytest.mark.parametrize("dtype", [ROBOT_ROW, DECISION_ROW], ids=["robots", "decisions"])
@pytest.mark.parametrize("n", [0, 1, 3, 1036])
def test_rclpy_reads_the_bytes_as_the_same_message_and_they_read_rclpys(dtype, n):
    """Byte equality with rclpy's serializer is not to be had: it leaves whatever was in memory in the alignment
    padding. Both ways round, the messages are the same."""
    rows = _rows(dtype, n)
    ours, theirs = encode_cloud(rows, 41), make_cloud(rows, 41)
    assert len(ours) == len(serialize_message(theirs))
    assert deserialize_message(ours, PointCloud2) == theirs
    back = decode_cloud(aligned(serialize_message(theirs)))
    assert back.header.stamp.sec == 41 and bytes(back.data) == rows.tobytes() and back.width == n


@pytest.mark.parametrize("label", ["held", "tick,stationary,localized", "x" * 33])
@pytest.mark.parametrize("n", [0, 1, 2, 9])
@pytest.mark.parametrize("tag", ["", "swarm_ros.tag:monitor:ab12:7:" + "0" * 32])
def test_an_int64_array_is_the_message_rclpy_serializes_both_ways_round(label, n, tag):
    """The graph's Int64MultiArray messages (held, metrics, tallies, counts) as bytes: rclpy reads them as the
    message they stand for, and they are as long as its own (whose padding holds what was in memory)."""
    values = np.arange(n, dtype=np.int64) * -(10**12) + 3
    msg = Int64MultiArray()
    msg.layout.dim = [MultiArrayDimension(label=label, size=n, stride=n)]
    if tag:
        msg.layout.dim.append(MultiArrayDimension(label=tag, size=1, stride=1))
    msg.data = values.tolist()
    ours = encode_ints(values, label, tag)
    assert len(ours) == len(serialize_message(msg))
    assert deserialize_message(ours, Int64MultiArray) == msg


@pytest.mark.parametrize("n", [1, 7])
def test_a_cloud_reads_back_as_rclpy_reads_it(n):
    rows = _rows(ROBOT_ROW, n, seed=3)
    data = aligned(encode_cloud(rows, 12))  # as a reader takes it: padded to a multiple of 4
    cloud, msg = decode_cloud(data), deserialize_message(data, PointCloud2)
    assert cloud.header.stamp.sec == msg.header.stamp.sec == 12 and cloud.header.frame_id == msg.header.frame_id
    assert [(f.name, f.offset, f.datatype, f.count) for f in cloud.fields] == [
        (f.name, f.offset, f.datatype, f.count) for f in msg.fields
    ]
    assert (cloud.height, cloud.width, cloud.point_step, cloud.row_step, cloud.is_dense, cloud.is_bigendian) == (
        msg.height,
        msg.width,
        msg.point_step,
        msg.row_step,
        msg.is_dense,
        msg.is_bigendian,
    )
    assert np.array_equal(checks.cloud(cloud, ROBOT_ROW, 100), rows)
    assert checks.tick_stamp(cloud.header) == 12


@settings(max_examples=300, deadline=None)
@given(cut=st.integers(0, 400), flips=st.lists(st.tuples(st.integers(0, 400), st.integers(0, 255)), max_size=4))
def test_bytes_from_anybody_parse_or_are_rejected_never_crash(cut, flips):
    data = bytearray(encode_cloud(_rows(DECISION_ROW, 5), 3))
    for at, value in flips:
        if at < len(data):
            data[at] = value
    data = bytes(data[: max(cut, 0)] if cut < len(data) else data)
    try:
        cloud = decode_cloud(data)
    except Rejected as fault:
        assert fault.kind == "malformed CDR"
        return
    try:
        checks.cloud(cloud, DECISION_ROW, 10)
    except Rejected:
        pass


def test_a_huge_length_is_refused_without_reading_past_the_buffer():
    data = bytearray(encode_cloud(_rows(ROBOT_ROW, 2), 1))
    data[12:16] = (2**31).to_bytes(4, "little")  # the frame id's length
    with pytest.raises(Rejected, match="malformed CDR"):
        decode_cloud(bytes(data))
    with pytest.raises(Rejected, match="not little-endian CDR"):
        decode_cloud(b"\x00\x00\x00\x00" + bytes(data[4:]))
