"""``python -m swarm_ros``: the ``swarm-ros`` command line."""

from swarm_ros.app.cli import entry

entry()
