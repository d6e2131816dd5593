"""``swarm-ros run``: one run over the ROS 2 graph, each node its own OS process.

The launcher loads the kernels every node uses, then forks the monitor, K robot-batch processes
and the world from itself (:mod:`swarm_ros.app.forking`; a restarted node is started afresh), follows the
run's progress on /swarm/status, and waits for the monitor to write the run
directory. Then it lets every process end by itself, and stops those that do not
(SIGTERM, then SIGKILL, to the process group of each). If any process
fails, or the user interrupts, it stops them all the same way.

A robot-batch process that dies is started again (``on_batch_loss="restart"``, up to
``max_restarts`` times per batch) with the same robots and the next incarnation
number; the world sends it the current tick and the run goes on as if nothing had
happened. Under ``"remove"`` a batch lost after tick 0 is not restarted and the world
removes its robots; one lost before tick 0 is restarted under both policies, since
none of its robots has moved yet. A world or monitor killed by a signal is started again
too (up to ``max_restarts`` times each, under both policies): the world goes on from its
checkpoint (``<logs>/world.checkpoint``), the monitor from the bag its process before
wrote (docs/faults.md); one that exits with an error fails the run. These rules are
:class:`swarm_ros.app.supervision.Supervisor`'s, which the launch file follows too.
Every node ends by itself within moments of the launcher's death (SIGHUP from the kernel:
``PR_SET_PDEATHSIG``, set by the node at start-up, see :func:`swarm_ros.ros.runtime.follow_parent`). After the run, the
shared-memory files of Fast DDS that its dead processes left in /dev/shm are removed
(only files those processes had open, and only if no live process holds them).

Each run gets a ROS domain id of its own (unless ROS_DOMAIN_ID is set), held through a
lock file so two runs on one machine never share one, and discovery stays on the host
(unless ROS_AUTOMATIC_DISCOVERY_RANGE is set). The processes' output and ROS logs go
to ``<run>/logs``; if the run fails they are kept in ``<run>.logs`` instead.
"""

from __future__ import annotations

import json
import os
import shutil
import sys
import tempfile
import threading
import time
from contextlib import nullcontext
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

from swarm_ros.app.forking import Forked, can_fork, preload, start_node
from swarm_ros.app.param_file import params_yaml
from swarm_ros.app.processes import (
    CHECKPOINT,
    SHM_LIST,
    Child,
    DomainLock,
    LaunchError,
    compile_first,
    logs_target,
    node_command,
    node_env,
    stop,
    world_sections,
)
from swarm_ros.app.supervision import END_GRACE, LATE_STATUS, MONITOR_GRACE, Supervisor
from swarm_ros.artifacts.recording_options import RecordingOptions
from swarm_ros.artifacts.run_dir import OutputError, fill_summary, partial_bag, partial_recording, public_mode
from swarm_ros.core.algorithm import algorithm_of
from swarm_ros.core.params import RunParams, Settings, node_defaults
from swarm_ros.core.shapes import Shape
from swarm_ros.core.signals import StopFlag, process_age
from swarm_ros.protocol.plan import MONITOR, is_world, plan_for
from swarm_ros.protocol.runkey import KEY_ENV, run_key
from swarm_ros.ros.shm import clean_shm, register, shm_locks, tidy_dead_runs, unregister


def plural(n: int, noun: str) -> str:
    """``1 robot-batch process``, ``2 robot-batch processes``."""
    return f"{n} {noun}" if n == 1 else f"{n} {noun}{'es' if noun.endswith('s') else 's'}"


def _bag_holders(out: Path) -> set[Path]:
    """The hidden folders a monitor streams the bag of ``out`` into while it runs (``.<run>.bag-XXXX``)."""
    return set(out.parent.glob(f".{out.name}.bag-*"))


def _identity(path: Path) -> tuple[int, int] | None:
    """(device, inode) of ``path``, or None if there is nothing there."""
    try:
        st = path.stat()
    except OSError:
        return None
    return st.st_dev, st.st_ino


