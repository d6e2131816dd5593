"""A third shape-formation algorithm, as small as one can be, to show that an algorithm is a plug-in: a robot
wanders one patch a tick in a random direction of eight, and stops for good on the first free patch of the shape
next to a stopped robot (the four seeds first). Its state is the study's model's (core.state.SwarmState), so the
study's summary, run directory and recording serve it as they are; it supplies its rule and nothing else.

Registered when imported: ``SWARM_ROS_ALGORITHMS=random_walk`` with this folder's parent on ``PYTHONPATH``.
"""

from swarm_ros.core.algorithm import Algorithm, register

NAME = "random-walk"

register(
    Algorithm(
        name=NAME,
        max_ticks=20_000,
        bytes_per_robot=250,  # the study's model's state, less its scratch
        kernel_dir="",  # no kernels of its own
        compile_seconds=0,
        run_dir_setting="walk",
        progress_unit="patch",
        progress_what="localized",
        no_removal="it has no graph",
        no_world_shards="it has no graph",
        engine="random_walk.engine:RandomWalk",
        summary="swarm_ros.core.run_result:summary_of",
        check_shape="random_walk.engine:check_shape",
        recording="swarm_ros.artifacts.recording_options:open_recording",
        write_run="swarm_ros.artifacts.run_dir:write_simulation",
        print_summary="swarm_ros.app.summary_print:print_summary",
    )
)
