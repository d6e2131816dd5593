"""The package as a ROS 2 user has it: built with the real colcon in a workspace, and ROS 2 Jazzy's own
command-line tools (``ros2 launch``, ``run``, ``topic``, ``node``, ``param``, ``pkg``).

No PyPI wheel ships those tools; their jazzy sources come with this project's test machines, beside the
checkout (``shared/ros2-jazzy-cli`` in its parent directory, or the directory ``SWARM_ROS_ROS2_CLI`` names),
with an ``install.sh VENV``. :func:`ros2_tools` installs them into ``.venv`` once (about 15 s), or skips the test
with the reason when they are not there. Commands run as a user runs them: ``. install/setup.sh`` first,
then the venv's prefix on ``AMENT_PREFIX_PATH`` (the message packages' ament index lives there) and its
``bin`` on ``PATH`` (the node scripts start with ``/usr/bin/env python3``: setup.cfg).
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
VENV = ROOT / ".venv"
COLCON = ROOT / ".venv-colcon" / "bin" / "colcon"
CLI_SOURCE = Path(os.environ.get("SWARM_ROS_ROS2_CLI", ROOT.parent / "shared" / "ros2-jazzy-cli"))
SOURCES = (
    "setup.py",
    "setup.cfg",
    "package.xml",
    "pyproject.toml",
    "resource",
    "swarm_ros",
    "shapes",
    "config",
    "launch",
    "rviz",
)
NODES = ("/monitor", "/robot_batch_0", "/robot_batch_1", "/world")  # the default graph (processes:=2)


def _sources_only(directory: str, names: list[str]) -> set[str]:
    """What a copy of the package's tree leaves out: Python's bytecode, but not numba's kernel cache, which a clone
    that ran scripts/setup.sh holds beside the sources and colcon installs with them (setup.py)."""
    if Path(directory).name == "__pycache__":
        return {n for n in names if not n.endswith((".nbi", ".nbc", ".compiled"))}
    return set()


def build_workspace(ws: Path) -> Path:
    """Copy the package's sources (and the kernels' cache, as scripts/setup.sh left it) into ``ws/src`` and
    ``colcon build`` them; return ``ws/install``."""
    if not COLCON.exists():
        pytest.skip("colcon is not installed in .venv-colcon (scripts/setup.sh installs it)")
    src = ws / "src" / "swarm_ros"
    src.mkdir(parents=True)
    for name in SOURCES:
        path = ROOT / name
        if path.is_dir():
            shutil.copytree(path, src / name, ignore=_sources_only)
        else:
            shutil.copy2(path, src / name)
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "AMENT_PREFIX_PATH")}
    done = subprocess.run(
        [str(COLCON), "--log-base", "log", "build", "--base-paths", "src"],
        cwd=ws,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    assert "1 package finished" in done.stdout
    return ws / "install"


def install_ros2_tools() -> Path:
    """``.venv/bin/ros2``, installed from :data:`CLI_SOURCE` if it is not yet; skips the test without it."""
    ros2 = VENV / "bin" / "ros2"
    if not (CLI_SOURCE / "install.sh").is_file():
        pytest.skip(
            f"ROS 2's command-line tools are not here ({CLI_SOURCE}; set SWARM_ROS_ROS2_CLI to their "
            f"directory with install.sh)"
        )
    if not ros2.exists():
        done = subprocess.run(
            ["bash", str(CLI_SOURCE / "install.sh"), str(VENV)], capture_output=True, text=True, timeout=600
        )
        assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    return ros2


class Ros2:
    """A shell of a ROS 2 user: the workspace sourced, on a ROS domain of its own, logs under ``home``."""

    def __init__(self, install: Path, home: Path, domain_id: int):
        self.install, self.home = install, home
        base = {
            k: v
            for k, v in os.environ.items()
            if k
            not in (
                "PYTHONPATH",
                "AMENT_PREFIX_PATH",
                "ROS_DOMAIN_ID",
                "ROS_AUTOMATIC_DISCOVERY_RANGE",
                "FASTRTPS_DEFAULT_PROFILES_FILE",
                "SWARM_ROS_RUN_KEY",
                "COLCON_PREFIX_PATH",
            )
        }
        self.env = {
            **base,
            "HOME": str(home),
            "ROS_LOG_DIR": str(home / "ros-log"),
            "ROS_DOMAIN_ID": str(domain_id),
            "PYTHONUNBUFFERED": "1",
            "PATH": f"{VENV / 'bin'}:{os.environ.get('PATH', '/usr/bin:/bin')}",
        }
        self.prelude = f'. "{install}/setup.sh" && export AMENT_PREFIX_PATH="$AMENT_PREFIX_PATH:{VENV}" && '

    def command(self, line: str) -> list[str]:
        return ["bash", "-c", self.prelude + "exec " + line]

    def run(self, line: str, timeout: float = 60, cwd: Path | None = None) -> subprocess.CompletedProcess:
        """Run one command line (``ros2 ...``) to its end."""
        return subprocess.run(
            self.command(line), cwd=cwd or self.home, env=self.env, capture_output=True, text=True, timeout=timeout
        )

    def start(self, line: str, cwd: Path | None = None, log: Path | None = None) -> subprocess.Popen:
        """Start one command line in a session of its own (a terminal's process group: see :func:`ctrl_c`),
        its output (stdout and stderr) into ``log``."""
        out = open(log, "w") if log else subprocess.DEVNULL
        return subprocess.Popen(
            self.command(line),
            cwd=cwd or self.home,
            env=self.env,
            stdout=out,
            stderr=subprocess.STDOUT,
            start_new_session=True,
            text=True,
        )

    def launch_logs(self) -> list[Path]:
        """The log directories of the launches so far, oldest first (each holds params.yaml)."""
        found = [p for p in (self.home / "ros-log").glob("*/params.yaml") if not p.parent.is_symlink()]  # 'latest'
        return sorted(found, key=lambda p: p.stat().st_mtime)


def ctrl_c(proc: subprocess.Popen) -> None:
    """What Ctrl-C in its terminal does: SIGINT to every process of the foreground process group."""
    os.killpg(proc.pid, signal.SIGINT)


def stop(proc: subprocess.Popen, timeout: float) -> None:
    """Ctrl-C, then wait for ``proc`` to end; one that does not within ``timeout`` has its whole process group
    SIGKILLed (no process outlives the test that started it) and the wait's TimeoutExpired raised."""
    ctrl_c(proc)
    try:
        proc.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
        raise
