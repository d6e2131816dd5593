"""The ROS 2 side: world, robot-batch and monitor nodes, their messages and parameters.

Everything here is a thin shell over :mod:`swarm_ros.core`; the only logic of its own is
moving rows between messages and numpy arrays and keeping the ticks in lockstep.
"""
