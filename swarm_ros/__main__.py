"""``python -m swarm_ros``: the ``swarm-ros`` command line."""

from swarm_ros.app.main import entry

entry()
