"""The graph's OS processes: a node's command and environment, its exit in words, stopping them all, and the
ROS domain id a run holds on its host (``swarm-ros run``, :mod:`swarm_ros.app.launcher`)."""

from __future__ import annotations

import fcntl
import os
import random
import re
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO

from swarm_ros.app.forking import Forked
from swarm_ros.core.errors import InputError, RunFailed
from swarm_ros.core.signals import PARENT_ENV
from swarm_ros.protocol.plan import WORLD, shard_name
from swarm_ros.protocol.runkey import with_run_key
from swarm_ros.ros.dds import apply_dds_defaults
from swarm_ros.ros.shm import SHM_DIR, clean_shm, shm_locks

DOMAIN_IDS = range(1, 102)  # 0 is everyone's default; above 101 ports can clash on Linux
# SIGTERM first, not SIGINT: a process started from a background job inherits SIGINT *ignored*, and a node
# ignores it until its own handler is in (after rclpy.init); SIGTERM ends it at once before that, and after it
# means what SIGINT means (stop between callbacks, write what there is to write).
_STOP_STEPS = ((signal.SIGTERM, 5.0), (signal.SIGKILL, 2.0))


class LaunchError(RunFailed):
    """The graph could not run to the end; the message says which process and where its log is (a run failure,
    not bad input: the command exits 1)."""


@dataclass
class Child:
    name: str
    proc: subprocess.Popen | Forked
    log: Path
    log_file: IO = field(repr=False)
    command: list[str] = field(default_factory=list)
    incarnation: int = 0
    shm: set[str] = field(default_factory=set)  #: Fast DDS shared-memory lock files it was seen holding open
    exit_noted: bool = False

    def scan_shm(self) -> None:
        """Remember the Fast DDS shared-memory files this process has open (while it runs)."""
        self.shm |= shm_locks(self.proc.pid)

    def last_error(self) -> str:
        """The last line of the process's log that reports an error, or "" if none does."""
        try:
            lines = [ln.strip() for ln in self.log.read_text(errors="replace").splitlines() if ln.strip()]
        except OSError:
            return ""
        errors = [ln for ln in lines if "error" in ln.lower()]
        return errors[-1] if errors else ""


class DomainLock:
    """A ROS domain id reserved for this run through an exclusive lock file (released by close())."""

    def __init__(self, fixed: int | None = None) -> None:
        self.file: IO | None = None
        if fixed is not None:
            self.domain_id = fixed
            return
        lock_dir = Path(tempfile.gettempdir()) / "swarm_ros-domains"
        lock_dir.mkdir(exist_ok=True)
        ids = list(DOMAIN_IDS)
        start = random.randrange(len(ids))
        for d in ids[start:] + ids[:start]:
            f = open(lock_dir / f"{d}.lock", "w")
            try:
                fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                f.close()
                continue
            self.file, self.domain_id = f, d
            return
        raise LaunchError(
            f"every ROS domain id in {DOMAIN_IDS.start}..{DOMAIN_IDS.stop - 1} is in use by "
            f"other swarm-ros runs; set ROS_DOMAIN_ID to choose one"
        )

    def close(self) -> None:
        if self.file is not None:
            self.file.close()
            self.file = None


#: An SROS2 enclave path prefix: ``/name`` parts of letters, digits and underscores.
ENCLAVE_PREFIX = re.compile(r"(/[A-Za-z_][A-Za-z0-9_]*)+")


def death(code: int) -> str:
    """How a process ended, for a message: 'was killed by SIGKILL', 'exited with status 1'."""
    if code < 0:
        try:
            return f"was killed by {signal.Signals(-code).name}"
        except ValueError:
            return f"was killed by signal {-code}"
    return f"exited with status {code}"


def check_graph_shape(shape: str) -> None:
    """Refuse a shape source the graph's nodes cannot each read, by its file type alone, before anything opens it:
    a named pipe with no writer would block the command's own read for ever.

    Raises:
        InputError: the shape names a file that exists but is not a regular file (a pipe, /dev/null, a device).
    """
    import stat

    from swarm_ros.core.shapes import builtin_shapes, builtin_shapes_3d

    if shape in builtin_shapes() or shape in builtin_shapes_3d():
        return
    try:
        mode = os.stat(shape).st_mode
    except (OSError, ValueError):
        return  # missing or unreadable: the shape's loader says so in its own words
    if not stat.S_ISREG(mode):  # a pipe, /dev/null: 'simulate' reads one once, but each node reads it too
        raise InputError(
            f"{shape}: not a regular file; each node of the graph reads the shape file "
            f"itself, so the graph needs a file ('simulate' reads a pipe once)"
        )


