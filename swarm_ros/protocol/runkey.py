"""The run's secret key, which its nodes tag their messages with (:mod:`swarm_ros.ros.auth`).

It reaches the nodes in their environment (``SWARM_ROS_RUN_KEY``), never over the network:
``swarm-ros run`` and the launch file make a new one for each run unless the variable is
set (set it yourself, to the same value everywhere, for nodes started by hand or on
several hosts). Light on purpose: the launcher imports it without rclpy.
"""

from __future__ import annotations

import os
import secrets

from swarm_ros.core.errors import ConfigError

KEY_ENV = "SWARM_ROS_RUN_KEY"
MIN_KEY_CHARS = 16
#: The key of nodes started without SWARM_ROS_RUN_KEY (``ros2 run`` by hand): it is public, so
#: anything on the domain can tag its own messages. The nodes say so when they start.
PUBLIC_KEY = b"swarm_ros: no run key given, anybody can vouch"


def run_key(env: dict[str, str] | os._Environ = os.environ) -> tuple[bytes, bool]:
    """(key, whether it is secret): SWARM_ROS_RUN_KEY, or the public key if it is unset or empty.

    Raises:
        ConfigError: the variable is set but shorter than ``MIN_KEY_CHARS`` characters.
    """
    text = env.get(KEY_ENV, "")
    if not text:
        return PUBLIC_KEY, False
    if len(text) < MIN_KEY_CHARS:
        raise ConfigError(
            f"{KEY_ENV} must have at least {MIN_KEY_CHARS} characters (it has {len(text)}); "
            f"make one with: python3 -c 'import secrets; print(secrets.token_hex(32))'"
        )
    return text.encode(), True


def new_key() -> str:
    """A fresh run key (256 random bits, hex)."""
    return secrets.token_hex(32)


def with_run_key(env: dict[str, str]) -> dict[str, str]:
    """``env`` with a run key: the one it has (checked), else a new one.

    Raises:
        ConfigError: the key it has is too short.
    """
    run_key(env)
    if not env.get(KEY_ENV):
        env[KEY_ENV] = new_key()
    return env
