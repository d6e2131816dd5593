"""A node forked by ``swarm-ros run`` (swarm_ros/app/forking.py) is what ``python -m`` would have started: its own
session, its own environment and command line, stdin from /dev/null, output in its log, none of the launcher's
files, and an exit status read as subprocess reads one. A stand-in node module reports what it finds."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from waiting import wait_for

from swarm_ros.app.forking import Forked, forkable, start_node

pytestmark = pytest.mark.process

NODE = textwrap.dedent(
    """
    import ctypes, json, os, signal, sys, time

    def main(argv):
        what = argv[1]
        if what == "report":
            print(json.dumps({
                "argv": argv,
                "env": os.environ.get("FORK_TEST"),
                "launcher_only": os.environ.get("LAUNCHER_ONLY"),
                "session_leader": os.getsid(0) == os.getpid(),
                "group_leader": os.getpgid(0) == os.getpid(),
                "stdin": os.readlink("/proc/self/fd/0"),
                "fds": sorted(int(fd) for fd in os.listdir("/proc/self/fd")),
                "cmdline": open("/proc/self/cmdline", "rb").read().rstrip(b"\\0").decode(),
                "sigterm_default": signal.getsignal(signal.SIGTERM) == signal.SIG_DFL,
                "program": ctypes.c_char_p.in_dll(ctypes.CDLL(None), "program_invocation_name").value.decode(),
            }))
            return 0
        if what == "code":
            return int(argv[2])
        if what == "exit-text":
            raise SystemExit("cannot go on: a reason")
        if what == "raise":
            raise ValueError("a bug in the node")
        if what == "sleep":
            print("sleeping", flush=True)
            time.sleep(60)
        return 9
    """
)


@pytest.fixture
def node_module(tmp_path, monkeypatch):
    (tmp_path / "fork_stand_in.py").write_text(NODE)
    monkeypatch.syspath_prepend(str(tmp_path))
    return "fork_stand_in"


def _fork(module: str, args: list[str], log: Path, env: dict[str, str] | None = None) -> Forked:
    with open(log, "ab") as f:
        return Forked(module, args, env if env is not None else {"FORK_TEST": "yes"}, f.fileno())


def test_a_forked_node_starts_as_python_dash_m_would(node_module, tmp_path, monkeypatch):
    monkeypatch.setenv("LAUNCHER_ONLY", "1")  # in this process's environment, not in the one given
    log = tmp_path / "node.log"
    held = open(tmp_path / "held", "w")  # a file of the launcher's (its domain lock, another node's log)
    held_fd = held.fileno()
    try:
        child = _fork(node_module, ["report", "--ros-args", "-r", "__node:=x y"], log)
        assert child.wait(timeout=30) == 0
    finally:
        held.close()
    seen = json.loads(log.read_text())
    assert seen["argv"] == [node_module, "report", "--ros-args", "-r", "__node:=x y"]
    assert seen["env"] == "yes" and seen["launcher_only"] is None
    assert seen["session_leader"] and seen["group_leader"]
    assert seen["stdin"] == "/dev/null"
    assert seen["fds"][:3] == [0, 1, 2] and held_fd not in seen["fds"]
    assert seen["sigterm_default"]
    assert seen["program"] == os.path.basename(sys.executable)  # ROS 2 names its log files by it
    # ps shows the node's own command, quoted as a shell would take it
    assert seen["cmdline"] == f"{sys.executable} -m {node_module} report --ros-args -r '__node:=x y'"


@pytest.mark.parametrize(
    "args,code,logged",
    [
        (["code", "0"], 0, ""),
        (["code", "3"], 3, ""),
        (["exit-text"], 1, "cannot go on: a reason"),
        (["raise"], 1, "ValueError: a bug in the node"),
    ],
)
def test_a_forked_nodes_exit_status_and_errors_are_those_of_its_own_process(node_module, tmp_path, args, code, logged):
    log = tmp_path / "node.log"
    child = _fork(node_module, args, log)
    assert child.wait(timeout=30) == code
    assert child.returncode == code and child.poll() == code
    assert logged in log.read_text()


def test_a_forked_node_killed_by_a_signal_reads_as_popen_reads_it(node_module, tmp_path):
    log = tmp_path / "node.log"
    child = _fork(node_module, ["sleep"], log)
    assert child.poll() is None and child.wait(timeout=0.05) is None
    wait_for(lambda: "sleeping" in log.read_text(), 30, "the node's main to run")
    os.killpg(child.pid, signal.SIGTERM)  # its own process group, as processes.stop signals it
    assert child.wait(timeout=30) == -signal.SIGTERM


def test_only_a_node_module_run_with_this_python_is_forked():
    assert forkable([sys.executable, "-m", "swarm_ros.nodes.world", "--ros-args"]) == "swarm_ros.nodes.world"
    assert forkable([sys.executable, "-m", "swarm_ros.core.kernels"]) is None
    assert forkable(["/usr/bin/python3", "-m", "swarm_ros.nodes.world"]) is None
    assert forkable([sys.executable, "script.py"]) is None


def _fresh_python(code: str) -> str:
    """What ``code`` prints in a fresh interpreter (this one has loaded rclpy and Rerun)."""
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    return done.stdout.strip()


def test_no_fork_once_rclpy_or_rerun_is_loaded_or_off_the_main_thread():
    """Each import that starts threads ends forking, and so does another thread."""
    assert (
        _fresh_python(
            "import sys, threading; from swarm_ros.app.forking import can_fork; seen = [can_fork()]; "
            "t = threading.Thread(target=lambda: seen.append(can_fork())); t.start(); t.join(); "
            "import rerun; seen.append(can_fork()); print(seen)"
        )
        == "[True, False, False]"
    )
    pytest.importorskip("rclpy")
    assert _fresh_python("import rclpy; from swarm_ros.app.forking import can_fork; print(can_fork())") == "False"


def test_a_command_that_may_not_be_forked_is_executed(tmp_path):
    """Another command than a node module's: subprocess, in a session of its own, as before."""
    with open(tmp_path / "log", "ab") as f:
        proc = start_node([sys.executable, "-c", "import os; print(os.getsid(0) == os.getpid())"], {}, f)
    assert isinstance(proc, subprocess.Popen)
    assert proc.wait(timeout=30) == 0
    assert (tmp_path / "log").read_text().strip() == "True"


