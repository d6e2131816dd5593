"""What a run needs from its machine: the package's data (shapes/, config/) and memory for its world.

The data folders are found for source, editable and normal installs.

A source checkout or an editable install (``pip install -e .``) reads the folders beside
the package; a normal install (``pip install .`` or colcon) has them under
``<prefix>/share/swarm_ros/`` through setup.py's data_files.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

from swarm_ros.core.algorithm import algorithm_of
from swarm_ros.core.errors import ParameterError

PACKAGE = "swarm_ros"


def _candidates(kind: str) -> list[Path]:
    here = Path(__file__).resolve().parent.parent.parent  # repository root when run from source
    dirs = [here / kind] if (here / "package.xml").is_file() else []
    dirs.append(Path(sys.prefix) / "share" / PACKAGE / kind)
    for prefix in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep):
        if prefix:
            dirs.append(Path(prefix) / "share" / PACKAGE / kind)
    return dirs


def data_dir(kind: str) -> Path:
    """The installed ``shapes`` or ``config`` folder.

    Raises:
        FileNotFoundError: the package's data files are not installed anywhere we look.
    """
    for d in _candidates(kind):
        if d.is_dir():
            return d
    looked = ", ".join(str(d) for d in _candidates(kind))
    raise FileNotFoundError(f"swarm_ros data folder '{kind}' not found (looked in {looked})")


#: Memory a run takes per patch of its world, in bytes, in each process that holds the world: peak RSS of
#: ``swarm-ros simulate --world-radius R --max-ticks 3`` grew by 92 bytes per patch from R = 500 to R = 1500
#: (recording on; 84 without), rounded up.
BYTES_PER_PATCH = 100


def available_memory() -> int | None:
    """Bytes of memory available to new allocations now (``MemAvailable``), or None where that cannot be read."""
    try:
        with open("/proc/meminfo", encoding="ascii") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def check_robot_memory(robots: int, algorithm: str) -> None:
    """Refuse a swarm too large for this machine's memory, before anything is allocated for it.

    Raises:
        ParameterError: in one line, with the memory needed and the memory available.
    """
    available = available_memory()
    per = algorithm_of(algorithm).bytes_per_robot  # core.algorithm: measured for each
    if available is None or per * robots <= available:
        return
    raise ParameterError(
        f"{robots:,} robots need about {_amount(per * robots)} under {algorithm} ({per:,} bytes each), more "
        f"than the {_amount(available)} of memory available now; at most {available // per:,} fit"
    )


def _amount(n: float) -> str:
    """``3.5 GiB``, ``600.0 MiB``: an amount of memory as a user reads it."""
    return f"{n / 1024**3:,.1f} GiB" if n >= 1024**3 else f"{n / 1024**2:,.1f} MiB"


def check_world_memory(radius: int, copies: int = 1, dims: int = 2) -> None:
    """Refuse a world too large for this machine's memory, before anything is allocated.

    ``copies``: the processes that each hold the world (1 in-process; for the ROS graph the
    world, the monitor and each robot batch).

    Raises:
        ParameterError: in one line, with the memory needed and the memory available.
    """
    available = available_memory()
    if available is None or not isinstance(radius, int) or radius < 3:
        return  # not Linux, or a bad radius (World says why)
    side = 2 * radius + 1
    needed = side**dims * BYTES_PER_PATCH * copies
    if needed > available:
        largest = int(((available / (BYTES_PER_PATCH * copies)) ** (1 / dims) - 1) // 2)
        gib = 1024**3
        each = f" in each of {copies} processes" if copies > 1 else ""
        shape = " x ".join([str(side)] * dims)
        raise ParameterError(
            f"world_radius {radius} needs about {needed / gib:,.1f} GiB ({shape} patches at "
            f"{BYTES_PER_PATCH} bytes each{each}), more than the {available / gib:.1f} GiB of "
            f"memory available now; at most {largest} fits"
        )
