"""numba's on-disk cache of the core's compiled kernels, by algorithm: is it filled, and fill it.

The core's hot loops are numba functions compiled with ``cache=True``: the first
process that calls one after an install (or after a change to the core) compiles it
and writes it into ``__pycache__`` beside the source; later processes load it in milliseconds.
Each algorithm's kernels are compiled apart, on first use, so a user of one does not wait for the
other's (scripts/bench_compile.py measures them: about 40 s for the study's model's, 2D and 3D, and 17 s
for the rubenstein algorithm's, on a quiet 2-core machine; docs/benchmarks.md). ``scripts/setup.sh``
fills the cache of both at once, one process each (``python -m swarm_ros.core.kernels ALGORITHM``), so
the first run does not pay for it; ``swarm-ros simulate`` and ``swarm-ros run`` say so in one line
when they have to, and ``run`` compiles once, before its node processes start, rather than in each of
them. The cache travels with the package: setup.py installs ``__pycache__``'s kernel files with the
sources, and numba keys a cached kernel by its source's contents, so a colcon or pip install made after
``scripts/setup.sh`` loads what setup compiled.

:func:`kernels_cached` loads neither numba nor the kernels: it only looks at files. :func:`compile_kernels`
leaves a stamp file per algorithm, and only a stamp newer than every kernel module of the algorithm says its cache
is filled. numba's own index files cannot say it: a kernel that is only ever inlined into others
(``inline="always"``) is not saved again when its module changes, so its index can stay older than its source for
good; and a process that compiled some kernels on first use (``ros2 launch`` resolving a rubenstein run's pack
compiles three) leaves indexes beside a cache that is only partly filled.

numba keys a kernel's cache by its own module's source only, yet links into it the code of the
kernels it calls: after an edit to ``rules.py`` the cached ``run_kernel`` (``tick_kernel.py``) would
go on running the old rule. :func:`drop_stale` removes what was cached before the last change to
any kernel module; :func:`compile_kernels` and the test suite's start call it. (An install brings
new sources, whose times numba sees: this is for a working tree.)
"""

from __future__ import annotations

import os
import sys
from collections.abc import Callable
from pathlib import Path

from swarm_ros.core.algorithm import algorithm_of, names

_CORE = Path(__file__).resolve().parent
_CACHE = _CORE / "__pycache__"
_MARK = "cache=True"  # a module with a cached kernel says so in its source
_STAMP = "swarm_ros-kernels-{}.compiled"  # in _CACHE: compile_kernels() ran after the last change to its modules


def compiling_note(algorithm: str) -> str:
    """What the commands say before they compile ``algorithm``'s kernels (one line, on stderr)."""
    return (
        f"compiling the {algorithm} algorithm's numba kernels first (once after an install or a change to the core, "
        f"about {algorithm_of(algorithm).compile_seconds} s; scripts/setup.sh does it too)"
    )


def _kernel_modules(algorithm: str | None = None) -> list[Path]:
    """The modules with a cached kernel: ``algorithm``'s, or every algorithm's, once each. An algorithm's are those
    of its package (core.algorithm's ``kernel_dir``) and the core's modules its kernels call (its
    ``shared_kernels``): a change to one leaves its cache stale."""
    modules: dict[Path, None] = {}
    for name in names() if algorithm is None else (algorithm,):
        entry = algorithm_of(name)
        own = sorted((_CORE / entry.kernel_dir).glob("*.py")) if entry.kernel_dir else []
        for path in [*own, *(_CORE / m for m in entry.shared_kernels)]:
            if _MARK in path.read_text("utf-8"):
                modules[path] = None
    return list(modules)


def _cached(suffix: str) -> list[Path]:
    """numba's cache files beside every algorithm's kernel modules (their module names are unique: test_layers)."""
    folders = dict.fromkeys(path.parent / "__pycache__" for path in _kernel_modules())
    return [path for folder in folders for path in folder.glob(f"*.{suffix}")]


def kernels_cached(algorithm: str | None = None) -> bool:
    """Whether ``algorithm``'s cache (or every algorithm's) is filled: :func:`compile_kernels`' stamp is newer than
    every module of it with a cached kernel. (A read-only install shipped without the stamp answers False each
    time: the commands then run :func:`compile_kernels`, which loads what numba cached where it could write.)

    Answers True when the cache is somewhere this function does not look
    (``NUMBA_CACHE_DIR`` set): it never claims work it cannot see; and for an algorithm with no ``compile`` hook
    (no kernels of its own).
    """
    if os.environ.get("NUMBA_CACHE_DIR"):
        return True
    if algorithm is None:
        return all(kernels_cached(a) for a in names())
    if not algorithm_of(algorithm).compile:  # no kernels of its own to compile
        return True
    try:
        stamp = _CACHE / _STAMP.format(algorithm)
        return stamp.stat().st_mtime >= max(p.stat().st_mtime for p in _kernel_modules(algorithm))
    except OSError:  # no stamp
        return False


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


def compile_kernels(algorithm: str | None = None) -> None:
    """Compile ``algorithm``'s kernels (or every algorithm's) into numba's cache: under the study's model, two
    ticks of the graph's code path and a few of the in-process engine's, on the star and on the 3D k-block; under
    rubenstein, a few ticks of its run; with the default parameters (the kernels' types do not depend on them)."""
    drop_stale()
    for name in names() if algorithm is None else (algorithm,):
        compile_ = algorithm_of(name).hook("compile")
        if compile_ is None:  # no kernels of its own
            continue
        compile_()
        try:
            (_CACHE / _STAMP.format(name)).touch()
        except OSError:
            pass  # a read-only install: kernels_cached() answers False, and the next command loads what it cached


def main(argv: list[str] | None = None) -> int:
    """``python -m swarm_ros.core.kernels [ALGORITHM ...]``: drop stale kernels, then fill the cache of each
    algorithm named (default: every one) whose cache is not filled (prints what it did)."""
    known = names()
    asked = list(sys.argv[1:] if argv is None else argv) or list(known)
    unknown = [n for n in asked if n not in known]
    if unknown:
        print(f"swarm_ros: no algorithm {unknown[0]!r} (known: {', '.join(known)})", file=sys.stderr)
        return 2
    if drop_stale():
        print("swarm_ros: dropped the kernels cached before the last change to the core")
    import time

    for name in asked:
        if kernels_cached(name):
            print(f"swarm_ros: the {name} algorithm's numba kernels are compiled and cached")
            continue
        start = time.perf_counter()
        compile_kernels(name)
        print(
            f"swarm_ros: compiled the {name} algorithm's numba kernels into their cache in "
            f"{time.perf_counter() - start:.1f} s"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
