"""Fixtures shared by the test modules (their helpers are in helpers.py), and the rule that every test module
says which kind it is: ``pytestmark = pytest.mark.unit`` or ``pytest.mark.process`` (pytest.ini)."""

from __future__ import annotations

import os
import shutil

import pytest
from helpers import SUBNET, _wait_until_up, disc_shape, ip_in

from swarm_ros.core import Shape, World

KINDS = ("unit", "process")


def pytest_collection_modifyitems(config, items):
    """A test module without exactly one kind marker is an error: ``pytest -m unit`` must leave none out."""
    for item in items:
        kinds = [m.name for m in item.iter_markers() if m.name in KINDS]
        if len(set(kinds)) != 1:
            raise pytest.UsageError(f"{item.nodeid}: mark the module with exactly one of {', '.join(KINDS)} "
                                    f"(got {sorted(set(kinds)) or 'none'})")


@pytest.fixture(scope="session")
def small_world() -> World:
    return World(radius=10)


@pytest.fixture(scope="session")
def small_disc(small_world: World) -> Shape:
    return disc_shape(small_world, 5.0)


@pytest.fixture(scope="session")
def small_ring(small_world: World) -> Shape:
    return disc_shape(small_world, 6.5, name="ring", hole=3.0)


@pytest.fixture
def two_hosts():
    """(namespace of host A, namespace of host B, host A's end of the veth); removed afterwards."""
    if shutil.which("ip") is None:
        pytest.skip("iproute2's 'ip' is not installed: cannot make network namespaces")
    if os.geteuid() != 0:
        pytest.skip("making network namespaces needs root")
    tag = os.getpid() % 10000
    a, b = f"swarm_ros_a{tag}", f"swarm_ros_b{tag}"
    made = ip_in("netns", "add", a)
    if made.returncode != 0:
        pytest.skip(f"cannot make a network namespace here: {made.stderr.strip()}")
    try:
        net = tag % 250
        steps = [("netns", "add", b),
                 ("link", "add", f"swra{tag}", "netns", a, "type", "veth", "peer", "name", f"swrb{tag}", "netns", b),
                 ("-n", a, "addr", "add", SUBNET.format(net, 1) + "/24", "dev", f"swra{tag}"),
                 ("-n", b, "addr", "add", SUBNET.format(net, 2) + "/24", "dev", f"swrb{tag}"),
                 ("-n", a, "link", "set", f"swra{tag}", "up"), ("-n", b, "link", "set", f"swrb{tag}", "up"),
                 ("-n", a, "link", "set", "lo", "up"), ("-n", b, "link", "set", "lo", "up")]
        for step in steps:
            done = ip_in(*step)
            if done.returncode != 0:
                pytest.skip(f"cannot set up the namespaces ({' '.join(step)}): {done.stderr.strip()}")
        _wait_until_up((a, f"swra{tag}"), (b, f"swrb{tag}"))
        yield a, b, f"swra{tag}"
    finally:
        for ns in (a, b):
            ip_in("netns", "del", ns)


@pytest.fixture(scope="session", autouse=True)
def _no_shared_memory_left_by_the_tests():
    """The tests kill processes on purpose (a launcher, nodes, in-process rclpy contexts left to the end of the
    session): at the end, remove the Fast DDS shared-memory files made during the session that no live process
    uses, as the launcher does after a run (nodes.shm.clean_shm). Files that were there before are not touched."""
    from pathlib import Path

    def segments() -> set[str]:
        return {str(p) for p in Path("/dev/shm").glob("fastrtps_*") if not p.name.endswith("_el")}

    before = segments()
    yield
    from swarm_ros.ros.shm import clean_shm

    clean_shm({f"{seg}_el" for seg in segments() - before})
