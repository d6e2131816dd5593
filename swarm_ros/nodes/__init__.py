"""The node executables: world, world_shard, robot_batch, monitor, kilobot_world, kilobot_batch, kilobot_monitor.

Each is a thin shell: it wires ROS callbacks to the plain classes of the protocol layer and
the core, and owns no rule of its own.
"""
