"""The DDS settings of a run's processes on one host (the launcher's and its nodes')."""

from __future__ import annotations

import os

from swarm_ros.core.resources import data_dir

PROFILE_FILE = "fastdds.xml"  #: in the package's config folder


def dds_defaults() -> dict[str, str]:
    """Environment variables a run's processes get unless the user set them.

    Discovery stays on this host (``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``), messages go over
    UDP (``FASTDDS_BUILTIN_TRANSPORTS=UDPv4``: see below), and Fast DDS loads
    ``config/fastdds.xml``, whose participants keep announcing themselves for their first
    seconds, so processes that start a few seconds apart find each other at once (the file
    says why).
    """
    defaults = {
        "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
        # UDP on the loopback, not shared memory: a process SIGKILLed while it hands a message to another's
        # shared-memory port can leave that port blocked, and the other process then receives nothing
        # (seen here once in 30 kills of bench_faults: the world stopped hearing every peer; Fast DDS 2.14,
        # eProsima/Fast-DDS#5469). A process killed on UDP loses only its own sockets. Cost: about
        # 5% of the star's run (docs/faults.md). Set it to DEFAULT for shared memory. With the LOCALHOST range above,
        # rmw_fastrtps picks the transports itself (UDP and shared memory) and this is not applied: it holds only for
        # a SUBNET range (docs/faults.md, "Not in effect on one host").
        "FASTDDS_BUILTIN_TRANSPORTS": "UDPv4",
    }
    try:
        defaults["FASTRTPS_DEFAULT_PROFILES_FILE"] = str(data_dir("config") / PROFILE_FILE)
    except FileNotFoundError:
        pass  # a broken install: Fast DDS's defaults still work, only slower to discover
    return defaults


def apply_dds_defaults(env: dict[str, str] | os._Environ = os.environ) -> None:
    """Set :func:`dds_defaults` in ``env`` where unset (in this process: before rclpy creates a participant)."""
    for key, value in dds_defaults().items():
        env.setdefault(key, value)
