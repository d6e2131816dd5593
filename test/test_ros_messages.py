"""Messages and node parameters of the ROS 2 graph, in one process."""

from __future__ import annotations

import re

import numpy as np
import pytest
import rclpy
from nav_msgs.msg import OccupancyGrid
from rclpy.context import Context
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.serialization import deserialize_message, serialize_message
from runs import cloud_rows, make_cloud
from sensor_msgs.msg import PointCloud2

from swarm_ros.core import RunParams, Shape, Simulation
from swarm_ros.core.errors import ConfigError, Rejected
from swarm_ros.core.params import RUN_PARAMETERS, Settings
from swarm_ros.protocol.darr_niazi.rows import DECISION_ROW, ROBOT_ROW, robot_rows
from swarm_ros.ros import graph as msgs
from swarm_ros.ros.node_params import read_parameters

pytestmark = pytest.mark.process


def test_robot_rows_survive_serialization_exactly_and_carry_the_tick():
    sim = Simulation(Shape.load("star"), RunParams(robots=1036, seed=9))
    sim.run(max_ticks=40)
    s = sim.state
    sent = robot_rows(np.arange(1036), s.state, s.x, s.y, s.heading)
    wire = serialize_message(make_cloud(sent, 40))
    msg = deserialize_message(wire, PointCloud2)
    assert msgs.tick_of(msg.header) == 40 and msg.header.frame_id == "world"
    assert (msg.width, msg.point_step, msg.row_step) == (1036, 40, 1036 * 40)
    got = cloud_rows(msg, ROBOT_ROW)
    assert got.tobytes() == sent.tobytes()
    with pytest.raises(Rejected, match="unexpected point layout"):
        cloud_rows(msg, DECISION_ROW)


def test_occupancy_grid_places_patch_centres_on_cells():
    shape = Shape.load("tyre")
    grid = deserialize_message(
        msgs.WorldMaps(shape.world.cell_map(shape.mask, np.zeros_like(shape.mask))).shape_message(3), OccupancyGrid
    )
    w = shape.world.size
    assert (grid.info.width, grid.info.height, grid.info.resolution) == (w, w, 1.0)
    assert grid.info.origin.position.x == -(shape.world.radius + 0.5)
    cells = np.asarray(grid.data, dtype=np.int8)
    assert (cells == msgs.CELL_EMPTY).sum() == shape.patches
    assert (cells == msgs.CELL_OFF_SHAPE).sum() == w * w - shape.patches


def test_a_rubenstein_runs_maps_are_its_shape_pixels_in_d_from_the_bitmaps_corner():
    """A central world's maps come from its engine's cells (CellMap): here a bitmap of unequal sides, in d."""
    from swarm_ros.core.rubenstein.run import RubensteinRun

    run = RubensteinRun(Shape.load("star"), RunParams(200, algorithm="rubenstein", seed=1))
    cells, b = run.cell_map(), run.bitmap
    maps = msgs.WorldMaps(cells)
    shape = deserialize_message(maps.shape_message(0), OccupancyGrid)
    assert (shape.info.width, shape.info.height) == (b.cols, b.rows) and b.cols != b.rows
    assert shape.info.resolution == pytest.approx(b.pixel)
    assert (shape.info.origin.position.x, shape.info.origin.position.y) == (b.x0, b.y0)
    assert np.array_equal(np.asarray(shape.data) == msgs.CELL_EMPTY, b.mask)  # row 0 the bottom, as the bitmap's
    run.run(2000)
    grid = deserialize_message(maps.occupancy_message(run.cell_map().filled, run.tick), OccupancyGrid)
    full = np.asarray(grid.data) == msgs.CELL_FULL
    assert full.sum() == run.progress()[0] > 0 and np.array_equal(full, run.covered > 0)


@pytest.fixture
def ros_context():
    context = Context()
    rclpy.init(args=[], context=context)
    yield context
    rclpy.shutdown(context=context)


def _node(context, kind, **values):
    return Node(
        kind,
        context=context,
        allow_undeclared_parameters=True,
        automatically_declare_parameters_from_overrides=True,
        parameter_overrides=[Parameter(k, value=v) for k, v in values.items()],
    )


def test_parameters_take_defaults_and_accept_integers_for_numbers(ros_context):
    node = _node(ros_context, "world", robots=500, vision_radius=2, monitor_window=0, tick_rate=20)
    run, own = read_parameters(node, "world")
    assert run == Settings(robots=500, vision_radius=2.0)
    assert isinstance(run.vision_radius, float) and isinstance(own["tick_rate"], float)
    assert own == {
        "monitor_window": 0,
        "start_timeout": 60.0,
        "on_batch_loss": "restart",
        "max_restarts": 3,
        "checkpoint": "",
        "incarnation": 0,
        "tick_rate": 20.0,
        "record_every": 0,
    }
    node.destroy_node()


