"""The monitor node alone, fed by this test as a participant on the run's ROS domain.

No world or batches: the test publishes what they would (or what they would not), and
checks what the monitor makes of it.
"""

from __future__ import annotations

import subprocess
import sys
from contextlib import contextmanager
from pathlib import Path

import pytest

from swarm_ros.app.param_file import params_yaml
from swarm_ros.app.processes import DomainLock, node_command, node_env
from swarm_ros.core.params import Settings
from swarm_ros.protocol.runkey import KEY_ENV

pytest.importorskip("rclpy")

pytestmark = pytest.mark.process

PY = sys.executable


@contextmanager
def _peer(domain: int, monkeypatch):
    """A node of this process on ``domain``, discovering as the run's nodes do."""
    import rclpy
    from rclpy.context import Context
    from rclpy.node import Node

    from swarm_ros.ros.dds import dds_defaults

    for key, value in dds_defaults().items():
        monkeypatch.setenv(key, value)
    context = Context()
    rclpy.init(args=[], context=context, domain_id=domain)
    try:
        yield Node("test_peer", context=context, start_parameter_services=False)
    finally:
        rclpy.shutdown(context=context)


@contextmanager
def _monitor(tmp_path: Path, settings: Settings):
    """A monitor process on a domain of its own: (the process, its domain, the run's key)."""
    out = tmp_path / "run"
    params = tmp_path / "params.yaml"
    params.write_text(params_yaml(settings, {"monitor": {"out_dir": str(out), "record": False}}))
    lock = DomainLock()
    log = open(tmp_path / "monitor.log", "w")
    env = node_env(lock.domain_id, tmp_path)
    proc = subprocess.Popen(node_command("monitor", params, "monitor"), env=env, stdout=log, stderr=subprocess.STDOUT)
    try:
        yield proc, lock.domain_id, env[KEY_ENV].encode()
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.wait()
        log.close()
        lock.close()


def test_a_monitor_whose_robots_never_come_fails_once_the_world_has_ended_instead_of_waiting(tmp_path, monkeypatch):
    # What a monitor sees when the robots' messages are lost and the world has ended: without a
    # launcher to stop it, it used to wait for them forever.
    from diagnostic_msgs.msg import DiagnosticArray

    from swarm_ros.ros import graph as msgs
    from swarm_ros.ros.auth import Signer

    with (
        _monitor(tmp_path, Settings(shape="star", robots=60)) as (proc, domain, key),
        _peer(domain, monkeypatch) as node,
    ):
        status = Signer(node, key, "world").publisher(DiagnosticArray, msgs.STATUS, msgs.LATCHED_QOS)
        status.publish(msgs.status_message(40, "complete", "complete at tick 40"))
        try:
            code = proc.wait(timeout=60)
        except subprocess.TimeoutExpired:
            code = None
    log = (tmp_path / "monitor.log").read_text()
    assert code == 1, log[-2000:]
    assert "the world ended the run ('complete') at tick 40, but the robots' messages reached the monitor only" in log
    assert not (tmp_path / "run" / "summary.json").exists()
