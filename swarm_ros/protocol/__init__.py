"""The contract between the graph's processes, as data and plain code (numpy, no rclpy).

Row layouts and their codecs, the check of every inbound message kind, the run's states,
the run key, and the world's coordination of the lockstep.
"""
