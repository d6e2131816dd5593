"""A 3D run's messages: its rows through rclpy's serializer, its voxel clouds as standard PointCloud2s, and
``swarm-ros topics``' table of either."""

from __future__ import annotations

import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from runs import cloud_rows, make_cloud
from sensor_msgs.msg import PointCloud2

from swarm_ros.core import RunParams, Shape, Simulation
from swarm_ros.core.errors import Rejected
from swarm_ros.protocol import checks
from swarm_ros.protocol.cdr import decode_cloud, encode_cloud
from swarm_ros.protocol.darr_niazi.rows import ROBOT_ROW, ROBOT_ROW_3D, decision_rows, state_rows
from swarm_ros.protocol.darr_niazi.wire import StudyWire
from swarm_ros.protocol.rows import VOXEL_ROW
from swarm_ros.ros import graph as msgs
from swarm_ros.tools.topics import decoded_rows

pytestmark = pytest.mark.process  # rclpy's serializer loads the ROS message libraries


@pytest.fixture(scope="module")
def torus_run():
    sim = Simulation(Shape.load("torus"), RunParams(robots=1348, seed=9))
    sim.run(max_ticks=40)
    return sim


def test_3d_robot_rows_survive_serialization_exactly_and_carry_z_and_pitch(torus_run):
    s = torus_run.state
    sent = state_rows(np.arange(s.robots), s)
    assert sent.dtype == ROBOT_ROW_3D and np.any(sent["z"] != 0) and np.any(sent["pitch"] != 0)
    msg = deserialize_message(serialize_message(make_cloud(sent, 40)), PointCloud2)
    assert (msg.point_step, msg.width) == (48, s.robots)
    checked = checks.cloud(msg, ROBOT_ROW_3D, s.robots)
    StudyWire.check_rows(torus_run, checked, torus_run.tick)
    assert checked.tobytes() == sent.tobytes()
    with pytest.raises(Rejected, match="point layout"):  # a 2D reader drops a 3D cloud, and the other way round
        checks.cloud(msg, ROBOT_ROW, s.robots)
    own = decode_cloud(encode_cloud(sent, 40))  # the graph's own writer and reader agree with rclpy's
    assert bytes(own.data) == sent.tobytes()


def test_a_3d_pose_out_of_range_is_rejected(torus_run):
    s = torus_run.state
    rows = state_rows(np.arange(s.robots), s).copy()
    rows["pitch"][7] = 2.0
    with pytest.raises(Rejected, match="pose outside the world"):
        StudyWire.check_rows(torus_run, checks.cloud(make_cloud(rows, 40), ROBOT_ROW_3D, s.robots), 40)
    rows["pitch"][7], rows["z"][9] = 0.0, 40.0
    with pytest.raises(Rejected, match="pose outside the world"):
        StudyWire.check_rows(torus_run, checks.cloud(make_cloud(rows, 40), ROBOT_ROW_3D, s.robots), 40)


def _cells(shape: Shape):
    return shape.world.cell_map(shape.mask, np.zeros_like(shape.mask))


def test_a_3d_worlds_maps_are_voxel_clouds(torus_run):
    shape, s = torus_run.shape, torus_run.state
    maps = msgs.WorldMaps(_cells(shape))
    assert maps.kind is PointCloud2
    whole = deserialize_message(maps.shape_message(0), PointCloud2)
    voxels = cloud_rows(whole, VOXEL_ROW)
    assert voxels.size == shape.patches and whole.header.frame_id == "world"
    flat = shape.world.flat_of(*(voxels[a].astype(np.int64) for a in "xyz"))
    assert shape.mask.ravel()[flat].all()
    filled = cloud_rows(
        deserialize_message(maps.occupancy_message(s.occupancy.reshape(shape.mask.shape) >= 0, 40), PointCloud2),
        VOXEL_ROW,
    )
    assert filled.size == int((s.occupancy >= 0).sum()) > 4
    assert msgs.WorldMaps(_cells(Shape.load("star"))).kind.__name__ == "OccupancyGrid"


def test_topics_prints_3d_rows_with_z_and_pitch(torus_run):
    s = torus_run.state
    text = decoded_rows(make_cloud(state_rows(np.arange(s.robots), s), 40))
    assert text.splitlines()[0].split()[4:] == ["x", "y", "z", "heading", "pitch", "id", "state"]
    decisions = decoded_rows(make_cloud(decision_rows(torus_run.last_decisions()), 40))
    assert "pitch" in decisions.splitlines()[0] and "claim" in decisions.splitlines()[0]
    assert "z" not in decoded_rows(make_cloud(np.zeros(3, dtype=ROBOT_ROW), 1)).split()  # 2D: as before


def test_topics_prints_any_algorithms_rows_as_their_fields_say():
    """An algorithm's own rows and the metrics rows have no layout of the study's: the table follows the fields."""
    from swarm_ros.core.darr_niazi.metrics import METRIC_COLUMNS
    from swarm_ros.protocol.central_rows import metrics_row

    rows = np.zeros(2, dtype=metrics_row(tuple(METRIC_COLUMNS)))
    rows["tick"], rows["empty_patches"] = [40, 41], [7, 6]
    text = decoded_rows(make_cloud(rows, 41)).splitlines()
    assert text[0].split()[4:] == list(METRIC_COLUMNS) and text[1].split()[0] == "#"
    assert [float(v) for v in text[2].split()[1:]] == [41, 0, 0, 0, 0, 6, 0]
