"""The console scripts (``swarm-ros`` and the nodes' ``world``, ``world_shard``, ``robot_batch``, ``monitor``,
which ``ros2 run`` and ``ros2 launch`` start): Ctrl-C is answered in one line from the first instant.

Importing the command line takes a few tenths of a second (numpy, argparse, the package);
a Ctrl-C in that time would otherwise end in a traceback of whatever was being imported.
This module imports nothing of its own before it can catch it: not even the exit status, whose module
imports the standard library's ``signal`` (an enum built at import, long enough for a Ctrl-C to land in it:
CI saw one there). It is imported once a Ctrl-C has been caught.
"""

from __future__ import annotations

import importlib
import sys


def entry() -> None:
    """Import the command line and run it (:func:`swarm_ros.app.cli.entry`); a Ctrl-C while importing it ends
    with ``swarm-ros: interrupted`` and exit status 130, as one during a command does."""
    try:
        from swarm_ros.app.cli import entry as run
    except KeyboardInterrupt:
        print("swarm-ros: interrupted", file=sys.stderr)
        sys.exit(_interrupted())
    run()  # its own handling of Ctrl-C starts at its first line (swarm_ros.app.cli.main)


def _node(module: str) -> None:
    """Import the node ``module`` and run it; a Ctrl-C before its own handling is in place (while Python
    imports it, or while ROS 2 starts) ends with one line and exit status 130, as one later does."""
    try:
        code = importlib.import_module(f"swarm_ros.nodes.{module}").main()
    except KeyboardInterrupt:
        print(f"{module}: interrupted while starting", file=sys.stderr)
        code = _interrupted()
    sys.exit(code)


def _interrupted() -> int:
    """The exit status of an interrupted command, imported only now (see the module's doc)."""
    from swarm_ros.core.signals import EXIT_INTERRUPTED

    return EXIT_INTERRUPTED


def world() -> None:
    _node("world")


def world_shard() -> None:
    _node("world_shard")


def robot_batch() -> None:
    _node("robot_batch")


def monitor() -> None:
    _node("monitor")