@pytest.mark.parametrize(
    "kind,values,message",
    [
        ("world", {"bogus": 1}, "node 'world': unknown parameter 'bogus'"),
        ("world", {"batch": 1}, "unknown parameter 'batch'"),
        (
            "robot_batch",
            {"robots": "many"},
            "robots must be an integer >= 4 \\(0 = the shape's patch count\\), got 'many'",
        ),
        ("monitor", {"overwrite": 1}, "overwrite must be a boolean, got 1"),
        ("monitor", {"seed": 1.5}, "seed must be an integer >= 0 and <= 9223372036854775807, got 1.5"),
        ("robot_batch", {"region_cuts": [4, 5]}, "region_cuts must be a string \\(.*\\), got \\[4, 5\\]"),
    ],
)
def test_unknown_or_ill_typed_parameters_are_refused(ros_context, kind, values, message):
    node = _node(ros_context, kind, **values)
    with pytest.raises(ConfigError, match=message):
        read_parameters(node, kind)
    node.destroy_node()


@pytest.mark.parametrize(
    "kind,values,message",
    [
        ("world", {"monitor_window": -5}, "monitor_window must be an integer >= 0 (0 = do not wait for one), got -5"),
        ("world", {"start_timeout": 0}, "start_timeout must be a number > 0, got 0"),
        ("world", {"on_batch_loss": "ignore"}, "on_batch_loss must be one of restart, remove, got 'ignore'"),
        ("world", {"max_restarts": -1}, "max_restarts must be an integer >= 0, got -1"),
        ("robot_batch", {"incarnation": -1}, "incarnation must be an integer >= 0, got -1"),
        (
            "monitor",
            {"record_every": -1},
            "record_every must be an integer >= 1 (0 = chosen from the swarm's size), got -1",
        ),
    ],
)
def test_node_parameters_out_of_range_are_refused(ros_context, kind, values, message):
    node = _node(ros_context, kind, **values)
    with pytest.raises(ConfigError, match=re.escape(f"node '{kind}': {message}")):
        read_parameters(node, kind)
    node.destroy_node()


@pytest.mark.parametrize("kind", ["world", "robot_batch", "monitor"])
def test_a_p_argument_wins_over_the_shipped_parameter_file(kind):
    """rcl's own precedence: the shipped file sets no node section that would shadow ``-p`` (as the docs'
    hand-started monitor, ``--params-file config/swarm_ros.yaml -p out_dir:=...``, relies on)."""
    from swarm_ros.core.params import NODE_PARAMETERS
    from swarm_ros.core.resources import data_dir

    given = {
        p.name: (not p.default if p.kind is bool else p.default + 1 if p.kind in (int, float) else "x")
        for p in NODE_PARAMETERS[kind]
        if not p.options
    }
    args = ["--ros-args", "--params-file", str(data_dir("config") / "swarm_ros.yaml"), "-p", "seed:=7"]
    for name, value in given.items():
        args += ["-p", f"{name}:={str(value).lower() if isinstance(value, bool) else value}"]
    context = Context()
    rclpy.init(args=args, context=context)
    try:
        node = Node(
            kind,
            context=context,
            allow_undeclared_parameters=True,
            automatically_declare_parameters_from_overrides=True,
        )
        run, own = read_parameters(node, kind)
        node.destroy_node()
    finally:
        rclpy.shutdown(context=context)
    assert run.seed == 7
    assert {name: own[name] for name in given} == given


def test_every_parameter_is_declared_with_its_descriptor_read_only_with_its_range(ros_context):
    """What `ros2 param describe` shows comes from the declaration: meaning, type, the values it takes in words,
    the range of a bounded number, read-only; the node's values are the checked ones."""
    from rcl_interfaces.msg import ParameterType

    from swarm_ros.core.params import NODE_PARAMETERS

    node = _node(ros_context, "world", robots=500, vision_radius=2, seed=9)
    run, own = read_parameters(node, "world")
    params = (*RUN_PARAMETERS, *NODE_PARAMETERS["world"])
    described = dict(zip([p.name for p in params], node.describe_parameters([p.name for p in params])))
    for p in params:
        d = described[p.name]
        assert (d.description, d.additional_constraints, d.read_only) == (p.help, p.describe(), True), p.name
        ranges = list(d.integer_range) + list(d.floating_point_range)
        if p.kind in (int, float) and not p.blank and (p.low is not None or p.high is not None):
            (r,) = ranges
            assert (p.low is None or r.from_value == p.low) and (p.high is None or r.to_value == p.high), p.name
        else:
            assert ranges == [], p.name
    assert described["seed"].type == ParameterType.PARAMETER_INTEGER
    assert described["vision_radius"].type == ParameterType.PARAMETER_DOUBLE
    assert (
        described["wiggle_deg"].floating_point_range[0].from_value,
        described["wiggle_deg"].floating_point_range[0].to_value,
    ) == (0.0, 180.0)
    assert node.get_parameter("vision_radius").value == 2.0 and node.get_parameter("seed").value == 9
    assert node.get_parameter("max_restarts").value == own["max_restarts"] == 3  # not overridden: the default
    refused = node.set_parameters([Parameter("seed", value=3)])[0]
    assert not refused.successful and "read-only" in refused.reason
    node.destroy_node()
