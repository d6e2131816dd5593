"""Node processes forked from the launcher after it has loaded what every node loads, instead of started afresh.

A node started with ``python -m`` spends about 1 s of CPU before it does anything of its own: numpy, numba
(which imports scipy.linalg to find a BLAS), numba's cache load of the kernels (the algorithm's ``warm_up`` hook,
e.g. :mod:`swarm_ros.core.darr_niazi.warmup`), rclpy and its node module. Four such processes on 2 cores were most
of the README's command. ``swarm-ros run`` therefore loads these once, in its own process, and forks each node from
it: the child starts with all of it in memory and goes straight to ``rclpy.init``. What the child does from there is
what ``python -m swarm_ros.nodes.<node>`` does.

Forking is only safe from a process without threads that hold locks the child would need. numpy's OpenBLAS
pool is fork-aware (it stops its threads before a fork and starts them again when next used). rclpy's import
loads LTTng-UST (ROS 2's tracing), whose two listener threads are fork-aware only through the hooks LTTng
exports for the purpose (``ust_before_fork``, ``ust_after_fork_parent``, ``ust_after_fork_child``: what its
``liblttng-ust-fork`` preload calls around ``fork()``), so :class:`Forked` calls them around its fork. A started
ROS context (DDS threads) and Rerun (threads of its own) are not fork-safe at all. :func:`can_fork` therefore
refuses once Rerun is imported, once the process has more threads than it had when :func:`preload` was done
(rclpy started: the launcher's progress bar), once rclpy is loaded other than by :func:`preload`, or when other
Python threads run (a Dask worker runs the launcher in a thread); the launcher then starts nodes with ``python
-m`` as before. A restarted node, for one, starts that way.
"""

from __future__ import annotations

import ctypes
import importlib
import inspect
import os
import shlex
import signal
import subprocess
import sys
import threading
import time
import traceback
from collections.abc import Mapping, Sequence
from typing import IO, Any

#: modules that start threads at import which a forked child cannot use (found by counting /proc/self/task)
_THREADED = ("rerun", "distributed")
_SIGSET = 128  #: bytes of a sigset_t (glibc): what LTTng's fork hooks save the signal mask in
_NODE_PREFIX = "swarm_ros.nodes."
_HELD = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)  #: what stops a launcher: only noted while it forks


class _Preloaded:
    """What :func:`preload` left: the threads this process had then, and LTTng's fork hooks if rclpy loaded it."""

    threads: int | None = None  #: native threads once preloaded; None: not preloaded (or not safely)
    lttng: ctypes.CDLL | None = None


def _native_threads() -> int:
    return len(os.listdir("/proc/self/task"))


def _lttng_library() -> str | None:
    """The path of the LTTng-UST library this process has loaded (rclpy's wheels bring it), or None."""
    with open("/proc/self/maps", encoding="utf-8", errors="replace") as maps:
        for line in maps:
            path = line.rstrip("\n").split(maxsplit=5)[-1]
            if os.path.basename(path).startswith("liblttng-ust") and "tracepoint" not in os.path.basename(path):
                return path
    return None


def can_fork() -> bool:
    """Whether this process may fork a node: on the main thread, the only Python thread, neither Rerun nor
    Dask's distributed loaded, and rclpy either not loaded or loaded by :func:`preload` and not started since
    (no thread more than it had then)."""
    if not (
        hasattr(os, "fork")
        and threading.current_thread() is threading.main_thread()
        and threading.active_count() == 1
        and not any(m == name or m.startswith(name + ".") for m in sys.modules for name in _THREADED)
    ):
        return False
    if "rclpy" not in sys.modules:
        return True
    return _Preloaded.threads is not None and _native_threads() <= _Preloaded.threads


