"""numba's on-disk cache of the core's compiled kernels: is it filled, and fill it.

The core's hot loops are numba functions compiled with ``cache=True``: the first
process that calls one after an install (or after a change to the core) compiles it,
about 17 s for all of them (2D and 3D) on a 2-core machine, and writes it into ``__pycache__``
beside the source; later processes load it in milliseconds. ``scripts/setup.sh`` fills
the cache (``python -m swarm_ros.core.kernels``), so the first run does not pay for it;
``swarm-ros simulate`` and ``swarm-ros run`` say so in one line when they have to, and
``run`` compiles once, before its node processes start, rather than in each of them.

:func:`kernels_cached` loads neither numba nor the kernels: it only looks at files. A kernel
that is only ever inlined into others (``inline="always"``) is not saved again when its module
changes, so its index can stay older than its source for good: :func:`compile_kernels` leaves a
stamp file, and a stamp newer than every kernel module says the cache is filled.

numba keys a kernel's cache by its own module's source only, yet links into it the code of the
kernels it calls: after an edit to ``rules.py`` the cached ``run_kernel`` (``tick_kernel.py``) would
go on running the old rule. :func:`drop_stale` removes what was cached before the last change to
any kernel module; :func:`compile_kernels` and the test suite's start call it. (An install brings
new sources, whose times numba sees: this is for a working tree.)
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path

_CORE = Path(__file__).resolve().parent
_CACHE = _CORE / "__pycache__"
_MARK = "cache=True"  # a module with a cached kernel says so in its source
_STAMP = "swarm_ros-kernels.compiled"  # in _CACHE: compile_kernels() ran after the last change to a kernel module
#: What the commands say before they compile (one line, on stderr).
COMPILING = (
    "compiling the numba kernels first (once after an install or a change to the core, about 17 s; "
    "scripts/setup.sh does it too)"
)


def _packages() -> tuple[Path, ...]:
    """The core and its second algorithm's package."""
    return (_CORE, _CORE / "rubenstein")


def _kernel_modules() -> list[Path]:
    return [
        p
        for package in _packages()
        for p in sorted(package.glob("*.py"))
        if p.name != "kernels.py" and _MARK in p.read_text("utf-8")
    ]


def _cached(suffix: str) -> list[Path]:
    """numba's cache files of every package (their module names are unique: test_layers)."""
    return [path for package in _packages() for path in (package / "__pycache__").glob(f"*.{suffix}")]


def kernels_cached() -> bool:
    """Whether the cache is filled: :func:`compile_kernels`' stamp is newer than every core module with a
    cached kernel, or each such module has an index in numba's cache newer than its source.

    Answers True when the cache is somewhere this function does not look
    (``NUMBA_CACHE_DIR`` set): it never claims work it cannot see.
    """
    if os.environ.get("NUMBA_CACHE_DIR"):
        return True
    try:
        sources = _kernel_modules()
        stamp = _CACHE / _STAMP
        if stamp.exists() and stamp.stat().st_mtime >= max(p.stat().st_mtime for p in sources):
            return True
        indexes = {p.name: p.stat().st_mtime for p in _cached("nbi")}
        for source in sources:
            changed = source.stat().st_mtime
            if not any(name.startswith(f"{source.stem}.") and at >= changed for name, at in indexes.items()):
                return False
    except OSError:
        return False
    return True


def drop_stale() -> int:
    """Remove the core's cached kernels written before the last change to any kernel module (numba's
    ``<module>.<kernel>-<line>.py<version>.nbi`` and ``.nbc`` files of these modules, nothing else); how many.
    Does nothing with the cache elsewhere (``NUMBA_CACHE_DIR`` set)."""
    if os.environ.get("NUMBA_CACHE_DIR"):
        return 0
    dropped = 0
    try:
        sources = _kernel_modules()
        newest = max(p.stat().st_mtime for p in sources)
        stems = {p.stem for p in sources}
        for path in [*_cached("nbi"), *_cached("nbc")]:
            if path.name.split(".", 1)[0] in stems and path.stat().st_mtime < newest:
                path.unlink(missing_ok=True)
                dropped += 1
    except (OSError, ValueError):  # no cache directory, a read-only install: nothing to do, or nothing it may do
        pass
    return dropped


def count_compiles() -> Callable[[], int]:
    """Count, from now on, the kernels numba compiles in this process (its ``numba:compile`` event, which a load
    from the cache does not raise); return what says how many so far. Nodes log it when ready: a node that
    compiled took the seconds the cache is there to save, whatever the machine's speed."""
    from numba.core import event

    class _Count(event.Listener):
        compiled = 0

        def on_start(self, ev: event.Event) -> None:
            self.compiled += 1

        def on_end(self, ev: event.Event) -> None:
            pass

    count = _Count()
    event.register("numba:compile", count)
    return lambda: count.compiled


def compile_kernels() -> None:
    """Compile every kernel into numba's cache: two ticks of the graph's code path and a few of the
    in-process engine's, on the star and on the 3D k-block, and a few of the rubenstein algorithm's, with the
    default parameters (the kernels' types do not depend on them)."""
    from swarm_ros.core.engine import Simulation
    from swarm_ros.core.grid import World
    from swarm_ros.core.params import RUBENSTEIN, RunParams
    from swarm_ros.core.rubenstein.run import KilobotRun
    from swarm_ros.core.shapes import Shape
    from swarm_ros.core.warmup import warm_up

    drop_stale()
    for name in ("star", "k-block"):  # a 2D and a 3D shape: the 3D kernels are compiled apart
        shape = Shape.load(name, World())
        params = RunParams(robots=shape.patches)
        warm_up(shape, params)
        Simulation(shape, params).run(max_ticks=5)
    shape = Shape.load("rectangle", World())
    KilobotRun(shape, RunParams(robots=50, algorithm=RUBENSTEIN)).run(max_ticks=5)
    try:
        (_CACHE / _STAMP).touch()
    except OSError:
        pass  # a read-only install: the indexes alone answer kernels_cached()


def main() -> int:
    """``python -m swarm_ros.core.kernels``: drop stale kernels, then fill the cache if it is not (prints what it
    did)."""
    if drop_stale():
        print("swarm_ros: dropped the kernels cached before the last change to the core")
    if kernels_cached():
        print("swarm_ros: the numba kernels are compiled and cached")
        return 0
    import time

    start = time.perf_counter()
    compile_kernels()
    print(f"swarm_ros: compiled the numba kernels into their cache in {time.perf_counter() - start:.1f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
