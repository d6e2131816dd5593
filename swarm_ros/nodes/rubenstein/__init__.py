"""The rubenstein algorithm's node classes: what the world, robot_batch and monitor executables run for its run."""
