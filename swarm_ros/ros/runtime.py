"""What every node's ``main`` shares: rclpy set-up, the spin loop, one-line errors, exit codes.

Exit codes: 0 done, 1 the run failed (a peer sent something impossible, a timeout),
2 bad parameters, 130 interrupted (SIGINT or SIGTERM, acted on between callbacks), 129
the launcher died (SIGHUP, sent by the kernel: see :func:`follow_parent`).
"""

from __future__ import annotations

import ctypes
import faulthandler
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Protocol

import rclpy
from rclpy.context import Context
from rclpy.executors import ExternalShutdownException
from rclpy.experimental import EventsExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions
from rclpy.utilities import get_default_context

from swarm_ros.core.errors import InputError, RunFailed
from swarm_ros.core.kernels import count_compiles
from swarm_ros.core.signals import EXIT_INTERRUPTED, PARENT_ENV, StopFlag, process_age

EXIT_OK, EXIT_FAILED, EXIT_USAGE, EXIT_ORPHANED = 0, 1, 2, 129  # and EXIT_INTERRUPTED, 130 (core.signals)
#: The ROS arguments of the command line's own short-lived nodes (the launcher's progress bar, topics, replay):
#: rcl's log file off, which would otherwise leave an empty ~/.ros/log/python_<pid>_<time>.log per command.
TOOL_ROS_ARGS = ("--ros-args", "--disable-external-lib-logs")
_SPIN_TIMEOUT = 0.05  # seconds; how often poll() runs when no message arrives
_TEARDOWN_S = 5.0  # seconds rclpy's and DDS's teardown may take once the node is closed
_DUMP_S = 0.5  # seconds faulthandler's dump of a hung teardown's stacks is given before the process ends
_CLOCK_MONOTONIC, _SIGEV_THREAD = 1, 2  # <time.h>'s and <signal.h>'s values on Linux


_HELD: tuple[int, ...] = (signal.SIGINT, signal.SIGTERM)  #: what a tool's handlers turn into KeyboardInterrupt


@contextmanager
def signals_held() -> Iterator[None]:
    """SIGINT and SIGTERM only noted for the block, then handed to their handlers as it ends: a KeyboardInterrupt a
    handler raises comes never halfway through rclpy making or unmaking its objects (CI once saw the ``__del__`` of
    a logger a node was making fail, printed as "Exception ignored" under the command's one line). The handlers
    are swapped, not the signal mask: the kernel gives a process's signal to any thread that does not block it.
    Off the main thread (where handlers cannot be set, and none run) it holds nothing."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    noted: list[int] = []
    before = {sig: signal.signal(sig, lambda signum, frame: noted.append(signum)) for sig in _HELD}
    try:
        yield
    finally:
        for sig, handler in before.items():
            signal.signal(sig, handler)
        for sig in dict.fromkeys(noted):
            signal.raise_signal(sig)


@contextmanager
def tool_node(name: str, domain_id: int, extra_args: tuple[str, ...] = ()) -> Iterator[Node]:
    """The node of a command-line tool's own short-lived participant (the launcher's progress bar, ``topics``,
    ``replay``) on ``domain_id``: its own context, rclpy's signal handlers off (the tool's own act on Ctrl-C and
    SIGTERM), rcl's log file off (:data:`TOOL_ROS_ARGS`). Made and closed with SIGINT and SIGTERM held: one that
    comes meanwhile is acted on once the participant is whole, or closed. An executor the caller made for it must
    be shut down before the block ends."""
    context = Context()
    with signals_held():
        rclpy.init(
            args=[*TOOL_ROS_ARGS, *extra_args],
            context=context,
            domain_id=domain_id,
            signal_handler_options=SignalHandlerOptions.NO,
        )
        try:
            node = Node(name, context=context, start_parameter_services=False)
        except BaseException:
            rclpy.shutdown(context=context)
            raise
    try:
        yield node
    finally:
        with signals_held():
            node.destroy_node()
            rclpy.shutdown(context=context)


def load_type_support() -> int:
    """Load the C type support of every message and service type whose module this process has imported (what a
    node makes endpoints of, and the parameter and type-description services every node has); returns how many.

    A node otherwise loads each on its first endpoint: with ``rosidl_generator_py`` (and its parser, lark and
    empy, imported along), about 0.05 s of CPU a node. The launcher does it once before it forks its nodes
    (``swarm_ros.app.forking.preload``). A type whose support does not load is left for the node to report.
    """
    from rclpy.type_support import check_for_type_support

    loaded = 0
    for name, module in list(sys.modules.items()):
        parts = name.split(".")
        if len(parts) != 3 or parts[1] not in ("msg", "srv") or not parts[2].startswith("_"):
            continue
        for value in list(vars(module).values()):
            if isinstance(value, type) and value.__module__ == name and hasattr(type(value), "_TYPE_SUPPORT"):
                try:
                    check_for_type_support(value)
                except Exception:  # the node that uses it reports it, in its own words
                    continue
                loaded += 1
    return loaded


class SwarmNode(Protocol):
    node: Node

    @property
    def finished(self) -> bool:
        """Whether the node's work is done and it may exit."""
        ...

    def load(self) -> None:
        """Called once the node is in the executor, before the first spin: the slow part of starting
        (numba's kernels, Rerun, the bag) comes after the endpoints, so discovery goes on meanwhile."""

    def poll(self) -> None:
        """Called between callbacks: check timeouts, raise RunFailed to stop."""

    def wake_in(self) -> float | None:
        """Seconds until :meth:`poll` has something due (the world's ``tick_rate``), if sooner than the next
        idle poll; None: nothing."""

    def close(self, code: int) -> None:
        """Called once on the way out with the exit code (release files, mark a stopped run)."""


