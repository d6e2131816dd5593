"""The swarm's ROS 2 graph, as ``swarm-ros run`` starts it: a world (or S world shards), K robot batches and a
monitor.

    ros2 launch swarm_ros swarm.launch.py shape:=star processes:=2
    ros2 launch swarm_ros swarm.launch.py params_file:=/path/to/params.yaml out_dir:=runs/mine

Launch arguments: the run parameters (each overrides the parameter file when given), the
number of robot-batch processes, of world shards, the region cuts, the parameter file, the monitor's output
directory and the SROS2 enclaves.
The arguments are resolved as ``swarm-ros run`` resolves its flags, into one parameter file
in the launch's log directory that every node reads (``swarm_ros.app.supervision.launch_setup``).
The numba kernels are compiled once, before the nodes start, when their cache is empty. A node
process that dies is started again as ``swarm-ros run`` starts it again (``swarm_ros.app.supervision``):
a batch with its robots, the world from its checkpoint, the monitor from its bag. The launch
ends with the run: exit 0 once the monitor has written it, 1 when the run failed.
"""

from __future__ import annotations

import os
import secrets
import sys
from pathlib import Path

from ament_index_python.packages import get_package_share_directory
from launch.actions import (
    DeclareLaunchArgument,
    EmitEvent,
    ExecuteProcess,
    LogInfo,
    OpaqueFunction,
    RegisterEventHandler,
    SetEnvironmentVariable,
    TimerAction,
)
from launch.event_handlers import OnProcessExit, OnProcessStart, OnShutdown
from launch.events import Shutdown
from launch.logging import launch_config
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from launch import LaunchDescription
from swarm_ros.app.supervision import (
    END_GRACE,
    MONITOR_GRACE,
    RunEnded,
    launch_processes,
    launch_setup,
    parameter_arguments,
)
from swarm_ros.core.kernels import compiling_note, kernels_cached
from swarm_ros.core.params import RUN_PARAMETERS, WORLD_SHARDS, node_parameter
from swarm_ros.protocol.plan import PROCESSES
from swarm_ros.protocol.runkey import KEY_ENV
from swarm_ros.ros.dds import dds_defaults
from swarm_ros.ros.shm import clean_shm, shm_locks

PACKAGE = "swarm_ros"
SHM_SCAN_S = 0.5  #: seconds between looks at the shared-memory files the nodes hold (they open them at start-up)


