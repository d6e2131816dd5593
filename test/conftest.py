"""Fixtures shared by the test modules (the helpers they share are modules by topic: runs.py, recordings.py,
graph_runs.py, central_fakes.py, netns.py, layering.py, waiting.py, bagcheck.py, ros2_tools.py, isolation.py,
bad_inputs.py), and the rule that every test module says which kind it is: ``pytestmark = pytest.mark.unit`` or
``pytest.mark.process`` (pytest.ini), a unit test kept in its process."""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
from pathlib import Path

import pytest
from bad_inputs import make_fixtures
from isolation import children_refused
from netns import SUBNET, _wait_until_up, ip_in
from runs import disc_shape

from swarm_ros.core import Shape, World
from swarm_ros.core.kernels import drop_stale

KINDS = ("unit", "process")


def pytest_configure(config):
    """Before any test process loads a kernel: drop the core's kernel caches older than its newest kernel
    module (numba would run a cached caller with the code of a callee edited since: swarm_ros.core.kernels).

    And Ctrl-C as a terminal gives it: a suite started in the background by a script (``pytest &`` in a shell
    without job control, as a batch job may be) inherits SIGINT ignored, and so would every process a test starts
    (Python keeps an ignored SIGINT ignored): the tests of Ctrl-C would see their commands never interrupted."""
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    if not hasattr(config, "workerinput"):  # the controller, before xdist starts its workers
        dropped = drop_stale()
        if dropped:
            print(f"swarm_ros: dropped {dropped} stale kernel cache files; the kernels compile again")


def pytest_collection_modifyitems(config, items):
    """A test module without exactly one kind marker is an error: ``pytest -m unit`` must leave none out."""
    for item in items:
        kinds = [m.name for m in item.iter_markers() if m.name in KINDS]
        if len(set(kinds)) != 1:
            raise pytest.UsageError(
                f"{item.nodeid}: mark the module with exactly one of {', '.join(KINDS)} "
                f"(got {sorted(set(kinds)) or 'none'})"
            )


@pytest.fixture(scope="session", autouse=True)
def _fonts_found_once():
    """matplotlib lists the system's fonts with fc-list (a child process) the first time it loads without a font
    cache: done here, once a session, so that a unit test that draws does not do it."""
    import matplotlib.font_manager  # noqa: F401


@pytest.fixture(autouse=True)
def _a_unit_test_stays_in_its_process(request):
    """What ``unit`` promises (pytest.ini), enforced: a unit test that starts a child process or a ROS 2 context
    fails, naming what it did (:func:`isolation.children_refused`)."""
    if request.node.get_closest_marker("unit") is None:
        yield
        return
    with children_refused() as attempts:
        yield
    if attempts:
        pytest.fail(f"a unit test {attempts[0]}: move it to a module marked process (pytest.ini)", pytrace=False)


@pytest.fixture(scope="module")
def bad_input_files(tmp_path_factory) -> Path:
    """Every file docs/bad_input.md names, made once a module; each row copies those it names
    (:func:`bad_inputs.fixtures_for`)."""
    d = tmp_path_factory.mktemp("bad-input-files")
    make_fixtures(d)
    return d


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
    """(namespace of host A, namespace of host B, host A's end of its veth); removed afterwards."""
    with lan(2) as (hosts, links):
        yield hosts[0], hosts[1], links[0]


@pytest.fixture
def four_hosts():
    """([namespaces of hosts 0..3], [each host's end of its veth]) on one switch; removed afterwards."""
    with lan(4) as made:
        yield made


@contextlib.contextmanager
def lan(count: int):
    """``count`` hosts, each a network namespace with one veth (address 10.231.<net>.<i + 1>) whose other end is a
    port of a bridge in a namespace of its own (the switch). Skips where namespaces cannot be made. Only this
    test's own namespaces are touched (named after its process id); all are removed at the end."""
    if shutil.which("ip") is None:
        pytest.skip("iproute2's 'ip' is not installed: cannot make network namespaces")
    if os.geteuid() != 0:
        pytest.skip("making network namespaces needs root")
    tag = os.getpid() % 10000
    hosts = [f"swarm_ros_{chr(ord('a') + i)}{tag}" for i in range(count)]
    switch = f"swarm_ros_s{tag}"
    links = [f"swr{chr(ord('a') + i)}{tag}" for i in range(count)]
    made = ip_in("netns", "add", switch)
    if made.returncode != 0:
        pytest.skip(f"cannot make a network namespace here: {made.stderr.strip()}")
    try:
        net = tag % 250
        steps = [("-n", switch, "link", "add", "br0", "type", "bridge"), ("-n", switch, "link", "set", "br0", "up")]
        for i, (ns, dev) in enumerate(zip(hosts, links)):
            port = f"sws{chr(ord('a') + i)}{tag}"
            steps += [
                ("netns", "add", ns),
                ("link", "add", dev, "netns", ns, "type", "veth", "peer", "name", port, "netns", switch),
                ("-n", switch, "link", "set", port, "master", "br0"),
                ("-n", switch, "link", "set", port, "up"),
                ("-n", ns, "addr", "add", SUBNET.format(net, i + 1) + "/24", "dev", dev),
                ("-n", ns, "link", "set", dev, "up"),
                ("-n", ns, "link", "set", "lo", "up"),
            ]
        for step in steps:
            done = ip_in(*step)
            if done.returncode != 0:
                pytest.skip(f"cannot set up the namespaces ({' '.join(step)}): {done.stderr.strip()}")
        _wait_until_up(*zip(hosts, links))
        yield hosts, links
    finally:
        for ns in (*hosts, switch):
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
