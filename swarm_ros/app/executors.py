"""Where an experiment's runs go: worker processes on this machine, or a Dask cluster.

Only a run's coordinates (:class:`~swarm_ros.app.experiment_file.RunSpec`) go to a worker and
only its results.csv row comes back; :mod:`swarm_ros.app.experiment` appends the rows.
"""

from __future__ import annotations

import json
import math
import os
import sys
import tempfile
import uuid
from collections.abc import Generator, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from swarm_ros.app.curves import CURVE, curve_of, steps
from swarm_ros.app.experiment_file import RunSpec
from swarm_ros.app.results_file import ExperimentError, result_row
from swarm_ros.core.algorithm import algorithm_of
from swarm_ros.core.grid import World
from swarm_ros.core.shapes import Shape
from swarm_ros.protocol.plan import PROCESSES

EXECUTORS = ("local", "dask")  #: where the runs go: worker processes here, or a Dask cluster
_CONNECT_TIMEOUT = "5s"  # to reach a Dask scheduler given by address
_TASK_SECONDS = 0.25  # seconds of runs a Dask task holds, once the runs' length is known (chunk_size)
_MIN_TASK_SECONDS = 0.05  # ... and at least this, near the end of a sweep of short runs
_IN_FLIGHT = 3  # Dask tasks submitted ahead per worker: it starts the next as soon as one ends

_SHAPES: dict[tuple[str, int, int], Shape] = {}


def _shape(spec: RunSpec) -> Shape:
    key = (spec.shape_file, spec.world_radius, spec.shape_scale)
    if key not in _SHAPES:
        _SHAPES[key] = Shape.load(spec.shape_file, World(spec.world_radius), scale=spec.shape_scale)
    return _SHAPES[key]


def run_inprocess(spec: RunSpec) -> dict:
    """Run ``spec`` with the in-process engine; its results.csv row."""
    import time

    start = time.perf_counter()
    params = spec.params()
    algorithm = algorithm_of(params.algorithm)
    run = algorithm.hook("engine")(_shape(spec), params)
    run.run()
    summary = algorithm.hook("summary")(run, wall_seconds=time.perf_counter() - start)
    return _with_curve(spec, run, result_row(spec, summary))


def _with_curve(spec: RunSpec, run, row: dict) -> dict:
    """``row``, with its run's step curve under ``CURVE`` if it is its grid point's repetition 0 (the report's)."""
    if spec.repetition == 0:
        row[CURVE] = steps(curve_of(run))
    return row


def run_ros2(spec: RunSpec, processes: int = PROCESSES.default) -> dict:
    """Run ``spec`` over the ROS 2 graph (``swarm-ros run``, no recording) in a scratch directory."""
    import shutil

    from swarm_ros.app.launcher import Launch
    from swarm_ros.artifacts.recording_options import RecordingOptions

    shape = _shape(spec)
    scratch = Path(tempfile.mkdtemp(prefix="swarm_ros-exp-"))
    try:
        launch = Launch(
            settings=spec.settings,
            shape=shape,
            params=spec.params(),
            processes=processes,
            out=scratch / "run",
            quiet=True,
            recording=RecordingOptions(enabled=False),
        )
        out = launch.run()
        summary = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    return result_row(spec, summary)


_IN_RUN = False  # in a worker: whether it is running a run now (else it waits for one, with nothing to stop)
_STOPPED = False  # in a worker: the parent's SIGTERM came


def _interrupt(signum: int, frame: object) -> None:
    global _STOPPED
    _STOPPED = True
    if not _IN_RUN:
        os._exit(130)  # idle: nothing to unwind (a KeyboardInterrupt there is a traceback from the pool's loop)
    raise KeyboardInterrupt


def _worker_init(engine: str) -> None:
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent decides what Ctrl-C does
    if engine == "ros2":
        # The parent stops workers with SIGTERM (Pool.terminate): unwind, so that a worker running a
        # ROS 2 graph stops its node processes (Launch.run's finally) instead of orphaning them.
        signal.signal(signal.SIGTERM, _interrupt)