def preload(shape, params, roles: Sequence[str] = ()) -> None:
    """Load, in this process, what each node would load on its own: numpy, numba, the compiled kernels of the
    run's code path (from numba's cache, which the launcher has filled), and the node executables of ``roles``
    with the run's algorithm's node classes and rclpy, if this process may still fork once they are loaded
    (LTTng's fork hooks found, where rclpy brings LTTng)."""
    from swarm_ros.core.algorithm import algorithm_of, node_of

    algorithm_of(params.algorithm).hook("warm_up")(shape, params)
    if not roles or not can_fork() or "rclpy" in sys.modules:
        return
    try:
        for role in roles:
            importlib.import_module(f"{_NODE_PREFIX}{role}")
            node_of(params.algorithm, role)
        algorithm_of(params.algorithm).hook("batch_host")  # what the robot-batch node runs for this algorithm
    except Exception:  # each node, started afresh, reports what it cannot import in its own log
        return  # can_fork then refuses (rclpy loaded, not preloaded): the nodes start with python -m
    from swarm_ros.ros.runtime import load_type_support

    load_type_support()
    # rclpy's logger finds its caller with inspect.getframeinfo, whose first call maps every loaded module to its
    # file (25-50 ms of CPU with numba loaded): made here once, the map is the children's too
    inspect.getframeinfo(sys._getframe())
    path = _lttng_library()
    if path is not None:
        try:
            lttng = ctypes.CDLL(path)
            for hook in ("ust_before_fork", "ust_after_fork_parent", "ust_after_fork_child"):
                getattr(lttng, hook).argtypes = [ctypes.c_void_p]
        except (OSError, AttributeError):
            return  # tracing without its fork hooks: no more forks from here (can_fork)
        _Preloaded.lttng = lttng
    _Preloaded.threads = _native_threads()


def forkable(command: list[str]) -> str | None:
    """The node module a ``python -m swarm_ros.nodes.<node> ...`` command runs, or None for any other command."""
    if len(command) >= 3 and command[0] == sys.executable and command[1] == "-m":
        if command[2].startswith(_NODE_PREFIX):
            return command[2]
    return None


def start_node(command: list[str], env: Mapping[str, str], log: IO) -> subprocess.Popen | Forked:
    """Start a node's ``command`` in a session of its own, stdout and stderr into ``log``: forked from this process
    if it may (:func:`can_fork`: a restart comes after rclpy's start) and the command is a node module's;
    otherwise executed."""
    module = forkable(command) if can_fork() else None
    if module is None:
        return subprocess.Popen(
            command, env=env, stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, start_new_session=True
        )
    return Forked(module, command[3:], env, log.fileno())


class Forked:
    """A node process forked from this one; what the launcher uses of :class:`subprocess.Popen`: ``pid``,
    ``returncode``, ``poll()`` and ``wait()``. Its exit status reads as Popen's does (-N: killed by signal N)."""

    def __init__(self, module: str, args: list[str], env: Mapping[str, str], log_fd: int) -> None:
        for stream in (sys.stdout, sys.stderr):
            stream.flush()  # or the child writes this process's buffered output a second time
        self.args = [module, *args]
        self.returncode: int | None = None
        # No signal handler may raise inside the fork. Python's at-fork hooks swallow its KeyboardInterrupt (the
        # signal was lost, and logging's lock stayed taken for good); one raised between LTTng's hooks leaves
        # LTTng's locks taken, and the next fork hangs on them (CI saw it once under a SIGTERM storm). Blocking
        # the signals in this thread does not keep them out: another thread (OpenBLAS's pool) takes the signal
        # and Python runs the handler here, at this thread's next bytecode. So while this forks the handlers
        # only note a signal; it is raised again after the fork, where the handler that was there handles it.
        noted: list[int] = []
        previous = _note_signals(noted)
        lttng, saved = _Preloaded.lttng, ctypes.create_string_buffer(_SIGSET)
        try:
            if lttng is not None:  # its locks taken, its signals blocked: its threads cannot be mid-way in the fork
                lttng.ust_before_fork(saved)
            pid = os.fork()
            if lttng is not None:  # gives the locks back; in the child, starts its listener threads again
                (lttng.ust_after_fork_child if pid == 0 else lttng.ust_after_fork_parent)(saved)
            if pid == 0:  # the child: never returns
                _become_node(module, args, env, log_fd)
            self.pid = pid
        finally:
            for sig, handler in previous.items():
                signal.signal(sig, handler)
        for signum in dict.fromkeys(noted):
            signal.raise_signal(signum)

    def poll(self) -> int | None:
        if self.returncode is None:
            try:
                pid, status = os.waitpid(self.pid, os.WNOHANG)
            except ChildProcessError:  # reaped elsewhere: its status is lost
                self.returncode = 255
                return self.returncode
            if pid:
                self.returncode = os.waitstatus_to_exitcode(status)
        return self.returncode

    def wait(self, timeout: float | None = None) -> int | None:
        deadline = None if timeout is None else time.monotonic() + timeout
        while self.poll() is None:
            if deadline is not None and time.monotonic() >= deadline:
                return None
            time.sleep(0.005)
        return self.returncode


