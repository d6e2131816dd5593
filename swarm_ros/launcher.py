"""``swarm-ros run``: one run over the ROS 2 graph, each node its own OS process.

The launcher starts the monitor, K robot-batch processes and the world, follows the
run's progress on /swarm/metrics, and waits for the monitor to write the run
directory. Then it lets every process end by itself, and stops those that do not
(SIGINT, then SIGTERM, then SIGKILL, to the process group of each). If any process
fails, or the user interrupts, it stops them all the same way.

Each run gets a ROS domain id of its own (unless ROS_DOMAIN_ID is set), held through a
lock file so two runs on one machine never share one, and discovery stays on the host
(unless ROS_AUTOMATIC_DISCOVERY_RANGE is set). The processes' output and ROS logs go
to ``<run>/logs``; if the run fails they are kept in ``<run>.logs`` instead.
"""

from __future__ import annotations

import fcntl
import os
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO

from .config import RecordingOptions, Settings
from .core.errors import SwarmError
from .core.params import RunParams
from .core.shapes import Shape
from .nodes.params import params_yaml

DOMAIN_IDS = range(1, 102)  # 0 is everyone's default; above 101 ports can clash on Linux
_STOP_STEPS = ((signal.SIGINT, 3.0), (signal.SIGTERM, 2.0), (signal.SIGKILL, 2.0))
_GRACE = 10.0  # seconds the world and batches get to end by themselves after the monitor is done


class LaunchError(SwarmError):
    """The graph could not run to the end; the message says which process and where its log is."""


@dataclass
class Child:
    name: str
    proc: subprocess.Popen
    log: Path
    log_file: IO = field(repr=False)

    def last_error(self) -> str:
        """The process's last 'error' line, else its last non-empty line."""
        try:
            lines = [ln.strip() for ln in self.log.read_text(errors="replace").splitlines() if ln.strip()]
        except OSError:
            return ""
        errors = [ln for ln in lines if "error" in ln.lower()]
        return (errors or lines or [""])[-1]


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
            f = open(lock_dir / f"{d}.lock", "w")  # noqa: SIM115 - held for the run
            try:
                fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                f.close()
                continue
            self.file, self.domain_id = f, d
            return
        raise LaunchError(f"every ROS domain id in {DOMAIN_IDS.start}..{DOMAIN_IDS.stop - 1} is in use by "
                          f"other swarm-ros runs; set ROS_DOMAIN_ID to choose one")

    def close(self) -> None:
        if self.file is not None:
            self.file.close()
            self.file = None


def node_env(domain_id: int, log_dir: Path) -> dict[str, str]:
    env = dict(os.environ)
    env["ROS_DOMAIN_ID"] = str(domain_id)
    env.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    env["ROS_LOG_DIR"] = str(log_dir / "ros")
    env.setdefault("HOME", str(log_dir))
    env["PYTHONUNBUFFERED"] = "1"
    env["RCUTILS_COLORIZED_OUTPUT"] = "0"
    return env


def node_command(module: str, params_file: Path, name: str, extra: dict[str, object] | None = None) -> list[str]:
    cmd = [sys.executable, "-m", f"swarm_ros.nodes.{module}", "--ros-args", "--params-file", str(params_file),
           "-r", f"__node:={name}"]
    for key, value in (extra or {}).items():
        cmd += ["-p", f"{key}:={value}"]
    return cmd


def stop(children: list[Child]) -> None:
    """End every child still running: SIGINT, SIGTERM, SIGKILL to its process group, waiting between."""
    for sig, wait in _STOP_STEPS:
        alive = [c for c in children if c.proc.poll() is None]
        if not alive:
            break
        for c in alive:
            try:
                os.killpg(c.proc.pid, sig)
            except ProcessLookupError:
                pass
        deadline = time.monotonic() + wait
        while time.monotonic() < deadline and any(c.proc.poll() is None for c in alive):
            time.sleep(0.02)
    for c in children:
        c.proc.wait()
        c.log_file.close()


def interrupted_run(out: Path) -> dict | None:
    """The summary in ``out`` if it is the run directory of an interrupted run, else None."""
    import json

    try:
        summary = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return summary if summary.get("outcome") == "interrupted" else None