def _work(job: tuple[RunSpec, str, int]) -> dict:
    global _IN_RUN
    spec, engine, processes = job
    _IN_RUN = True
    try:
        return run_ros2(spec, processes) if engine == "ros2" else run_inprocess(spec)
    except KeyboardInterrupt:  # stopped by the parent; a graph's processes are already stopped
        os._exit(130)
    finally:
        _IN_RUN = False
        if _STOPPED:  # the signal landed where the run took it as its own end (its shutdown): stop anyway, or
            os._exit(130)  # this worker would wait for a next run while the parent waits for it to exit


def execute(
    todo: list[RunSpec], jobs: int, engine: str = "inprocess", processes: int = PROCESSES.default
) -> Generator[dict, None, None]:
    """Yield the row of each run as it finishes, over ``jobs`` worker processes (spawned).

    Closing the generator (or an exception in the caller, e.g. Ctrl-C) terminates the workers.
    """
    import multiprocessing as mp

    if not todo:
        return
    ctx = mp.get_context("spawn")
    pool = ctx.Pool(min(jobs, len(todo)), initializer=_worker_init, initargs=(engine,))
    try:
        yield from pool.imap_unordered(_work, [(s, engine, processes) for s in todo], chunksize=1)
        pool.close()
        pool.join()  # done: the workers leave by themselves (terminate() below then has nobody to stop)
    finally:
        pool.terminate()
        pool.join()


def run_spec(spec: RunSpec, engine: str, processes: int) -> dict:
    """One run's results.csv row: what a Dask worker computes (it gets the run's coordinates only)."""
    return run_ros2(spec, processes) if engine == "ros2" else run_inprocess(spec)