def test_the_launcher_imports_neither_rclpy_nor_rerun_before_it_forks():
    """Its imports up to the fork leave it free to fork (else every node would start with ``python -m``)."""
    code = (
        "import sys; import swarm_ros.app.launcher, swarm_ros.app.commands, swarm_ros.app.forking as f; "
        "from swarm_ros.core import Shape; from swarm_ros.core.params import RunParams; "
        "s = Shape.load('star'); f.preload(s, RunParams(robots=s.patches)); print(f.can_fork(), 'rclpy' in sys.modules)"
    )
    assert _fresh_python(code) == "True False"


PRELOADED = (
    "import os, sys; import swarm_ros.app.forking as f; "
    "from swarm_ros.core import Shape; from swarm_ros.core.params import RunParams; "
    "s = Shape.load('star'); f.preload(s, RunParams(robots=s.patches), ['world']); "
    "lttng = f._lttng_library(); "
)


def test_rclpy_preloaded_for_the_nodes_leaves_forking_open_until_ros_starts():
    """The node modules, rclpy and the type support of their messages and services loaded before the fork (each
    node then skips their load); LTTng's fork hooks found where rclpy loaded LTTng; a started ROS context (DDS
    threads) ends forking."""
    pytest.importorskip("rclpy")
    code = PRELOADED + (
        "from sensor_msgs.msg import PointCloud2; from rcl_interfaces.srv import GetParameters; "
        "seen = ['rclpy' in sys.modules, f.can_fork(), lttng is None or f._Preloaded.lttng is not None, "
        "PointCloud2.__class__._TYPE_SUPPORT is not None and GetParameters.__class__._TYPE_SUPPORT is not None]; "
        "import rclpy; from rclpy.context import Context; c = Context(); rclpy.init(context=c); "
        "n = rclpy.create_node('fork_test', context=c); seen.append(f.can_fork()); print(seen)"
    )
    assert _fresh_python(code) == "[True, True, True, True, False]"


def test_a_node_module_that_cannot_be_preloaded_is_left_to_the_node_to_report():
    """An import that fails in the launcher is not the launcher's error: preload gives up quietly, and each node
    then imports (and fails) on its own, in its own log."""
    code = (
        "import sys; import swarm_ros.app.forking as f; "
        "from swarm_ros.core import Shape; from swarm_ros.core.params import RunParams; "
        "s = Shape.load('star'); f.preload(s, RunParams(robots=s.patches), ['no_such_module_for_the_fork_test']); "
        "print(f._Preloaded.threads is None, f.can_fork())"
    )
    assert _fresh_python(code) == "True True"


