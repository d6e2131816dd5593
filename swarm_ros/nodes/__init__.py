"""The node executables: world, world_shard, robot_batch, monitor: one set for every algorithm.

Each executable (``world.py``, ...) makes its rclpy node, reads its parameters and runs the node class the run's
algorithm supplies for its role (:mod:`swarm_ros.nodes.roles`): ``darr_niazi/`` holds the study's model's world and
monitor; ``central/`` those of every algorithm whose world is one process holding
every robot (Rubenstein et al.'s, a plug-in's); ``robot_batch.py`` the batch of every algorithm. A node class is a
thin shell: it wires ROS callbacks to the plain classes of
the protocol layer and the core, and owns no rule of its own.
"""