@dataclass
class Launch:
    """One ``swarm-ros run``. Call :meth:`run`; it returns the run directory."""

    settings: Settings
    shape: Shape
    params: RunParams
    processes: int
    out: Path
    overwrite: bool = False
    quiet: bool = False
    domain_id: int | None = None
    recording: RecordingOptions = field(default_factory=RecordingOptions)
    children: list[Child] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)  #: processes lost during the run

    def run(self) -> Path:
        out = self.out.absolute()
        out.parent.mkdir(parents=True, exist_ok=True)
        logs = Path(tempfile.mkdtemp(prefix=f".{out.name}.logs-", dir=out.parent))  # a fresh name: replaces nothing
        (logs / "ros").mkdir()
        lock = DomainLock(self.domain_id)
        ok = interrupted = False
        try:
            self._start(logs, lock.domain_id, out)
            self._follow()
            ok = True
        except LaunchError as exc:
            raise LaunchError(f"{exc} (logs: {self._logs_target(out, False)})") from None
        except KeyboardInterrupt:
            interrupted = True
            raise
        finally:
            stop(self.children)  # an interrupted monitor writes the run so far before it exits
            lock.close()
            self._keep_logs(logs, out, ok or (interrupted and interrupted_run(out) is not None))
        return out

    def _start(self, logs: Path, domain_id: int, out: Path) -> None:
        shape_arg = self.settings.shape
        if Path(shape_arg).suffix.lower() in (".txt", ".png"):
            shape_arg = str(Path(shape_arg).absolute())
        run = Settings(**{**self.settings.__dict__, "shape": shape_arg, "robots": self.params.robots})
        viewer = self.recording.connect or ""
        if self.recording.spawn:
            from .recording import spawn_viewer

            viewer = spawn_viewer()
        params_file = logs / "params.yaml"
        params_file.write_text(params_yaml(run, {"world": {}, "monitor": {
            "out_dir": str(out), "overwrite": self.overwrite, "record": self.recording.enabled,
            "record_every": self.recording.every, "viewer_url": viewer}}), encoding="utf-8")
        env = node_env(domain_id, logs)
        self.domain = domain_id
        plan = [("monitor", "monitor", {})]
        plan += [(f"robot_batch_{k}", "robot_batch", {"batch": k, "batches": self.processes})
                 for k in range(self.processes)]
        plan.append(("world", "world", {}))
        for name, module, extra in plan:
            log = logs / f"{name}.log"
            f = open(log, "wb")  # noqa: SIM115 - closed in stop()
            proc = subprocess.Popen(node_command(module, params_file, name, extra), env=env, stdout=f,
                                    stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, start_new_session=True)
            self.children.append(Child(name, proc, log, f))

    def _follow(self) -> None:
        """Show progress until the monitor has written the run.

        A robot-batch process that dies is the world's business: it notices (liveliness),
        removes that batch's robots and goes on; the launcher reports the exit. A monitor
        that dies is reported too, and the swarm runs to its end without it; the command
        then fails, as nothing wrote the run directory (the recording so far stays in
        ``<run>.partial.rrd``). The world failing fails the run at once.
        """
        from .nodes.progress import Progress

        monitor = next(c for c in self.children if c.name == "monitor")
        world = next(c for c in self.children if c.name == "world")
        reported: set[str] = set()
        world_done_at = None
        with Progress(self.domain, self.shape.patches, quiet=self.quiet) as progress:
            while True:
                progress.spin(0.1)
                for c in self.children:
                    code = c.proc.poll()
                    if code not in (None, 0) and c is not world and c.name not in reported:
                        reported.add(c.name)
                        then = ("the world removes its robots and the run goes on" if c is not monitor else
                                "the swarm goes on without it, but nothing will write the run directory")
                        self.warnings.append(f"{c.name} exited with status {code} ({c.last_error() or 'no output'})"
                                             f"; {then}")
                        progress.bar.write(f"swarm-ros: warning: {self.warnings[-1]}", file=sys.stderr)
                if world.proc.returncode not in (None, 0):
                    raise LaunchError(f"world exited with status {world.proc.returncode}: "
                                      f"{world.last_error() or 'no output'}")
                if monitor.proc.returncode == 0:
                    break
                if world.proc.returncode == 0 and world_done_at is None:
                    world_done_at = time.monotonic()
                if world_done_at is not None and monitor.proc.returncode is not None:
                    raise LaunchError(f"the monitor was lost (status {monitor.proc.returncode}); the swarm ran to its "
                                      f"end without it, but no run directory was written")
                if world_done_at is not None and time.monotonic() - world_done_at > 3 * _GRACE:
                    raise LaunchError(f"the run ended but the monitor did not write it within {3 * _GRACE:g} s")
        deadline = time.monotonic() + _GRACE
        while time.monotonic() < deadline and any(c.proc.poll() is None for c in self.children):
            time.sleep(0.05)

    @staticmethod
    def _logs_target(out: Path, ok: bool) -> Path:
        """Where the logs go: ``<run>/logs``, or for a failed run ``<run>.logs`` (``<run>.logs.2``, ... if taken:
        an existing directory is never replaced)."""
        if ok and out.is_dir():
            return out / "logs"
        target, n = out.parent / f"{out.name}.logs", 1
        while target.exists():
            n += 1
            target = out.parent / f"{out.name}.logs.{n}"
        return target

    def _keep_logs(self, logs: Path, out: Path, ok: bool) -> None:
        target = self._logs_target(out, ok)
        try:
            if target.exists():
                raise FileExistsError(target)  # an existing directory is never replaced
            logs.rename(target)
        except OSError:
            shutil.rmtree(logs, ignore_errors=True)