def test_a_node_forked_after_rclpy_was_loaded_starts_ros_and_lttngs_threads_again(node_module, tmp_path):
    """Forked with rclpy (and so LTTng) loaded: the child has LTTng's listener threads again (its fork hooks ran)
    and starts a ROS context and a node of its own; the parent can go on forking."""
    pytest.importorskip("rclpy")
    child = textwrap.dedent(
        """
        import json, os, rclpy
        from rclpy.context import Context

        def main(argv):
            before = len(os.listdir("/proc/self/task"))
            c = Context()
            rclpy.init(context=c, domain_id=int(argv[1]))
            node = rclpy.create_node("forked_child", context=c)
            print(json.dumps({"threads_before_ros": before, "node": node.get_name(),
                              "threads_with_ros": len(os.listdir("/proc/self/task"))}))
            node.destroy_node()
            rclpy.shutdown(context=c)
            return 0
        """
    )
    (tmp_path / "fork_ros_child.py").write_text(child)
    code = PRELOADED + (
        f"sys.path.insert(0, {str(tmp_path)!r}); "
        "listeners = f._native_threads(); "
        f"log = os.open({str(tmp_path / 'log')!r}, os.O_WRONLY | os.O_CREAT); "
        "codes = [f.Forked('fork_ros_child', ['77'], dict(os.environ), log).wait(60) for _ in range(2)]; "
        "print(codes, f.can_fork(), lttng is not None)"
    )
    codes, can, has_lttng = _fresh_python(code).rsplit(" ", 2)
    assert codes == "[0, 0]" and can == "True"
    reports = [json.loads(line) for line in (tmp_path / "log").read_text().splitlines() if line.startswith("{")]
    assert [r["node"] for r in reports] == ["forked_child"] * 2
    for r in reports:
        assert r["threads_with_ros"] > r["threads_before_ros"]  # DDS started in the child
        if has_lttng == "True":  # main thread and LTTng's two listeners, started again by its fork hook
            assert r["threads_before_ros"] >= 3


SIGNAL_IN_FORK = textwrap.dedent(
    """
    import json, logging, os, signal, sys, threading, time
    import swarm_ros.app.forking as forking
    from swarm_ros.app.forking import Forked

    if sys.argv[1:] == ["rclpy"]:  # as the launcher forks: rclpy loaded, LTTng's fork hooks around each fork
        from swarm_ros.core import Shape
        from swarm_ros.core.params import RunParams

        shape = Shape.load("star")
        forking.preload(shape, RunParams(robots=shape.patches), ["robot_batch"])
        assert forking.can_fork()

    def interrupt(signum, frame):  # as swarm-ros run's own SIGTERM handler does
        raise KeyboardInterrupt

    signal.signal(signal.SIGTERM, interrupt)
    # A thread that blocks no signal, as OpenBLAS's pool: it takes a SIGTERM the forking thread blocks, and
    # Python then runs the handler in the forking thread, at its next bytecode, wherever that is.
    threading.Thread(target=time.sleep, args=(3600,), daemon=True).start()
    moment = []
    for hook in ("before", "after_in_parent"):  # Python's at-fork hooks: inside os.fork, around fork()
        os.register_at_fork(**{hook: lambda hook=hook: moment == [hook] and os.kill(os.getpid(), signal.SIGTERM)})
    log = os.open(os.devnull, os.O_WRONLY)
    outcomes = []
    for hook in ["before", "after_in_parent"] * 20:
        moment[:] = [hook]
        try:
            Forked("fork_stand_in", ["code", "0"], {}, log)
            time.sleep(0.05)  # a signal handled late is still handled, here
            outcomes.append("lost")
        except KeyboardInterrupt:
            outcomes.append("handled")
    moment.clear()
    last = Forked("fork_stand_in", ["code", "0"], {}, log)  # hangs if a fork left LTTng's locks taken
    took = []  # logging's module lock, from another thread: free unless a fork's hook lost its release
    def take():
        took.append(logging._lock.acquire(timeout=5))
        if took[0]:
            logging._lock.release()

    t = threading.Thread(target=take, daemon=True)
    t.start()
    t.join()
    print(json.dumps({"outcomes": outcomes, "last": last.wait(timeout=60), "took": took}))
    """
)


@pytest.mark.parametrize("loaded", ["", "rclpy"])
def test_a_sigterm_while_the_launcher_forks_is_handled_after_the_fork_and_leaves_no_lock_taken(
    node_module, tmp_path, loaded
):
    """A SIGTERM whose handler raised inside os.fork was lost: Python's at-fork hooks swallow the exception (and
    logging's lock stayed taken; the launcher's next thread that logged hung). Raised between LTTng's fork hooks,
    with rclpy loaded, it left LTTng's locks taken and the launcher's next fork hung (CI saw it under a signal
    storm). Blocking the signal in the forking thread did not keep it out: another thread took it. Sent at both
    ends of the fork, from a thread that blocks nothing, each one is handled after the fork, and nothing hangs."""
    if loaded:
        pytest.importorskip(loaded)
    script = tmp_path / "signal_in_fork.py"
    script.write_text(SIGNAL_IN_FORK)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(tmp_path), *sys.path])}
    command = [sys.executable, str(script), *([loaded] if loaded else [])]
    done = subprocess.run(command, capture_output=True, text=True, timeout=300, env=env)
    assert done.returncode == 0, done.stderr
    seen = json.loads(done.stdout)
    assert seen["outcomes"] == ["handled"] * 40, done.stderr
    assert seen["last"] == 0 and seen["took"] == [True], done.stderr