_PR_SET_PDEATHSIG = 1


def follow_parent() -> None:
    """Under ``swarm-ros run``: receive SIGHUP when the launcher dies, so no node outlives it.

    The kernel sends it (``prctl(PR_SET_PDEATHSIG)``), also if the launcher is SIGKILLed;
    the node then stops between callbacks with exit status 129. If the launcher died
    before this call, exit now.
    Nothing happens for a node started another way (``ros2 run``, ``ros2 launch``).
    """
    parent = os.environ.get(PARENT_ENV, "")
    if not parent.isdigit():
        return
    import ctypes

    libc = ctypes.CDLL(None, use_errno=True)
    if libc.prctl(_PR_SET_PDEATHSIG, int(signal.SIGHUP), 0, 0, 0) != 0:
        return  # not Linux: the launcher's own stop() is the only guard
    if os.getppid() != int(parent):
        raise SystemExit(EXIT_ORPHANED)


def handle_missed(node: Node) -> int:
    """Hand every message waiting in ``node``'s readers to its callback, oldest first; return how many.

    rclpy's EventsExecutor (Jazzy) sometimes loses a subscription's new-message event: the
    message stays in its reader, unseen. Measured: in 3 of 12 short runs a whole topic of
    the monitor's (``/swarm/shape``, ``/clock`` or ``/swarm/occupancy``) never reached its
    callback. :func:`run_node` calls this whenever the executor has had nothing to do for a
    spin's timeout, and the monitor before it writes the run. (An event of the executor's for
    a message taken here finds nothing to take, and does nothing.)
    """
    return sum(take_waiting(sub) for sub in list(node.subscriptions))


def take_waiting(sub) -> int:
    """Hand every message waiting in the reader of subscription ``sub`` to its callback, oldest first; return
    how many (see :func:`handle_missed`). For a node that must not go on before a topic's message is handled,
    though nothing else waits for it (the monitor's decisions, which it records)."""
    count = 0
    while True:
        with sub.handle:
            taken = sub.handle.take_message(sub.msg_type, sub.raw)
        if taken is None:
            return count
        count += 1
        sub.callback(taken[0])


