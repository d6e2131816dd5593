"""The swarm's ROS 2 graph, as ``swarm-ros run`` starts it: a world, K robot batches and a monitor.

    ros2 launch swarm_ros swarm.launch.py shape:=star processes:=2
    ros2 launch swarm_ros swarm.launch.py params_file:=/path/to/params.yaml out_dir:=runs/mine

Launch arguments: the run parameters (each overrides the parameter file when given), the
number of robot-batch processes, the parameter file and the monitor's output directory.
Robot batches are respawned when they die: the world sends the new process a snapshot
of the current tick and the run goes on unchanged (docs/ros_graph.md, Faults).
"""

from __future__ import annotations

import os
import secrets

from ament_index_python.packages import get_package_share_directory
from launch.actions import (
    DeclareLaunchArgument,
    EmitEvent,
    OpaqueFunction,
    RegisterEventHandler,
    SetEnvironmentVariable,
    TimerAction,
)
from launch.event_handlers import OnProcessExit
from launch.events import Shutdown
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from launch import LaunchDescription
from swarm_ros.core.params import RUN_PARAMETERS
from swarm_ros.protocol.plan import MONITOR, ROBOT_BATCH, graph_plan

PACKAGE = "swarm_ros"
#: run parameters a launch argument may set ("" = leave it to the parameter file / the default): all of them
RUN_ARGUMENTS = {p.name: p for p in RUN_PARAMETERS}
KEY_ENV = "SWARM_ROS_RUN_KEY"  # as swarm_ros.protocol.runkey.KEY_ENV
MONITOR_GRACE = 30.0  # seconds the monitor has to write the run after the world's end (as swarm-ros run)


def _value(name: str, text: str) -> object:
    """A launch argument's text as the parameter's type (ROS parameters are typed)."""
    kind = RUN_ARGUMENTS[name].kind
    return kind(text) if kind in (int, float) else text


def graph(context) -> list:
    """The nodes, from the launch arguments' values."""
    share = get_package_share_directory(PACKAGE)
    arg = lambda name: LaunchConfiguration(name).perform(context)  # noqa: E731
    params_file = arg("params_file") or os.path.join(share, "config", "swarm_ros.yaml")
    run = {name: _value(name, arg(name)) for name in RUN_ARGUMENTS if arg(name)}
    processes = int(arg("processes"))
    monitor = {"out_dir": arg("out_dir")} if arg("out_dir") else {}
    enclaves = arg("enclaves")
    # SROS2: each node in its enclave <enclaves>/<node> (as swarm-ros run --enclaves)
    sros = lambda name: {"ros_arguments": ["--enclave", f"{enclaves}/{name}"]} if enclaves else {}  # noqa: E731
    nodes = []
    for name, executable, own in graph_plan(processes):  # the graph swarm-ros run starts, in its order
        batch = executable == ROBOT_BATCH  # respawned when it dies, as swarm-ros run restarts it
        params = [params_file, run, monitor if executable == MONITOR else {}, own]
        nodes.append(Node(package=PACKAGE, executable=executable, name=name, output="screen",
                          parameters=[p for p in params if p != {}], **({"respawn": True, "respawn_delay": 0.0}
                                                                         if batch else {}), **sros(name)))
    return nodes + end_of_run(world=nodes[-1], monitor=nodes[0])


def end_of_run(world, monitor) -> list:
    """Event handlers that end the launch with the run, as ``swarm-ros run`` ends.

    Without them ``ros2 launch`` would never return: it respawns a robot batch whatever its
    exit status, so the batches that leave after the outcome would come back and wait for a
    world that is gone. The run is over when the monitor has written it (exit 0), when the
    world fails (non-zero), or once both have exited (a monitor that died mid-run does not
    stop the swarm: the world runs on without it, as under ``swarm-ros run``). A monitor
    that has not written the run ``MONITOR_GRACE`` seconds after the world's end is given up on.
    """
    exited: dict[str, int] = {}

    def on_exit(name: str):
        def handle(event, context):
            exited[name] = event.returncode
            why = ", ".join(f"{node} exited with status {code}" for node, code in exited.items())
            if (name == "monitor" and event.returncode == 0) or (name == "world" and event.returncode != 0) \
                    or len(exited) == 2:
                return [EmitEvent(event=Shutdown(reason=f"the run is over: {why}"))]
            if name == "world":
                return [TimerAction(period=MONITOR_GRACE, actions=[EmitEvent(event=Shutdown(
                    reason=f"{why}, but the monitor did not write the run within {MONITOR_GRACE:g} s"))])]
            return None
        return handle

    return [RegisterEventHandler(OnProcessExit(target_action=world, on_exit=on_exit("world"))),
            RegisterEventHandler(OnProcessExit(target_action=monitor, on_exit=on_exit("monitor")))]


def generate_launch_description() -> LaunchDescription:
    share = get_package_share_directory(PACKAGE)
    return LaunchDescription([
        DeclareLaunchArgument("processes", default_value="2", description="robot-batch processes K"),
        DeclareLaunchArgument("params_file", default_value="",
                              description="parameter file (default: the package's config/swarm_ros.yaml)"),
        DeclareLaunchArgument("enclaves", default_value="",
                              description="SROS2: run each node in the enclave <enclaves>/<node> (e.g. /swarm_ros; "
                                          "untested here, docs/security.md)"),
        DeclareLaunchArgument("out_dir", default_value="",
                              description="the monitor's run directory (default: runs/<time>_<shape>_...)"),
        *[DeclareLaunchArgument(name, default_value="", description=f"run parameter {name} (default: the "
                                f"parameter file's, else the model's)") for name in RUN_ARGUMENTS],
        # discovery on this host, and Fast DDS's announcements as swarm-ros run sets them (config/fastdds.xml)
        SetEnvironmentVariable("ROS_AUTOMATIC_DISCOVERY_RANGE",
                               os.environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")),
        SetEnvironmentVariable("FASTRTPS_DEFAULT_PROFILES_FILE",
                               os.environ.get("FASTRTPS_DEFAULT_PROFILES_FILE",
                                              os.path.join(share, "config", "fastdds.xml"))),
        # the run's key, which its nodes tag their messages with (docs/security.md): a new one
        # for each launch unless SWARM_ROS_RUN_KEY is set
        SetEnvironmentVariable(KEY_ENV, os.environ.get(KEY_ENV) or secrets.token_hex(32)),
        OpaqueFunction(function=graph),
    ])