def check_graph(
    shape,
    params,
    processes: int,
    enclaves: str | None,
    flags: tuple[str, str] = ("--processes", "--enclaves"),
    region_cuts: str = "",
    world_shards: int = 1,
) -> None:
    """Refuse a graph that cannot run, before any node starts (``swarm-ros run`` and the launch file).

    Raises:
        InputError: a shape source the nodes cannot each read, too little memory, fewer columns than
            batches, region cuts that do not cut the world into ``processes`` strips (the algorithm's
            ``check_graph``), a bad enclave path; in one line (``flags``: how the user named the batch count and
            the enclaves).
        LaunchError: a Fast DDS port in /dev/shm would keep the nodes from starting (:func:`check_shared_memory`).
    """
    from swarm_ros.core.algorithm import algorithm_of
    from swarm_ros.core.resources import check_world_memory

    check_world_memory(shape.world.radius, copies=processes + 1 + world_shards)  # the world(s), the monitor, batches
    if world_shards > processes:
        raise InputError(
            f"--world-shards {world_shards} is more than the {processes} robot-batch processes ({flags[0]}): "
            f"each world shard owns the strips of one batch at least"
        )
    own_checks = algorithm_of(params.algorithm).hook("check_graph")
    if own_checks is not None:
        own_checks(shape, params, processes, region_cuts, flags[0])
    if enclaves is not None and not ENCLAVE_PREFIX.fullmatch(enclaves):
        raise InputError(
            f"{flags[1]} must be an enclave path like /swarm_ros (names of letters, digits and _ "
            f"after each /), got {enclaves!r}"
        )
    check_shared_memory()


def check_shared_memory() -> None:
    """Refuse to start nodes that would wait for ever in Fast DDS's ``Node()`` on a port a killed process left half
    made (:func:`swarm_ros.ros.shm.half_made_ports`).

    Raises:
        LaunchError: naming the file, and what to do.
    """
    from swarm_ros.ros.shm import half_made_ports

    wedged = half_made_ports()
    if wedged:
        raise LaunchError(
            f"{wedged[0]}: a Fast DDS shared-memory port a killed process left half made (0 bytes); every ROS 2 "
            f"process on this host that opens it waits for ever. No process holds it: remove it, then run again"
        )


def node_env(domain_id: int, log_dir: Path) -> dict[str, str]:
    env = dict(os.environ)
    env[PARENT_ENV] = str(os.getpid())
    env["ROS_DOMAIN_ID"] = str(domain_id)
    apply_dds_defaults(env)
    env["ROS_LOG_DIR"] = str(log_dir / "ros")
    env.setdefault("HOME", str(log_dir))
    env["PYTHONUNBUFFERED"] = "1"
    env["RCUTILS_COLORIZED_OUTPUT"] = "0"
    return with_run_key(env)


def node_command(
    module: str, params_file: Path, name: str, extra: Mapping[str, object] | None = None, enclaves: str | None = None
) -> list[str]:
    """The command of a node process; with ``enclaves`` (SROS2), its enclave is ``<enclaves>/<name>``."""
    cmd = [
        sys.executable,
        "-m",
        f"swarm_ros.nodes.{module}",
        "--ros-args",
        "--params-file",
        str(params_file),
        "-r",
        f"__node:={name}",
    ]
    if enclaves:
        cmd += ["--enclave", f"{enclaves}/{name}"]
    for key, value in (extra or {}).items():
        cmd += ["-p", f"{key}:={value}"]
    return cmd


def stop(children: list[Child]) -> None:
    """End every child still running: SIGTERM, then SIGKILL, to its process group, waiting between."""
    for sig, wait in _STOP_STEPS:
        alive = [c for c in children if c.proc.poll() is None]
        if not alive:
            break
        for c in alive:
            try:
                os.killpg(c.proc.pid, sig)
            except ProcessLookupError:  # a forked node not yet in its own session (app/forking.py)
                try:
                    os.kill(c.proc.pid, sig)
                except ProcessLookupError:
                    pass
        deadline = time.monotonic() + wait
        while time.monotonic() < deadline and any(c.proc.poll() is None for c in alive):
            time.sleep(0.02)
    for c in children:
        c.proc.wait()
        c.log_file.close()


CHECKPOINT = "world.checkpoint"  #: the world's checkpoint file in the run's logs (removed at the end)