def run_node(name: str, factory: Callable[[], SwarmNode], argv: list[str] | None = None) -> int:
    """Init rclpy with ``argv`` (ROS arguments included), build the node, spin until it finishes, exit.

    The process ends with :func:`os._exit` as soon as the node is closed and rclpy is shut
    down: the interpreter's own teardown (module clean-up, the DDS libraries' destructors)
    would take another half second of a run's critical path, and there is nothing left to
    save by then (the node has closed its files; stdout and stderr are flushed here).
    """
    follow_parent()
    args = sys.argv if argv is None else argv
    try:
        # Our own SIGINT/SIGTERM handling: a flag checked between callbacks, so a signal never
        # lands inside one (an exception raised there comes out of rclpy as a bare RuntimeError).
        rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    except Exception as exc:  # rclpy reports bad --ros-args (e.g. a missing params file) as RCLError
        return _fail(name, f"cannot start ROS 2: {_first_line(exc)}", EXIT_USAGE)
    stop = StopFlag()
    swarm = executor = None
    code = EXIT_FAILED  # an unexpected exception
    compiled = count_compiles()
    try:
        swarm = factory()
        # The node joins the executor before it loads: a message that arrives while it loads is then
        # queued as an event. (Added after, the EventsExecutor sometimes never dispatched what a
        # subscription had received before: whole topics went missing from the monitor's bag.)
        executor = EventsExecutor()
        executor.add_node(swarm.node)
        swarm.load()
        swarm.node.get_logger().info(
            f"ready, {process_age():.2f} s after the process started ({time.process_time():.2f} s of CPU, "
            f"{compiled()} kernels compiled)"
        )
        missed = 0
        while not swarm.finished and not stop.signum:
            began = time.monotonic()
            due = swarm.wake_in()
            executor.spin_once(timeout_sec=_SPIN_TIMEOUT if due is None else min(due, _SPIN_TIMEOUT))
            if time.monotonic() - began >= _SPIN_TIMEOUT:  # nothing to do: anything in a reader was missed
                missed += handle_missed(swarm.node)
            swarm.poll()
        if missed:  # rclpy's, handled: information, not a warning (a clean run printed [WARN] at its end)
            swarm.node.get_logger().info(
                f"{missed} messages came without the executor's event (rclpy's EventsExecutor loses some); each "
                f"was handled at the next idle moment ({_SPIN_TIMEOUT * 1000:g} ms without events)"
            )
        swarm.node.get_logger().info(
            f"done, {process_age():.2f} s after the process started ({time.process_time():.2f} s of CPU)"
        )
        code = (
            EXIT_OK
            if swarm.finished or not stop.signum
            else EXIT_ORPHANED
            if stop.signum == signal.SIGHUP
            else EXIT_INTERRUPTED
        )
    except InputError as exc:
        code = _fail(name, str(exc), EXIT_USAGE)
    except RunFailed as exc:
        code = _fail(name, str(exc), EXIT_FAILED)
    except OSError as exc:  # the file system refused (a full disk): said in one line, as the launcher reports it
        code = _fail(name, f"{exc.filename}: {exc.strerror}" if exc.filename else str(exc.strerror or exc), EXIT_FAILED)
    except (KeyboardInterrupt, ExternalShutdownException):
        code = EXIT_INTERRUPTED
    finally:
        if swarm is not None:
            try:
                swarm.close(code)
            except (InputError, RunFailed, OSError) as exc:  # closing its files failed (a full disk)
                if code == EXIT_OK:
                    code = _fail(name, f"while closing: {exc}", EXIT_FAILED)
                else:  # the error already said is the one the launcher reports; this one goes to the log
                    swarm.node.get_logger().warn(f"while closing: {exc}")
        guard_teardown(name, code)
        if executor is not None:
            executor.shutdown()
        if swarm is not None:
            swarm.node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
        # Deletes the DDS participant now, which tells the peers at once that this node's readers
        # and writers are gone (os._exit below skips the destructors that would otherwise do it).
        get_default_context().destroy()
        sys.stdout.flush()
        sys.stderr.flush()
    os._exit(code)