def _note_signals(noted: list[int]) -> dict[int, Any]:
    """Make each Python handler of :data:`_HELD` append its signal to ``noted`` instead; the handlers that were
    there, to give back. None in a thread other than the main one: Python runs handlers only in that one."""
    previous: dict[int, Any] = {}
    if threading.current_thread() is not threading.main_thread():
        return previous
    try:
        for sig in _HELD:
            if callable(signal.getsignal(sig)):  # the OS's own action (ignore, end the process) raises nothing
                previous[sig] = signal.signal(sig, lambda signum, frame: noted.append(signum))
    except BaseException:  # signal.signal ran a pending handler, which raised: nothing is forked yet
        for taken, handler in previous.items():
            signal.signal(taken, handler)
        raise
    return previous


_PROGRAM = ctypes.create_string_buffer(256)  #: the program's name for libc (and so ROS's log file names)


def _name_program(name: str) -> None:
    """Point libc's program_invocation_name, which ROS 2 names its log files by (``<name>_<pid>_<ms>.log``),
    back at the interpreter's name: after setproctitle it is the whole title, slashes and spaces included."""
    try:
        libc = ctypes.CDLL(None)
        _PROGRAM.value = name.encode()[: len(_PROGRAM) - 1]
        for symbol in ("program_invocation_name", "program_invocation_short_name"):
            ctypes.c_void_p.in_dll(libc, symbol).value = ctypes.addressof(_PROGRAM)
    except (OSError, ValueError):
        pass  # not glibc: the log files take the title's last part


def _become_node(module: str, args: list[str], env: Mapping[str, str], log_fd: int) -> None:
    """In the forked child: become ``python -m <module> <args>`` with ``env``, stdout and stderr in ``log_fd``,
    in a session of its own (as ``start_new_session`` makes one); then exit, never returning to the caller."""
    code = 1
    try:
        os.setsid()
        null = os.open(os.devnull, os.O_RDONLY)
        os.dup2(null, 0)
        os.dup2(log_fd, 1)
        os.dup2(log_fd, 2)
        os.closerange(3, os.sysconf("SC_OPEN_MAX"))  # the launcher's lock, other nodes' logs: not this node's
        signal.set_wakeup_fd(-1)
        for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):  # the handlers a fresh interpreter has
            if signal.getsignal(sig) not in (signal.SIG_IGN, signal.SIG_DFL, signal.default_int_handler):
                signal.signal(sig, signal.default_int_handler if sig == signal.SIGINT else signal.SIG_DFL)
        import setproctitle

        # what ps shows for it; first: it finds the room for the title through the environment as it was
        setproctitle.setproctitle(shlex.join([sys.executable, "-m", module, *args]))
        _name_program(os.path.basename(sys.executable))  # the title now holds argv[0]: ROS names its log by it
        os.environ.clear()
        os.environ.update(env)
        sys.stdin = open(0, encoding="utf-8", closefd=False)
        sys.stdout = open(1, "w", encoding="utf-8", errors="backslashreplace", closefd=False, buffering=1)
        sys.stderr = open(2, "w", encoding="utf-8", errors="backslashreplace", closefd=False, buffering=1)
        sys.argv = [module, *args]
        code = importlib.import_module(module).main(sys.argv)  # a node's main ends the process itself
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
        if not isinstance(exc.code, int | None):
            print(exc.code, file=sys.stderr)
    except KeyboardInterrupt:  # as the interpreter ends on one: killed by SIGINT
        signal.signal(signal.SIGINT, signal.SIG_DFL)
        os.kill(os.getpid(), signal.SIGINT)
    except BaseException:
        traceback.print_exc()
    finally:
        try:
            sys.stdout.flush()
            sys.stderr.flush()
        finally:
            os._exit(code)
