"""The application: the ``swarm-ros`` command line, the graph's launcher and supervisor, experiments, reports.

The top layer: it may import every other layer, and nothing imports it.
"""
