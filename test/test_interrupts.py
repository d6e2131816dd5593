"""SIGTERM (what a service manager or `kill` sends) to simulate and experiment: out within 5 s, nothing lost.

Ctrl-C (SIGINT) is covered for `run` in test_ros_graph.py and for `experiment` in
test_experiment.py; in-process interrupts of `simulate` in test_recording.py.
"""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from graph_runs import (
    alive,
    children_of,
    descendants_of,
    processes_mentioning,
    run_processes,
    shm_group,
    shm_left,
    wait_ticks_recorded,
)
from recordings import Recording, rrd_verify
from runs import small_config
from waiting import wait_for

import swarm_ros
from swarm_ros.app.results_file import read_results
from swarm_ros.ros.shm import in_use, shm_locks

pytestmark = pytest.mark.process
#: seconds from a signal to the exit, at most: 1-2 s on a quiet machine, 5.7 s seen in CI beside a ROS test on a slow
#: day (a machine half as fast must pass too); each of these commands, left alone, goes on for minutes
PROMPT_S = 20

PY = sys.executable
PACKAGE = str(Path(swarm_ros.__file__).parent)  # a frame in here is swarm_ros's own code


def _wait_for(predicate, timeout: float = 120) -> None:
    """:func:`waiting.wait_for`, with this module's usual bound."""
    wait_for(predicate, timeout, "the condition the test waits for")