def guard_teardown(name: str, code: int) -> None:
    """Everything is saved: rclpy's and DDS's teardown may not hold the exit up. After ``_TEARDOWN_S`` the
    process exits with ``code`` (a monitor that had written its run once hung in it until the launcher killed
    it, failing a finished run). That watchdog is Python's and needs the GIL, which rclpy keeps while it waits
    inside Fast DDS: a batch whose launcher was SIGKILLed hung for good in a deadlock of Fast DDS 2.14 (its
    event thread and a receive thread, each waiting on the other, as the dead launcher's participant was
    removed), and a finished batch hung the same way in ``destroy_node`` on a four-host run. So at one and a half
    times that, faulthandler's C thread writes the threads' stacks into the log, and a timer of the C library,
    whose thread needs no GIL either, ends the process just after with ``code``: a hung teardown never turns a
    node's finished work into a failure (it exited 1 there, before), and it is over before the launcher's 10 s
    grace for a node to exit by itself."""
    watchdog = threading.Timer(_TEARDOWN_S, _hung_teardown, (name, code))
    watchdog.daemon = True
    watchdog.start()
    faulthandler.dump_traceback_later(1.5 * _TEARDOWN_S, exit=False)
    _exit_later(1.5 * _TEARDOWN_S + _DUMP_S, code)


class _SigEvent(ctypes.Structure):
    """glibc's ``struct sigevent`` on a 64-bit Linux (64 bytes), for ``SIGEV_THREAD``."""

    _fields_ = (
        ("value", ctypes.c_long),  # union sigval: the function's argument, here _exit's status
        ("signo", ctypes.c_int),
        ("notify", ctypes.c_int),
        ("function", ctypes.c_void_p),
        ("attributes", ctypes.c_void_p),
        ("pad", ctypes.c_int * 8),
    )


class _TimerSpec(ctypes.Structure):
    """``struct itimerspec``: the interval (none) and the first expiry, each as seconds and nanoseconds."""

    _fields_ = (("every", ctypes.c_long * 2), ("first", ctypes.c_long * 2))


def _exit_later(seconds: float, code: int) -> None:
    """``_exit(code)`` in ``seconds``, from a thread glibc starts (POSIX timer, ``SIGEV_THREAD``): no Python runs
    in it, so it fires while another thread keeps the GIL. The status is handed to ``_exit`` as the timer's
    ``sigval``, which the x86-64 and AArch64 calling conventions pass in the register an ``int`` argument
    uses."""
    libc = ctypes.CDLL(None, use_errno=True)
    event = _SigEvent(value=code, notify=_SIGEV_THREAD, function=ctypes.cast(libc._exit, ctypes.c_void_p).value)
    timer = ctypes.c_void_p()
    whole = int(seconds)
    spec = _TimerSpec(first=(ctypes.c_long * 2)(whole, int((seconds - whole) * 1e9)))
    if (
        libc.timer_create(_CLOCK_MONOTONIC, ctypes.byref(event), ctypes.byref(timer)) != 0
        or libc.timer_settime(timer, 0, ctypes.byref(spec), None) != 0
    ):  # not expected on Linux: the faulthandler fallback, with status 1
        faulthandler.dump_traceback_later(1.5 * _TEARDOWN_S, exit=True)


def _hung_teardown(name: str, code: int) -> None:
    print(
        f"swarm_ros {name}: rclpy's shutdown took over {_TEARDOWN_S:g} s; exiting without it",
        file=sys.stderr,
        flush=True,
    )
    os._exit(code)


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


def _fail(name: str, message: str, code: int) -> int:
    print(f"swarm_ros {name}: error: {message}", file=sys.stderr, flush=True)
    return code