def _ros_environment() -> dict[str, str]:
    """What decides, on a worker's host, whether each of its ROS runs gets a ROS domain of its own."""
    return {key: os.environ.get(key, "") for key in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE")}


def _check_ros_workers(client) -> None:
    """Refuse the ros2 engine on workers where two runs could share a ROS domain.

    A run takes a domain id of its own on its host (a lock file, as ``swarm-ros run``), and keeps
    its discovery on that host; neither holds with ``ROS_DOMAIN_ID`` fixed, or with discovery
    reaching other hosts (whose runs lock their ids independently).
    """
    for worker, env in sorted(client.run(_ros_environment).items()):
        if env["ROS_DOMAIN_ID"]:
            why = f"ROS_DOMAIN_ID={env['ROS_DOMAIN_ID']} fixes one ROS domain for all its runs"
        elif env["ROS_AUTOMATIC_DISCOVERY_RANGE"] not in ("", "LOCALHOST"):
            why = (
                f"ROS_AUTOMATIC_DISCOVERY_RANGE={env['ROS_AUTOMATIC_DISCOVERY_RANGE']} lets runs on different "
                f"hosts meet in one domain"
            )
        else:
            continue
        raise ExperimentError(
            f"--engine ros2 on Dask needs a ROS domain of its own for each run, but on worker "
            f"{worker} {why}; unset it where the workers start"
        )


@contextmanager
def dask_client(scheduler: str | None, jobs: int, engine: str, quiet: bool) -> Iterator:
    """A Dask client: of the scheduler at ``scheduler``, or of a LocalCluster of ``jobs``
    single-threaded worker processes started here and stopped on the way out (also on Ctrl-C).

    Raises:
        ExperimentError: the scheduler cannot be reached, or the ros2 engine is refused
            (:func:`_check_ros_workers`).
    """
    import logging

    from dask.distributed import Client, LocalCluster

    from swarm_ros.app.dask_workers import QuietHeartbeatAtClose

    cluster = client = None
    quiet_after_interrupt = _QuietAfterInterrupt()
    tornado_log = logging.getLogger("tornado.application")
    tornado_log.addFilter(quiet_after_interrupt)
    handlers = quiet_after_interrupt.watch()
    try:
        if scheduler:
            try:
                client = Client(scheduler, timeout=_CONNECT_TIMEOUT)
            except (OSError, TimeoutError, ValueError) as exc:
                text = str(exc).strip()
                raise ExperimentError(
                    f"cannot reach the Dask scheduler at {scheduler}: "
                    f"{text.splitlines()[0] if text else type(exc).__name__}"
                ) from None
        else:
            with _workers_ignore_sigint():  # a Ctrl-C is this process's to act on: it stops the workers
                cluster = LocalCluster(
                    n_workers=jobs,
                    threads_per_worker=1,
                    processes=True,
                    dashboard_address=":0",
                    silence_logs=logging.ERROR,
                )
            client = Client(cluster)
            client.register_plugin(QuietHeartbeatAtClose(), name=QuietHeartbeatAtClose.name)  # ours alone
        if not quiet:
            where = scheduler or f"a LocalCluster of {jobs} workers"
            print(f"swarm-ros: Dask: {where}, dashboard {client.dashboard_link}", file=sys.stderr, flush=True)
        if engine == "ros2":
            _check_ros_workers(client)
        _WATCHING.append(quiet_after_interrupt)  # execute_dask checks it at every run finished
        yield client
    finally:
        try:
            if client is not None:
                client.close()
            if cluster is not None:
                cluster.close()
        finally:
            tornado_log.removeFilter(quiet_after_interrupt)
            quiet_after_interrupt.unwatch(handlers)
            if quiet_after_interrupt in _WATCHING:
                _WATCHING.remove(quiet_after_interrupt)


class _QuietAfterInterrupt:
    """Drops the error records of Dask's event loop once the user interrupted the experiment.

    A Ctrl-C that lands while the client waits on its loop (``distributed.utils.sync``) makes the loop log a
    traceback of its own (a ``NameError`` in the cancel callback of distributed 2026.8): noise, not a fault of
    the run, printed after the command already said it was interrupted. Until then nothing is dropped.
    """

    def __init__(self) -> None:
        self.interrupted = False
        self.signum = 0  #: the last SIGINT or SIGTERM that came
        self._hook: Any = None  #: sys.unraisablehook before watch(), given back by unwatch()

    def filter(self, record: object) -> bool:
        return not self.interrupted

    def check(self) -> None:
        """Raise the interrupt noted, if Python lost it: a handler's KeyboardInterrupt raised while a garbage
        collector's callback runs (Dask's GC diagnosis) is printed and dropped, and the experiment ran on to its
        end (CI saw exit 0 after a Ctrl-C). The main thread checks at every run finished.

        Raises:
            KeyboardInterrupt: a SIGINT or SIGTERM came.
        """
        if self.interrupted:
            raise KeyboardInterrupt

    def watch(self) -> dict:
        """Note a SIGINT or SIGTERM before its handler raises (the loop logs as soon as the raise reaches the
        wait); the handlers before, to give back to :meth:`unwatch`. Nothing in a thread other than the main.

        Where Python cannot raise the handler's KeyboardInterrupt, it prints it as "Exception ignored", with a
        traceback, and drops it: inside a garbage collector's callback (Dask's scheduler adds one), a weakref's
        callback or a finalizer. ``sys.unraisablehook`` then gets it instead: it prints nothing and sends the
        signal again :data:`_RESEND_S` later, when the main thread is likely elsewhere (and :meth:`check`
        raises it at the next run finished at the latest)."""
        import signal
        import threading

        if threading.current_thread() is not threading.main_thread():
            return {}
        before: dict[signal.Signals, Any] = {}
        for sig in (signal.SIGINT, signal.SIGTERM):
            handler = signal.getsignal(sig)
            if callable(handler):  # Python's, not the OS's
                before[sig] = handler

        def noted(signum: int, frame: Any) -> None:
            self.interrupted, self.signum = True, signum
            before[signal.Signals(signum)](signum, frame)

        hook = sys.unraisablehook

        def dropped(unraisable: Any) -> None:
            if self.signum and isinstance(unraisable.exc_value, KeyboardInterrupt):
                threading.Timer(_RESEND_S, os.kill, (os.getpid(), self.signum)).start()
                return
            hook(unraisable)

        for sig in before:
            signal.signal(sig, noted)
        if before:
            self._hook, sys.unraisablehook = hook, dropped
        return before

    def unwatch(self, before: dict) -> None:
        """Give the handlers and ``sys.unraisablehook`` back, from the main thread (a cluster closed in another
        thread leaves :meth:`watch`'s in place: they hand each signal on to the ones before)."""
        import signal
        import threading

        if threading.current_thread() is not threading.main_thread():
            return
        for sig, handler in before.items():
            signal.signal(sig, handler)
        if self._hook is not None:
            self._hook, sys.unraisablehook = None, self._hook


_RESEND_S = 0.05  #: seconds after which an interrupt Python dropped (see _QuietAfterInterrupt.watch) is sent again
_WATCHING: list[_QuietAfterInterrupt] = []  #: the open Dask sessions' watchers (signals are the process's)


@contextmanager
def _workers_ignore_sigint() -> Iterator[None]:
    """Ignore SIGINT in this process while the block starts worker processes, which keep ignoring it for good.

    A terminal's Ctrl-C reaches every process of its group: a LocalCluster's workers would each print a
    traceback of their own. Only an ignored signal stays ignored across the exec that starts a worker (a
    handler, or a blocked mask, does not), so the workers are started while this process ignores it too; this
    process then stops them on the way out. A Ctrl-C in that second (the cluster's start) is not seen.
    """
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    before = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, before)