def world_sections(world: dict, shards: int, logs: Path) -> dict[str, dict]:
    """The parameter file's section of the world node, or (``shards`` > 1) of each world shard: the world's own
    parameters, each process with its checkpoint in ``logs`` (world shard i's: ``world.checkpoint.<i>``)."""
    if shards == 1:
        return {WORLD: {**world, "checkpoint": str(logs / CHECKPOINT)}}
    return {shard_name(i): {**world, "checkpoint": str(logs / f"{CHECKPOINT}.{i}")} for i in range(shards)}


#: In the run's logs while it goes on: the Fast DDS lock files its processes hold in /dev/shm, a line each, for
#: the next 'run' of the same directory to remove (recover_killed) if this launcher is SIGKILLed before it does.
SHM_LIST = "shm-files"


def logs_target(out: Path, ok: bool) -> Path:
    """Where a run's logs go: ``<run>/logs``, or for a failed run ``<run>.logs`` (``<run>.logs.2``, ... if taken:
    an existing directory is never replaced)."""
    if ok and out.is_dir():
        return out / "logs"
    target, n = out.parent / f"{out.name}.logs", 1
    while target.exists():
        n += 1
        target = out.parent / f"{out.name}.logs.{n}"
    return target


def recover_killed(out: Path) -> list[Path]:
    """Tidy what an earlier ``run`` of ``out`` that was SIGKILLed left beside it; return where its logs went.

    Its hidden logs folder (``.<out>.logs-XXXXXXXX``) becomes ``<out>.logs`` (``.2``, ... if taken), said in one
    line; its world checkpoint is removed; the Fast DDS files of its processes (listed in :data:`SHM_LIST`) that
    no live process uses are removed from /dev/shm. Call it while holding ``out``
    (:func:`~swarm_ros.artifacts.run_dir.claim_out_dir`): no live command then owns such a folder.
    """
    out = out.absolute()
    kept = []
    for hidden in sorted(out.parent.glob(f".{out.name}.logs-*")):
        if not hidden.is_dir() or hidden.is_symlink():
            continue
        try:
            listed = (hidden / SHM_LIST).read_text(encoding="utf-8", errors="replace").split()
        except OSError:
            listed = []
        clean_shm(
            {
                f
                for f in listed
                if Path(f).parent == SHM_DIR and Path(f).name.startswith("fastrtps_") and f.endswith("_el")
            }
        )  # its own file, but checked: only Fast DDS lock files in /dev/shm
        for f in hidden.glob(CHECKPOINT + "*"):
            f.unlink(missing_ok=True)
        target = logs_target(out, False)
        try:
            hidden.rename(target)
        except OSError:
            continue
        kept.append(target)
        print(f"swarm-ros: an earlier run of {out} was killed; its logs are now in {target}", file=sys.stderr)
    return kept


def check_central_graph(shape, params, processes: int, region_cuts: str, flag: str) -> None:
    """Refuse, in one line, a batch count (``processes``, whatever ``flag`` named it) or region cuts (x positions in
    its unit) a central world's grid of columns (core.strips) cannot be cut by.

    Raises:
        InputError: that.
    """
    from swarm_ros.core.algorithm import algorithm_of
    from swarm_ros.core.strips import strips_for

    engine = algorithm_of(params.algorithm).hook("engine")(shape, params)
    if processes > engine.grid.nx:
        raise InputError(
            f"a world of {engine.grid.nx} columns cannot be cut into {processes} strips, one per "
            f"robot-batch process ({flag}, default 2); each strip needs at least one column"
        )
    strips_for(engine, processes, region_cuts)


def compile_first(algorithm: str, quiet: bool) -> bool:
    """Fill numba's cache of ``algorithm``'s kernels, in a process of its own, if it is empty, saying so in one line
    (unless ``quiet``): every node process would otherwise compile the same kernels at the same time. Return whether
    it compiled.

    Raises:
        LaunchError: compiling failed, with its last line.
    """
    from swarm_ros.core.kernels import compiling_note, kernels_cached

    if kernels_cached(algorithm):
        return False
    if not quiet:
        print(f"swarm-ros: {compiling_note(algorithm)}", file=sys.stderr, flush=True)
    done = subprocess.run(
        [sys.executable, "-m", "swarm_ros.core.kernels", algorithm],
        stdin=subprocess.DEVNULL,
        capture_output=True,
        text=True,
    )
    if done.returncode != 0:
        lines = (done.stderr or done.stdout).strip().splitlines()
        raise LaunchError(f"compiling the numba kernels failed ({lines[-1] if lines else done.returncode})")
    return True