def graph(context) -> list:
    """The nodes (after the kernels' compilation, if their cache is empty) and their supervision."""
    share = get_package_share_directory(PACKAGE)
    arg = lambda name: LaunchConfiguration(name).perform(context)
    processes = launch_processes(arg("processes"))
    shards = launch_processes(arg("world_shards"), WORLD_SHARDS)
    enclaves = arg("enclaves")
    setup = launch_setup(
        arg("params_file") or os.path.join(share, "config", "swarm_ros.yaml"),
        {p.name: arg(p.name) for p in RUN_PARAMETERS},
        arg("out_dir"),
        Path(launch_config.log_dir),
        processes,
        enclaves,
        arg("region_cuts"),
        shards,
    )
    supervisor = setup.supervisor
    plan = {name: (executable, own) for name, executable, own in setup.plan}
    names: dict[object, str] = {}  # each Node action started -> its node name
    running: set[object] = set()
    timers: list[TimerAction] = []

    def node(name: str) -> Node:
        executable, own = plan[name]
        incarnation = supervisor.incarnation(name)
        # A node's own values go as -p arguments: a dict in `parameters` became a /tmp/launch_params_* file that
        # launch_ros never removes (one per node and launch).
        own = {**own, **({"incarnation": incarnation} if incarnation else {})}
        action = Node(
            package=PACKAGE,
            executable=executable,
            name=name,
            output="screen",
            parameters=[str(setup.params)],
            ros_arguments=[
                *parameter_arguments(own),
                # SROS2: each node in its enclave <enclaves>/<node> (as swarm-ros run --enclaves)
                *(["--enclave", f"{enclaves}/{name}"] if enclaves else []),
            ],
        )
        names[action] = name
        return action

    def later(period: float, why: str, failed: bool) -> TimerAction:
        def fire(context):
            if failed:
                raise RunEnded(why)
            return [EmitEvent(event=Shutdown(reason=why))]

        for timer in timers:
            timer.cancel()
        timers[:] = [TimerAction(period=period, actions=[OpaqueFunction(function=fire)])]
        return timers[0]

    # The Fast DDS lock files each node holds in /dev/shm, seen every SHM_SCAN_S while nodes run: a SIGKILLed
    # node leaves its files, and the ports of the nodes it talked to, which are removed at the launch's end
    # (only files no live process uses), as swarm-ros run removes them (swarm_ros.ros.shm).
    pids: dict[object, int] = {}
    held: set[str] = set()
    scanning: list[bool] = [False]

    def scan(context):
        held.update(*(shm_locks(pids[action]) for action in running if action in pids))
        scanning[0] = bool(running) and not context.is_shutdown
        return [TimerAction(period=SHM_SCAN_S, actions=[OpaqueFunction(function=scan)])] if scanning[0] else []

    def on_start(event, context):
        if event.action in names:  # a node (not the kernels' compilation)
            running.add(event.action)
            pids[event.action] = event.pid
            if not scanning[0]:
                scanning[0] = True
                return [TimerAction(period=SHM_SCAN_S, actions=[OpaqueFunction(function=scan)])]
        return None

    def on_exit(event, context):
        name = names.get(event.action)
        if name is None or context.is_shutdown:
            return None
        running.discard(event.action)
        verdict = supervisor.exited(name, event.returncode)
        actions = [LogInfo(msg=f"swarm_ros: {verdict.note}")] if verdict.note else []
        if verdict.end:
            raise RunEnded(verdict.end)  # ros2 launch: "Caught exception in launch ...", every node stopped, exit 1
        if verdict.stop:
            return [*actions, EmitEvent(event=Shutdown(reason=verdict.stop))]
        if verdict.restart:
            actions.append(node(name))
        elif verdict.wait_for_monitor:
            actions.append(
                later(
                    MONITOR_GRACE,
                    f"the run ended, but the monitor did not write it within {MONITOR_GRACE:g} s",
                    failed=True,
                )
            )
        if supervisor.monitor_done:
            if running:
                actions.append(later(END_GRACE, "the monitor has written the run; stopping what is left", False))
            else:
                for timer in timers:
                    timer.cancel()
        return actions

    def at_shutdown(event, context):
        for path in setup.checkpoint.parent.glob(setup.checkpoint.name + "*"):  # a failed world's (the world
            path.unlink(missing_ok=True)  # removes its own when the run ends)
        clean_shm(held)  # what dead nodes left in /dev/shm: a live process's files stay

    nodes = [node(name) for name in plan]  # the graph swarm-ros run starts, in its order
    handlers = [
        RegisterEventHandler(OnProcessStart(on_start=on_start)),
        RegisterEventHandler(OnProcessExit(on_exit=on_exit)),
        RegisterEventHandler(OnShutdown(on_shutdown=at_shutdown)),
    ]
    if kernels_cached(setup.algorithm):
        return handlers + nodes
    # fill numba's cache of the run's algorithm once, here: every node would otherwise compile the same kernels at
    # the same time
    compiling = ExecuteProcess(
        cmd=[sys.executable, "-m", "swarm_ros.core.kernels", setup.algorithm], name="compile_kernels", output="screen"
    )

    def compiled(event, context):
        if event.returncode != 0:
            raise RunEnded(f"compiling the numba kernels failed (exit status {event.returncode})")
        return nodes

    return [
        *handlers,
        LogInfo(msg=f"swarm_ros: {compiling_note(setup.algorithm)}"),
        compiling,
        RegisterEventHandler(OnProcessExit(target_action=compiling, on_exit=compiled)),
    ]


def generate_launch_description() -> LaunchDescription:
    return LaunchDescription(
        [
            DeclareLaunchArgument("processes", default_value=str(PROCESSES.default), description=PROCESSES.help),
            DeclareLaunchArgument(
                "world_shards", default_value=str(WORLD_SHARDS.default), description=WORLD_SHARDS.help
            ),
            DeclareLaunchArgument(
                "region_cuts", default_value="", description=node_parameter("robot_batch", "region_cuts").help
            ),
            DeclareLaunchArgument(
                "params_file",
                default_value="",
                description="parameter file (default: the package's config/swarm_ros.yaml)",
            ),
            DeclareLaunchArgument(
                "enclaves",
                default_value="",
                description="SROS2: run each node in the enclave <enclaves>/<node> (e.g. /swarm_ros; "
                "untested here, docs/security.md)",
            ),
            DeclareLaunchArgument(
                "out_dir",
                default_value="",
                description="the monitor's run directory (default: runs/<time>_<shape>_...)",
            ),
            *[
                DeclareLaunchArgument(
                    p.name,
                    default_value="",
                    description=f"run parameter {p.name} (default: the parameter file's, else the model's)",
                )
                for p in RUN_PARAMETERS
            ],
            # DDS as swarm-ros run sets it, unless set (swarm_ros.ros.dds): discovery on this host, Fast DDS's
            # announcements (config/fastdds.xml) and its transports
            *[SetEnvironmentVariable(key, os.environ.get(key, value)) for key, value in dds_defaults().items()],
            # the run's key, which its nodes tag their messages with (docs/security.md): a new one
            # for each launch unless SWARM_ROS_RUN_KEY is set
            SetEnvironmentVariable(KEY_ENV, os.environ.get(KEY_ENV) or secrets.token_hex(32)),
            OpaqueFunction(function=graph),
        ]
    )
