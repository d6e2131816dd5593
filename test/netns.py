"""Hosts on one machine: Linux network namespaces joined by veth links to a bridge."""

from __future__ import annotations

import json
import os
import subprocess

from waiting import wait_for

SUBNET = "10.231.{}.{}"


def host_env() -> dict[str, str]:
    """This process's environment without any ROS or DDS setting (an earlier test may have left some):
    what a process on another host starts from."""
    return {k: v for k, v in os.environ.items() if not k.startswith(("ROS_", "FASTDDS_", "FASTRTPS_", "RMW_"))}


def ip_in(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(["ip", *args], capture_output=True, text=True, timeout=30)


def _wait_until_up(*links: tuple[str, str], limit: float = 10.0) -> None:
    """Wait until each (namespace, device) reports operstate UP, with its carrier.

    The kernel reports a veth's carrier (operstate UP) asynchronously, after both ends are set
    up; it usually takes milliseconds. Fast DDS lists a host's interfaces once, when a
    participant starts, so a node must not start before its interface is really up.
    """

    def states() -> dict[str, str]:
        return {
            f"{ns}/{dev}": json.loads(ip_in("-n", ns, "-j", "link", "show", "dev", dev).stdout or "[{}]")[0].get(
                "operstate", "absent"
            )
            for ns, dev in links
        }

    try:
        wait_for(lambda: set(states().values()) == {"UP"}, limit, f"the veth pair {links} coming up")
    except AssertionError as exc:
        raise AssertionError(f"{exc}: operstate {states()}") from None
