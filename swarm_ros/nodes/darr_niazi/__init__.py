"""The study's model's node classes (darr-niazi): what the world, world_shard, robot_batch and monitor
executables run for its run."""