def run_specs(specs: list[RunSpec], engine: str, processes: int) -> list[dict]:
    """The rows of a few runs, one after the other: one Dask task (see :func:`execute_dask`)."""
    return [run_spec(spec, engine, processes) for spec in specs]


def chunk_size(run_seconds: float | None, remaining: int, workers: int) -> int:
    """How many runs the next Dask task holds, given the typical time of a run (None: not known yet).

    One, until finished runs tell how long runs take. Then about ``_TASK_SECONDS`` of runs,
    so that Dask's cost per task (a few milliseconds of scheduling and messages, much of a
    12 ms paper-protocol run) is spread over many short runs, while runs that take seconds
    (a ROS 2 graph, a large world) go one per task. Near the end, tasks shrink to half a
    worker's share of what is left, so that the workers finish together, but not below
    ``_MIN_TASK_SECONDS`` of runs.
    """
    if run_seconds is None or remaining <= 0:
        return 1
    run_seconds = max(run_seconds, 1e-6)
    balanced = max(remaining // (2 * max(workers, 1)), math.ceil(_MIN_TASK_SECONDS / run_seconds))
    return max(1, min(int(_TASK_SECONDS / run_seconds), balanced, remaining))


def execute_dask(client, todo: list[RunSpec], engine: str, processes: int) -> Generator[dict, None, None]:
    """Yield the row of each run as it finishes, computed on ``client``'s cluster.

    Only the runs' coordinates (:class:`RunSpec`) go to the workers and only rows come back.
    Runs go out a few tasks at a time (``_IN_FLIGHT`` per worker), each holding
    :func:`chunk_size` runs, judged by the median time of the last runs (a worker's first
    run also loads the engine). A worker that dies loses nothing finished here: Dask runs
    its tasks again elsewhere. Closing the generator (or an exception in the caller, e.g.
    Ctrl-C) cancels what is left.
    """
    from collections import deque

    from dask.distributed import as_completed

    if not todo:
        return
    workers = max(1, len(client.scheduler_info().get("workers", {})))
    queue = list(todo)
    submitted = []
    pending = as_completed()
    recent: deque[float] = deque(maxlen=32)  # seconds of the last runs

    def submit() -> None:
        chunk = chunk_size(float(np.median(recent)) if recent else None, len(queue), workers)
        specs = queue[:chunk]
        del queue[:chunk]
        future = client.submit(
            run_specs,
            specs,
            engine,
            processes,
            pure=False,
            key=f"swarm_ros-runs-{specs[0].shape}-{specs[0].robots}-{specs[0].repetition}-"
            f"{len(specs)}-{uuid.uuid4().hex[:8]}",
        )
        submitted.append(future)
        pending.add(future)

    try:
        while queue and len(submitted) < _IN_FLIGHT * workers:
            submit()
        for future in pending:
            for watching in _WATCHING:  # a Ctrl-C that Python dropped (_QuietAfterInterrupt.check)
                watching.check()
            rows = future.result()
            recent.extend(max(float(row["wall_seconds"]), 0.0) for row in rows)
            while queue and pending.count() < _IN_FLIGHT * workers:
                submit()
            yield from rows
    finally:
        client.cancel(submitted)


def default_jobs() -> int:
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
