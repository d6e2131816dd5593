"""Operator tools over a running or recorded graph: ``swarm-ros topics``, ``swarm-ros replay``, the progress display."""