def discard_unstarted(logs: Path, out: Path, holders_before: set[Path], made: list[Path]) -> None:
    """Remove what a run interrupted before tick 0 made: its logs, and the recording and bag its monitor had
    opened (``<out>.partial.rrd``, ``<out>.partial-bag``), and the folders ``made`` for it while empty.
    Nothing else can be there: the command refuses to
    start while an earlier run's are (:func:`swarm_ros.artifacts.run_dir.check_leftovers`) or while another command
    holds ``out`` (:func:`swarm_ros.artifacts.run_dir.claim_out_dir`)."""
    shutil.rmtree(logs, ignore_errors=True)
    rrd, bag = partial_recording(out), partial_bag(out)
    try:
        rrd.unlink()
    except FileNotFoundError:
        pass
    shutil.rmtree(bag, ignore_errors=True)
    for hidden in _bag_holders(out) - holders_before:  # this run's monitor was killed with its bag open
        shutil.rmtree(hidden, ignore_errors=True)
    for d in made:  # the folders the run made for ``out`` (e.g. runs/), if still empty
        try:
            d.rmdir()
        except OSError:
            break


@dataclass
class Launch:
    """One ``swarm-ros run``. Call :meth:`run`; it returns the run directory."""

    settings: Settings
    shape: Shape
    params: RunParams
    processes: int
    out: Path
    region_cuts: str = ""  #: where the batches' strips start (x positions), or "": balanced at tick 0
    world_shards: int = 1  #: world processes: 1 the world node, S > 1 world shards by region
    overwrite: bool = False
    quiet: bool = False
    domain_id: int | None = None
    recording: RecordingOptions = field(default_factory=RecordingOptions)
    world: dict = field(default_factory=dict)  #: the world node's own parameters (on_batch_loss, max_restarts, ...)
    bag: bool = True  #: the monitor writes bag/, a rosbag2 of the run
    enclaves: str | None = None  #: SROS2: each node's enclave is <enclaves>/<node> (docs/security.md)
    children: list[Child] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)  #: processes lost during the run
    #: (tick, name) of each node process restarted: the last tick the world's status had reported when it was
    restarts: list[tuple[int, str]] = field(default_factory=list)
    shm_removed: list[str] = field(default_factory=list)  #: shared-memory files left by dead processes, removed
    own_shm: set[str] = field(default_factory=set)  #: Fast DDS lock files of this process's own node
    timeline: list[tuple[float, str]] = field(default_factory=list)  #: (epoch seconds, event), to logs/launcher.log
    ended_at: float | None = None  #: time.monotonic() when the world's outcome arrived
    started: bool = False  #: the world has sent tick 0 (as far as this process has heard)
    logs_kept: Path | None = None  #: where the processes' logs went at the end
    _shm_listed: int = 0  #: how many shared-memory lock files SHM_LIST holds

    def _note(self, event: str, at: float | None = None) -> None:
        self.timeline.append((time.time() if at is None else at, event))

    @property
    def on_batch_loss(self) -> str:
        return str(self.world.get("on_batch_loss", node_defaults("world")["on_batch_loss"]))

    @property
    def max_restarts(self) -> int:
        return int(self.world.get("max_restarts", node_defaults("world")["max_restarts"]))

    @cached_property
    def supervisor(self) -> Supervisor:
        """What is done when a node process ends: the rules the launch file follows too."""
        removes = algorithm_of(self.params.algorithm).removes_lost_robots
        said = ("--on-batch-loss remove", "--max-restarts")
        return Supervisor(self.max_restarts, self.on_batch_loss, removes, said, stops=frozenset())  # a signal: a fault

    def run(self) -> Path:
        run_key()  # a SWARM_ROS_RUN_KEY that is set but unusable fails here, before anything is made
        self.shm_removed += tidy_dead_runs()  # what a SIGKILLed earlier run, of any directory, left in /dev/shm
        out = self.out.absolute()
        made = [d for d in (out.parent, *out.parent.parents) if not d.exists()]  # deepest first
        out.parent.mkdir(parents=True, exist_ok=True)
        logs = Path(tempfile.mkdtemp(prefix=f".{out.name}.logs-", dir=out.parent))  # a fresh name: replaces nothing
        public_mode(logs, directory=True)
        (logs / "ros").mkdir()
        self._note("command started", at=time.time() - process_age())
        holders = _bag_holders(out)
        self.out_before = _identity(out)
        lock = DomainLock(self.domain_id)
        ok = interrupted = unwritten = False
        try:
            self._start(logs, lock.domain_id, out)
            self._follow()
            ok = True
        except LaunchError as exc:
            raise LaunchError(f"{exc} (logs: {logs_target(out, False)})") from None
        except OSError as exc:  # the file system refused (a full disk): before a node started, nothing to keep
            unwritten = not self.children
            raise LaunchError(
                f"{exc.filename or out}: {exc.strerror or exc}"
                + ("" if unwritten else f" (logs: {logs_target(out, False)})")
            ) from None
        except KeyboardInterrupt:
            interrupted = True
            raise
        finally:
            with StopFlag() as late:  # a Ctrl-C from here on waits until what the run made is in its place
                stop(self.children)  # an interrupted monitor writes the run so far before it exits
                self._note_exits()
                self._note("all node processes gone")
                kept = ok or (interrupted and self.result() is not None)  # Ctrl-C'd after the run was written
                if kept:  # an interrupted run too; its shutdown time only once the world's outcome was heard
                    ended = self.ended_at
                    shutdown = {} if ended is None else {"shutdown_seconds": round(time.monotonic() - ended, 3)}
                    try:
                        fill_summary(out, self.restarts, processes=self.processes, **shutdown)
                    except OutputError as exc:  # the run stands; what the launcher adds to it is missing: said
                        self._note(str(exc))
                        self._warn(None, str(exc))
                lock.close()
                # its own node is shut down by now, but Fast DDS keeps the segments it mapped (a killed peer's
                # too) mapped in this process: this process is not a user that keeps them
                seen = set().union(self.own_shm, *(c.shm for c in self.children))
                self.shm_removed += clean_shm(seen, frozenset({os.getpid()}))
                unregister(os.getpid())
                for f in [*logs.glob(CHECKPOINT + "*"), logs / SHM_LIST]:  # of no use once the run is over
                    f.unlink(missing_ok=True)
                if (interrupted or unwritten) and not kept and not self.started:
                    discard_unstarted(logs, out, holders, made)
                else:
                    try:
                        self._write_timeline(logs / "launcher.log")
                    except OSError:  # a full disk: the logs are kept without the launcher's timeline
                        pass
                    self._keep_logs(logs, out, kept)
            if late.signum and ok:  # the run is whole; the command still ends as interrupted
                raise KeyboardInterrupt
        return out

    def _start(self, logs: Path, domain_id: int, out: Path) -> None:
        if compile_first(self.params.algorithm, self.quiet):  # once, here, not in every node at once
            self._note("numba kernels compiled")
        if can_fork() and algorithm_of(self.params.algorithm).warm_up:  # forked from here (app/forking.py)
            preload(self.shape, self.params, sorted({role for _, role, _ in self.plan()}))
        shape_arg = self.settings.shape
        if Path(shape_arg).suffix.lower() in (".txt", ".png"):
            shape_arg = str(Path(shape_arg).absolute())
        run = Settings(**{**self.settings.__dict__, "shape": shape_arg, "robots": self.params.robots})
        viewer = self.recording.connect or ""
        if self.recording.spawn:
            from swarm_ros.artifacts.rerun_recording import spawn_viewer

            viewer = spawn_viewer() or ""
        params_file = logs / "params.yaml"
        params_file.write_text(
            params_yaml(
                run,
                {
                    **world_sections(
                        {
                            **self.world,
                            "on_batch_loss": self.on_batch_loss,
                            "max_restarts": self.max_restarts,
                            "record_every": self.recording.every,  # the world publishes the robots that often
                        },
                        self.world_shards,
                        logs,
                    ),
                    "monitor": {
                        "out_dir": str(out),
                        "overwrite": self.overwrite,
                        "record": self.recording.enabled,
                        "record_every": self.recording.every,
                        "viewer_url": viewer,
                        "bag": self.bag,
                    },
                },
            ),
            encoding="utf-8",
        )
        self.env = node_env(domain_id, logs)
        self.domain = domain_id
        self.params_file = params_file
        for name, module, extra in self.plan():
            log = logs / f"{name}.log"
            self.children.append(
                self._spawn(name, node_command(module, params_file, name, extra, self.enclaves), log, 0)
            )
        if not self.quiet:
            print(
                f"swarm-ros: ROS domain {domain_id}, {plural(self.processes, 'robot-batch process')}, logs in {logs} "
                f"(kept in the run directory at the end)",
                file=sys.stderr,
                flush=True,
            )

    def plan(self) -> list[tuple[str, str, dict[str, int | str]]]:
        """The node processes, in start order: (node name, executable, parameters beyond the file's).

        ``launch/swarm.launch.py`` starts the same graph (:func:`swarm_ros.protocol.plan.plan_for`).
        """
        return plan_for(self.params.algorithm, self.processes, self.region_cuts, self.world_shards)

    def _spawn(self, name: str, command: list[str], log: Path, incarnation: int) -> Child:
        f = open(log, "ab")
        if incarnation:
            f.write(f"--- swarm-ros: restarted, incarnation {incarnation} ---\n".encode())
            f.flush()
        full = command + (["-p", f"incarnation:={incarnation}"] if incarnation else [])
        proc = start_node(full, self.env, f)
        self._note(f"started {name} (pid {proc.pid}{', forked' if isinstance(proc, Forked) else ''})")
        return Child(name, proc, log, f, command=command, incarnation=incarnation)

    def _restart(self, old: Child, tick: int) -> Child:
        """Start a dead node's process again (``tick``: the run's tick, as the world's status last said it): same
        robots, next incarnation."""
        old.log_file.close()
        new = self._spawn(old.name, old.command, old.log, old.incarnation + 1)
        new.shm = old.shm  # cleaned up after the run, with everyone's
        self.children[self.children.index(old)] = new
        self.restarts.append((max(tick, 0), old.name))
        return new

    def _follow(self) -> None:
        """Show progress until the monitor has written the run.

        A robot-batch process that dies is restarted (see the module's doc); one that may
        not be restarted is the world's business: it notices (liveliness), removes that
        batch's robots and goes on; the launcher reports the exit. A world or monitor killed
        by a signal is restarted (:meth:`_restart_core`); one that exits with an error, or
        dies once more than the bound, fails the run at once. A monitor killed after it
        wrote the run directory leaves the run whole (:meth:`_written`).
        """
        from swarm_ros.tools.progress import Progress

        reported: set[str] = set()
        monitor_done = False
        world_done_at = None
        scanned_at = 0.0
        # Ctrl-C and SIGTERM are taken as a flag and acted on between spins: a KeyboardInterrupt raised
        # inside the executor's call of a Python callback comes out as a RuntimeError from pybind11.
        # (Signal handlers can only be set from the main thread; a Dask worker runs this in another.)
        stop = StopFlag() if threading.current_thread() is threading.main_thread() else None
        key = self.env[KEY_ENV].encode()
        algorithm = algorithm_of(self.params.algorithm)
        with (
            stop or nullcontext(),
            Progress(
                self.domain,
                self.shape.patches,
                key,
                quiet=self.quiet,
                enclaves=self.enclaves,
                unit=algorithm.progress_unit,
                what=algorithm.progress_what,
            ) as progress,
        ):
            while True:
                if stop is not None and stop.signum:
                    raise KeyboardInterrupt
                # once the world's outcome is out no messages come to wake the spin: look at the
                # processes every 10 ms, so the monitor's exit is seen as it happens
                progress.spin(0.1 if progress.ended_at is None else 0.01)
                self.ended_at = progress.ended_at
                self.started = progress.started
                now = time.monotonic()
                if now - scanned_at > 0.5:  # processes open their shared memory once, at start-up
                    scanned_at = now
                    for c in self.children:
                        c.scan_shm()
                    self.own_shm |= shm_locks(os.getpid())  # this process's node (the progress bar's)
                    self._list_shm()
                self._note_exits()
                for c in list(self.children):
                    code = c.proc.poll()
                    if code is None or code == 0 or c.name in reported:
                        continue
                    if c.name == MONITOR and self._written():
                        monitor_done = True  # killed after it wrote the run directory: the run is whole
                        break
                    # the run has ended: the world exited, or its outcome is out (its status); the world's own
                    # word that tick 0 went out decides whether a batch lost under 'remove' is started again
                    self.supervisor.world_ended = world_done_at is not None or progress.ended_at is not None
                    verdict = self.supervisor.exited(c.name, code, why=c.last_error() or "", started=progress.started)
                    if verdict.end or verdict.stop:
                        raise LaunchError(verdict.end or verdict.stop)
                    if verdict.restart:
                        self._restart(c, progress.tick)
                        world_done_at = None if c.name == MONITOR else world_done_at
                    else:
                        reported.add(c.name)
                    if verdict.note:
                        self._warn(progress, verdict.note)
                monitor = self._child(MONITOR)
                if monitor_done or monitor.proc.returncode == 0:
                    break
                worlds = [c for c in self.children if is_world(c.name)]
                if all(w.proc.returncode == 0 for w in worlds) and world_done_at is None:
                    world_done_at = time.monotonic()
                if world_done_at is not None and time.monotonic() - world_done_at > MONITOR_GRACE:
                    raise LaunchError(f"the run ended but the monitor did not write it within {MONITOR_GRACE:g} s")
            # while the others end, the world's outcome may still reach this node after the monitor wrote the run
            # (a loaded machine): the shutdown time counts from it
            deadline = time.monotonic() + END_GRACE
            while time.monotonic() < deadline:
                progress.spin(0.01)
                self.ended_at = progress.ended_at
                self._note_exits()
                if all(c.proc.poll() is not None for c in self.children):
                    deadline = min(deadline, time.monotonic() + (0 if self.ended_at else LATE_STATUS))

    def _list_shm(self) -> None:
        """Write the shared-memory lock files seen so far into the logs (:data:`SHM_LIST`), when there are new ones."""
        seen = set().union(self.own_shm, *(c.shm for c in self.children))
        if len(seen) != self._shm_listed:
            self._shm_listed = len(seen)
            try:
                (self.params_file.parent / SHM_LIST).write_text(
                    "".join(f"{f}\n" for f in sorted(seen)), encoding="utf-8"
                )
            except OSError:
                pass  # a full disk: only the clean-up after a SIGKILL misses them
            register(os.getpid(), seen)  # for any later run, whatever its output directory (tidy_dead_runs)

    def _child(self, name: str) -> Child:
        return next(c for c in self.children if c.name == name)

    def result(self) -> dict | None:
        """The summary of the run directory this run's monitor wrote (whole, whatever its outcome), or None."""
        if not self._written():
            return None
        try:
            return json.loads((self.out.absolute() / "summary.json").read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return None

    def _written(self) -> bool:
        """Whether the monitor wrote the run directory: ``out`` is there now, and is not what was there before
        the run (the monitor writes it whole under another name, then renames it: it is complete)."""
        now = _identity(self.out.absolute())
        return now is not None and now != self.out_before and (self.out.absolute() / "summary.json").is_file()

    def _note_exits(self) -> None:
        for c in self.children:
            if c.proc.poll() is not None and not c.exit_noted:
                c.exit_noted = True
                self._note(f"{c.name} exited with status {c.proc.returncode}")

    def _write_timeline(self, path: Path) -> None:
        """The launcher's clock: when each process started and ended (epoch seconds, as in the ROS logs)."""
        path.write_text("".join(f"[{at:.6f}] {event}\n" for at, event in self.timeline), encoding="utf-8")

    def _warn(self, progress, text: str) -> None:
        """Say ``text`` as a warning: above the progress bar, or on stderr once there is none."""
        self.warnings.append(text)
        (progress.bar.write if progress is not None else print)(f"swarm-ros: warning: {text}", file=sys.stderr)

    def _keep_logs(self, logs: Path, out: Path, ok: bool) -> None:
        target = logs_target(out, ok)
        try:
            if target.exists():
                raise FileExistsError(target)  # an existing directory is never replaced
            logs.rename(target)
            self.logs_kept = target
        except OSError:
            shutil.rmtree(logs, ignore_errors=True)