def test_sigterm_to_simulate_writes_an_interrupted_run_directory(tmp_path):
    out = tmp_path / "run"
    # crowding 'disc' at vision 3 nearly freezes the swarm at this density: a long run (docs/model.md)
    proc = subprocess.Popen(
        [
            PY,
            "-m",
            "swarm_ros",
            "simulate",
            "--shape",
            "star",
            "--vision",
            "3",
            "--rules",
            "local",
            "--crowding",
            "disc",
            "--record-every",
            "50",
            "--out",
            str(out),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    _wait_for(
        lambda: (tmp_path / "run.partial.rrd").exists() and (tmp_path / "run.partial.rrd").stat().st_size > 200_000
    )  # running and recording
    start = time.monotonic()
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == 130, err
    assert time.monotonic() - start < PROMPT_S
    summary = json.loads((out / "summary.json").read_text())
    last = summary["convergence_tick"]
    assert summary["outcome"] == "interrupted" and 0 < last < 100_000
    assert f"interrupted at tick {last}; the run so far is in {out}" in err and "Traceback" not in err
    assert len((out / "metrics.csv").read_text().splitlines()) == last + 2
    assert rrd_verify(out / "recording.rrd").returncode == 0
    rec = Recording(out / "recording.rrd")
    assert max(rec.series["moving"]) == last and max(rec.robots) == last
    assert rec.events[-1][1].startswith(f"interrupted at tick {last}")


def test_sigterm_to_an_experiment_stops_its_workers_and_keeps_finished_runs(tmp_path):
    config = small_config(tmp_path, repetitions=40)
    out = tmp_path / "exp"
    proc = subprocess.Popen(
        [PY, "-m", "swarm_ros", "experiment", str(config), "--out", str(out), "--jobs", "2"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    results = out / "results.csv"
    _wait_for(lambda: results.exists() and len(results.read_text().splitlines()) > 4)
    start = time.monotonic()
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == 130, err
    assert time.monotonic() - start < PROMPT_S
    assert not children_of(proc.pid), "a worker outlived the experiment"
    assert "run the same command again to resume" in err
    assert 3 <= len(read_results(results)) < 240
    assert not Path(out / "stats.csv").exists()  # the report is built at the end only


def test_sigterm_to_a_ros2_experiment_stops_the_graphs_of_its_workers(tmp_path):

    config = small_config(tmp_path, repetitions=3, vision_radius=[1], shapes={"disc.txt": [60]})
    proc = subprocess.Popen(
        [
            PY,
            "-m",
            "swarm_ros",
            "experiment",
            str(config),
            "--out",
            str(tmp_path / "exp"),
            "--engine",
            "ros2",
            "--jobs",
            "1",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    mentioning = lambda: set(processes_mentioning("swarm_ros-exp-"))  # a worker's graph, of any experiment
    _wait_for(lambda: mentioning() & set(descendants_of(proc.pid)))  # this one's graph is up
    family = descendants_of(proc.pid)
    start = time.monotonic()
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == 130, err
    _wait_for(lambda: not any(alive(pid) for pid in family), timeout=PROMPT_S)
    assert time.monotonic() - start < PROMPT_S
    assert "Traceback" not in err


def test_sigterm_to_run_before_tick_0_leaves_nothing_behind(tmp_path):
    """Stopped while its processes start: no run directory (there is no run yet), and nothing the run made
    (logs, partial recording or bag, the folders made for --out) is left; said in one line."""
    out = tmp_path / "made" / "for" / "run"
    proc = subprocess.Popen(
        [PY, "-m", "swarm_ros", "run", "--shape", "star", "--out", str(out)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    _wait_for(
        lambda: (
            any((logs / "world.log").exists() for logs in out.parent.glob(".run.logs-*"))
            if out.parent.exists()
            else False
        )
    )  # every node process has been started; none is ready
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == 130, err
    assert "interrupted before tick 0; nothing was written" in err and "Traceback" not in err
    assert list(tmp_path.iterdir()) == [], list(tmp_path.rglob("*"))


def test_sigterm_to_run_as_tick_0_goes_out_keeps_the_ticks_the_world_sent(tmp_path):
    """Stopped once the world has sent tick 0, whether or not the monitor has loaded: an interrupted run
    directory of the ticks sent, and no litter beside it."""
    out = tmp_path / "run"
    proc = subprocess.Popen(
        [PY, "-m", "swarm_ros", "run", "--shape", "star", "--rules", "local", "--out", str(out), "--quiet"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )

    def world_started() -> bool:
        return any(
            ": tick 0" in (logs / "world.log").read_text(errors="replace")
            for logs in tmp_path.glob(".run.logs-*")
            if (logs / "world.log").exists()
        )

    _wait_for(world_started, timeout=120)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == 130, err
    assert (out / "summary.json").exists(), err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["outcome"] == "interrupted"
    assert f"interrupted at tick {summary['convergence_tick']}; the run so far is in {out}" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]


def test_ctrl_c_as_run_shuts_down_says_the_run_ended_and_keeps_it_whole(tmp_path):
    """A Ctrl-C once the monitor has written the run directory (the nodes are still stopping): the run is
    whole, with its logs and shutdown time, and the message says so (not 'no run directory')."""
    import shutil

    out = tmp_path / "run"
    for _ in range(3):  # the nodes take ~0.3 s to stop: the Ctrl-C nearly always lands in that time
        proc = subprocess.Popen(
            [PY, "-m", "swarm_ros", "run", "--shape", "star", "--out", str(out), "--quiet"],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        wait_for(lambda: (out / "summary.json").exists(), 180, "the run's summary.json", poll=0.005)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=30)
        if proc.returncode != 0:
            break
        shutil.rmtree(out)  # the command had ended before the Ctrl-C reached it: again
    assert proc.returncode == 130, err
    summary = json.loads((out / "summary.json").read_text())
    assert (
        f"interrupted after the run had ended (complete at tick {summary['convergence_tick']}); it is whole in {out}"
        in err
        and "Traceback" not in err
    ), err
    assert summary["outcome"] == "complete" and summary["shutdown_seconds"] is not None
    assert (out / "logs" / "launcher.log").is_file()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]


@pytest.mark.parametrize("command", [["shapes"], ["simulate", "--shape", "star", "--quiet"]])
def test_ctrl_c_while_the_command_line_loads_is_one_line(tmp_path, command):
    """Ctrl-C while the command imports its modules (the first few tenths of a second): one line, exit 130."""
    script = Path(sys.executable).parent / "swarm-ros"
    for delay in (0.08, 0.15, 0.3):
        proc = subprocess.Popen(
            [str(script), *command], cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
        )
        time.sleep(delay)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=30)
        ours = [f for f in re.findall(r'^  File "([^"]+)"', err, re.M) if f.startswith(f"{PACKAGE}{os.sep}")]
        if "KeyboardInterrupt" in err and not ours:
            # before any line of swarm_ros ran (Python's start-up: its site module, the .pth files, the console
            # script's import line looking for the package): Python's own traceback, the one moment no code of
            # ours can answer (a loaded machine; CI met each of these)
            continue
        assert "Traceback" not in err, err
        if proc.returncode == -signal.SIGINT:  # reached before the interpreter had set its handler (a loaded
            assert not err  # machine): killed by the signal as any program, silent; a shell says 130
        elif proc.returncode != 0:  # 'interrupted', or on a fast machine, in the run: 'interrupted at tick 0; ...'
            assert proc.returncode == 130 and err.startswith("swarm-ros: interrupted") and err.count("\n") == 1, err


def test_ctrl_c_while_the_command_imports_its_run_directory_module_is_one_line(monkeypatch, capsys):
    """The moment a CI run's Ctrl-C landed (the launcher's start, loaded machine): the command line has loaded,
    its main() imports the run directory's module. One line, exit 130, no traceback."""
    import importlib.abc

    from swarm_ros.app import cli

    class Interrupting(importlib.abc.MetaPathFinder):
        def find_spec(self, name, path, target=None):
            if name == "swarm_ros.artifacts.run_dir":
                raise KeyboardInterrupt
            return None

    import swarm_ros.artifacts
    import swarm_ros.artifacts.run_dir

    monkeypatch.delitem(sys.modules, "swarm_ros.artifacts.run_dir")
    monkeypatch.delattr(swarm_ros.artifacts, "run_dir")
    monkeypatch.setattr(sys, "meta_path", [Interrupting(), *sys.meta_path])
    try:
        code = cli.main(["shapes"])
    except KeyboardInterrupt:  # caught here: one escaping would end pytest's whole session
        pytest.fail("a Ctrl-C while main() imports the run directory's module escaped it: a traceback")
    assert code == 130 and capsys.readouterr().err == "swarm-ros: interrupted\n"


def test_a_terminal_ctrl_c_to_a_dask_experiment_leaves_no_worker_traceback(tmp_path):
    """A terminal's Ctrl-C reaches the whole process group, Dask's workers included: they ignore it, and the
    command stops them; one message, exit 130."""
    import os

    config = small_config(tmp_path, repetitions=200)
    out = tmp_path / "exp"
    proc = subprocess.Popen(
        [PY, "-m", "swarm_ros", "experiment", str(config), "--out", str(out), "--jobs", "2", "--executor", "dask"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    results = out / "results.csv"
    _wait_for(lambda: results.exists() and len(results.read_text().splitlines()) > 4)
    os.killpg(proc.pid, signal.SIGINT)
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == 130, err
    assert "Traceback" not in err and err.count("interrupted") == 1, err
    assert "run the same command again to resume" in err


def test_sigterm_to_topics_closes_its_participant_and_leaves_no_log_file(tmp_path):
    """topics (and replay, the same way) stopped by SIGTERM: one line, exit 130, nothing left in /dev/shm,
    and no empty rcl log file in ~/.ros/log."""
    import os

    home = tmp_path / "home"
    before = set(os.listdir("/dev/shm"))
    env = {**os.environ, "HOME": str(home), "ROS_DOMAIN_ID": "229"}
    env.pop("ROS_LOG_DIR", None)
    proc = subprocess.Popen(
        [PY, "-m", "swarm_ros", "topics", "--echo", "/swarm/metrics", "--seconds", "20"],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    held: set[str] = set()  # the shared-memory files it uses (none with the UDP transport swarm_ros sets)

    def participating() -> bool:
        """Its DDS participant is up (its UDP sockets are open): the SIGTERM then lands while it waits for the
        topic, with something to close."""
        held.update(shm_locks(proc.pid))
        try:
            fds = os.listdir(f"/proc/{proc.pid}/fd")
        except OSError:
            return False
        sockets = 0
        for fd in fds:
            try:
                sockets += os.readlink(f"/proc/{proc.pid}/fd/{fd}").startswith("socket:")
            except OSError:
                continue
        return sockets >= 2 and proc.poll() is None

    _wait_for(participating)
    held |= shm_locks(proc.pid)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == 130 and err.strip() == "swarm-ros: interrupted", err
    # what it held, and any new file named after it (other tests' runs may make files meanwhile). A port's files
    # (fastrtps_port<N>) are shared with every participant on that port: the full suite once left one that a
    # neighbouring test's SIGKILLed node held too, which this process's close cannot remove; not counted here
    made = {f"/dev/shm/{f}" for f in set(os.listdir("/dev/shm")) - before if str(proc.pid) in f}
    own = {f for f in held if "fastrtps_port" not in f}
    left = shm_left(made | own | {el.removesuffix("_el") for el in own})
    assert not left, left
    assert not list(home.rglob("*.log")), list(home.rglob("*"))


def test_the_next_run_tidies_what_a_sigkilled_launcher_left(tmp_path):
    """SIGKILL the launcher mid-run: its hidden logs folder, Fast DDS files and lock file stay. The next 'run' of
    the same directory names where the logs went, removes the run's files from /dev/shm that nobody uses, and
    still refuses to write beside the partial recording and bag (the user's to keep or delete)."""
    import os

    out = tmp_path / "run"
    proc = subprocess.Popen(
        [PY, "-m", "swarm_ros", "run", "--shape", "star", "--rules", "local", "--out", str(out), "--quiet"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )

    def listed() -> list[str]:
        return [
            f
            for logs in tmp_path.glob(".run.logs-*")
            if (logs / "shm-files").exists()
            for f in (logs / "shm-files").read_text().split()
        ]

    # every node is up and its files listed, and the monitor has begun the recording (which must then stay)
    _wait_for(lambda: len(listed()) >= 4 and (tmp_path / "run.partial.rrd").exists(), timeout=120)
    proc.kill()
    proc.communicate(timeout=30)

    _wait_for(lambda: not run_processes(tmp_path / "run"), timeout=30)  # the nodes die with it
    left = [f for f in listed() if os.path.exists(f)]
    assert left, "a SIGKILLed launcher left no shared-memory file: nothing to test"
    hidden = list(tmp_path.glob(".run.logs-*"))
    assert len(hidden) == 1
    # a port's files are shared by every participant on that port: a test beside this one that has taken the
    # port since holds them now, rightly, as the tidy-up below runs (and may let go before the check: CI once)
    shared = {f for f in left if "_port" in Path(f).name and in_use(shm_group(f))}
    again = subprocess.run(
        [PY, "-m", "swarm_ros", "run", "--shape", "star", "--out", str(out), "--quiet"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert again.returncode == 2
    assert f"an earlier run of {out} was killed; its logs are now in {tmp_path / 'run.logs'}" in again.stderr
    assert "run.partial.rrd: left by an earlier run" in again.stderr
    assert not list(tmp_path.glob(".run.logs-*")) and (tmp_path / "run.logs" / "world.log").is_file()
    assert not list((tmp_path / "run.logs").glob("world.checkpoint*"))
    assert shm_left([f for f in left if f not in shared]) == []


@pytest.mark.parametrize(
    "hang,code,said",
    [
        # the teardown waits in Python, or in C with the GIL let go: Python's watchdog exits with the node's code
        ("time.sleep(60)", 7, "rclpy's shutdown took over 0.5 s; exiting without it"),
        # in C with the GIL kept, as rclpy waits inside Fast DDS (a deadlock of its threads, seen in CI, once
        # in a finished batch's destroy_node): faulthandler's thread writes the stacks, then the C library's
        # timer thread exits with the node's code all the same
        ("ctypes.PyDLL(None).sleep(60)", 0, "Timeout (0:00:00.750000)!"),
        ("ctypes.PyDLL(None).sleep(60)", 130, "Timeout (0:00:00.750000)!"),
    ],
)
def test_a_node_whose_teardown_hangs_exits_all_the_same(hang, code, said):
    """A node's process ends within 1.5 times the teardown bound (and half a second) however rclpy's teardown
    hangs, with the node's own status, so a node never outlives its launcher (a batch hung for good in CI once its
    launcher was SIGKILLed) and a finished node is never taken for a failed one."""
    pytest.importorskip("rclpy")
    script = (
        "import ctypes, time\n"
        "from swarm_ros.ros import runtime\n"
        "runtime._TEARDOWN_S = 0.5\n"
        f"runtime.guard_teardown('robot_batch_0', {code})\n"
        f"{hang}\n"
    )
    began = time.monotonic()
    done = subprocess.run([PY, "-c", script], capture_output=True, text=True, timeout=60)
    assert done.returncode == code, done.stderr
    assert said in done.stderr
    assert time.monotonic() - began < 30  # not the 60 s of the hang (start-up included, on a slow machine)


def test_a_ctrl_c_python_dropped_still_stops_a_dask_experiment_and_a_closing_thread_leaves_the_handlers():
    """A handler's KeyboardInterrupt raised inside a garbage collector's callback (Dask's GC diagnosis) is printed
    and dropped by Python: CI saw an experiment run on to exit 0 after a Ctrl-C. The noted interrupt is raised
    again at the next run finished; and the cluster's close, run in a thread while the report is built, gives the
    handlers back only from the main thread (signal.signal refuses any other)."""
    import threading

    from swarm_ros.app.executors import _QuietAfterInterrupt

    watcher = _QuietAfterInterrupt()
    before = signal.getsignal(signal.SIGINT)
    handlers = watcher.watch()
    try:
        assert signal.getsignal(signal.SIGINT) is not before
        watcher.check()  # nothing noted: nothing raised
        with pytest.raises(KeyboardInterrupt):
            signal.getsignal(signal.SIGINT)(signal.SIGINT, None)  # the handler: noted, then handed on
        assert watcher.interrupted
        with pytest.raises(KeyboardInterrupt):
            watcher.check()  # as if the one above had been dropped
        errors: list[BaseException] = []

        def close() -> None:
            try:
                watcher.unwatch(handlers)
            except BaseException as exc:
                errors.append(exc)

        closing = threading.Thread(target=close)
        closing.start()
        closing.join()
        assert errors == [] and signal.getsignal(signal.SIGINT) is not before
    finally:
        watcher.unwatch(handlers)
    assert signal.getsignal(signal.SIGINT) is before


@pytest.mark.parametrize("where", ["gc callback", "weakref callback"])
def test_a_ctrl_c_where_python_drops_exceptions_prints_no_traceback_and_still_interrupts(capfd, where):
    """Where Python would print a handler's KeyboardInterrupt as "Exception ignored", with a traceback, and drop it
    (inside a gc callback, as CI saw after a Ctrl-C to a Dask experiment, whose scheduler adds one; inside a
    weakref's callback, as CI saw in this very test), the signal is sent again a moment later: no traceback, and
    the interrupt still comes."""
    import gc
    import weakref

    from swarm_ros.app.executors import _QuietAfterInterrupt

    watcher = _QuietAfterInterrupt()
    before = sys.unraisablehook
    handlers = watcher.watch()
    came: list[bool] = []

    def interrupt(*_: object) -> None:  # as if the SIGINT landed here
        if not came:
            came.append(True)
            signal.getsignal(signal.SIGINT)(signal.SIGINT, sys._getframe())

    class Thing:
        pass

    if where == "gc callback":
        gc.callbacks.append(interrupt)
    try:
        with pytest.raises(KeyboardInterrupt):
            if where == "gc callback":
                gc.collect()
            else:
                thing = Thing()
                ref = weakref.ref(thing, interrupt)
                del thing
                assert ref() is None
            time.sleep(30)  # the signal sent again arrives long before
        assert came and watcher.interrupted
    finally:
        if interrupt in gc.callbacks:
            gc.callbacks.remove(interrupt)
        watcher.unwatch(handlers)
    assert sys.unraisablehook is before
    err = capfd.readouterr().err
    assert "Exception ignored" not in err and "Traceback" not in err, err


def test_ctrl_c_mid_rubenstein_run_keeps_an_interrupted_run_directory_and_its_recording(tmp_path):
    """Ctrl-C during a rubenstein simulate: exit 130, one line, and the run so far written whole (outcome
    interrupted), its recording ended and moved in; nothing left beside it."""
    import json
    import signal
    import subprocess
    import sys

    out = tmp_path / "run"
    proc = subprocess.Popen(
        [sys.executable, "-m", "swarm_ros", "simulate", "--algorithm", "rubenstein", "--shape", "star"]
        + ["--out", str(out), "--quiet"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    wait_ticks_recorded(out, 100_000)  # ticks are in the recording (it opens with about 14 kB: the shape)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert "Traceback" not in err and err.strip().splitlines()[-1].startswith("swarm-ros: interrupted at tick"), err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["outcome"] == "interrupted" and summary["convergence_tick"] > 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]
    metrics = (out / "metrics.csv").read_text().splitlines()
    assert len(metrics) == summary["convergence_tick"] + 2  # the header, tick 0 and every tick run
    from recordings import rrd_verify

    assert rrd_verify(out / "recording.rrd").returncode == 0
