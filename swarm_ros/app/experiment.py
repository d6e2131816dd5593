"""``swarm-ros experiment``: a grid of shapes x group sizes x vision radii x repetitions.

An experiment file is YAML::

    name: paper                 # names the default output directory, experiments/<name>
    seed: 2026                  # experiment seed; each run's seed derives from it and the run's coordinates
    repetitions: 10
    vision_radius: [1]          # one number or a list
    rules: [paper, local]       # optional: one rule set or a list (default: paper)
    crowding: disc              # optional: override a switch (join, crowding, steps) for every rule set
    reference: study_reference.csv  # optional: published numbers to set beside ours (relative to this file)
    max_ticks: 100000           # optional, as for one run
    wiggle_deg: 45              # optional
    world_radius: 32            # optional
    fail_fraction: 0.1          # optional: this fraction of the robots fails at the end of tick fail_tick
    fail_tick: 500
    shapes:                     # built-in name or shape file (relative to this file) -> group sizes
      star: [1025, 1030, 1035, 1040, 1045, patches]   # 'patches' = the shape's exact patch count

Runs go to J worker processes. Each finished run is appended at once, as one line, to
``results.csv`` in the output directory, so an interrupted experiment loses only the
runs in flight, and running the same command again skips the runs already there. A
run's seed depends only on the experiment seed and its coordinates (shape, group size,
vision radius, repetition), never on J, on the order runs finish or on the rule set: the
rule sets of one experiment start from the same placements (common random numbers). At
the end the statistics and figures are (re)built (:mod:`swarm_ros.app.report`); a reference
file is copied into the output directory so the report can always find it.
"""

from __future__ import annotations

import json
import math
import numbers
import os
import sys
import tempfile
import threading
import uuid
import zlib
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from swarm_ros.app.param_file import check_world_memory, read_yaml
from swarm_ros.core.errors import SwarmError
from swarm_ros.core.params import DEFAULT_MAX_TICKS, DEFAULT_WIGGLE_DEG, MAX_SEED, RunParams
from swarm_ros.core.rulesets import DEFAULT_RULES, RULE_SETS, SWITCHES
from swarm_ros.core.shapes import Shape
from swarm_ros.core.grid import DEFAULT_RADIUS, World
from swarm_ros.app.published import load_reference
from swarm_ros.app.results_file import REFERENCE_FILE, RESULT_COLUMNS, RESULTS_FILE, ExperimentError, ResultsFile

EXPERIMENTS_DIR = Path("experiments")
EXPERIMENT_FILE = "experiment.json"
PATCHES = "patches"  #: a group size written as this word is the shape's exact patch count
ENGINES = ("inprocess", "ros2")

_KEYS = ("name", "seed", "repetitions", "vision_radius", "rules", "join", "crowding", "steps", "max_ticks",
         "wiggle_deg", "world_radius", "fail_fraction", "fail_tick", "reference", "shapes")
_REQUIRED = ("seed", "repetitions", "vision_radius", "shapes")
EXECUTORS = ("local", "dask")  #: where the runs go: worker processes here, or a Dask cluster
_CONNECT_TIMEOUT = "5s"  # to reach a Dask scheduler given by address
_TASK_SECONDS = 0.25  # seconds of runs a Dask task holds, once the runs' length is known (chunk_size)
_MIN_TASK_SECONDS = 0.05  # ... and at least this, near the end of a sweep of short runs
_IN_FLIGHT = 3  # Dask tasks submitted ahead per worker: it starts the next as soon as one ends


@dataclass(frozen=True)
class RunSpec:
    """One run of an experiment: its coordinates and everything needed to run it in another process."""

    shape: str  #: the shape's name (the file stem for a shape file)
    shape_file: str  #: what Shape.load takes: a built-in name or an absolute path
    robots: int
    vision_radius: float
    repetition: int
    seed: int
    max_ticks: int
    wiggle_deg: float
    world_radius: int
    fail_fraction: float = 0.0
    fail_tick: int = 0
    rules: str = DEFAULT_RULES
    join: str = ""  #: switch overrides ("" = the rule set's own)
    crowding: str = ""
    steps: str = ""

    @property
    def key(self) -> tuple[str, int, float, str, int]:
        return self.shape, self.robots, self.vision_radius, self.rules, self.repetition

    def params(self) -> RunParams:
        return RunParams(robots=self.robots, vision_radius=self.vision_radius, seed=self.seed,
                         max_ticks=self.max_ticks, wiggle_deg=self.wiggle_deg, fail_fraction=self.fail_fraction,
                         fail_tick=self.fail_tick, rules=self.rules, join=self.join, crowding=self.crowding,
                         steps=self.steps)


def run_seed(experiment_seed: int, shape: str, robots: int, vision_radius: float, repetition: int) -> int:
    """The seed of the run at these coordinates: numpy's SeedSequence over the experiment seed and the coordinates.

    The rule set is not a coordinate here: every rule set starts from the same placements."""
    key = (zlib.crc32(shape.encode()), robots, round(vision_radius * 1000), repetition)
    words = np.random.SeedSequence(entropy=experiment_seed, spawn_key=key).generate_state(2, dtype=np.uint32)
    return (int(words[0]) << 32 | int(words[1])) & MAX_SEED


@dataclass(frozen=True)
class Experiment:
    """A parsed, checked experiment file."""

    name: str
    seed: int
    repetitions: int
    vision_radius: tuple[float, ...]
    max_ticks: int
    wiggle_deg: float
    world_radius: int
    fail_fraction: float
    fail_tick: int
    shapes: tuple[tuple[str, str, int, tuple[int, ...]], ...]  #: (name, file, patches, sizes)
    rules: tuple[str, ...] = (DEFAULT_RULES,)
    join: str = ""
    crowding: str = ""
    steps: str = ""
    reference: str = ""  #: the reference file as the experiment file names it (relative to it), or ""

    def runs(self) -> list[RunSpec]:
        """Every run, in the canonical order: shape, group size, vision radius, rule set, repetition."""
        return [RunSpec(shape=name, shape_file=file, robots=n, vision_radius=v, repetition=r,
                        seed=run_seed(self.seed, name, n, v, r), max_ticks=self.max_ticks,
                        wiggle_deg=self.wiggle_deg, world_radius=self.world_radius,
                        fail_fraction=self.fail_fraction, fail_tick=self.fail_tick, rules=rules, join=self.join,
                        crowding=self.crowding, steps=self.steps)
                for name, file, _, sizes in self.shapes for n in sizes for v in self.vision_radius
                for rules in self.rules for r in range(self.repetitions)]

    def as_dict(self) -> dict:
        return asdict(self)


def _fail(path: Path, key: str, message: str) -> ExperimentError:
    return ExperimentError(f"{path}: {key}: {message}" if key else f"{path}: {message}")


def _integer(path: Path, key: str, value: object, low: int) -> int:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < low:
        raise _fail(path, key, f"must be an integer >= {low}, got {value!r}")
    return int(value)


def _number(path: Path, key: str, value: object, low: float, inclusive: bool) -> float:
    ok = isinstance(value, numbers.Real) and not isinstance(value, bool) and math.isfinite(value)
    if not ok or (value < low if inclusive else value <= low):
        raise _fail(path, key, f"must be a number {'>=' if inclusive else '>'} {low:g}, got {value!r}")
    return float(value)


def load_experiment(path: str | Path) -> Experiment:
    """Read and check an experiment file; every run's parameters are checked too, before any run starts.

    Raises:
        ExperimentError: unreadable file, bad YAML, unknown or missing key, bad value,
            unknown shape, or a group size that does not fit the world. The message
            names the file and the key.
    """
    path = Path(path)
    data = read_yaml(path, "experiment file", ExperimentError)
    if not isinstance(data, dict):
        raise _fail(path, "", f"expected a mapping with the keys {', '.join(_KEYS)}")
    for key in data:
        if key not in _KEYS:
            raise _fail(path, str(key), f"unknown key (known: {', '.join(_KEYS)})")
    for key in _REQUIRED:
        if key not in data:
            raise _fail(path, key, "missing")
    name = data.get("name", path.stem)
    if not isinstance(name, str) or not name.strip() or "/" in name:
        raise _fail(path, "name", f"must be a non-empty name without '/', got {name!r}")
    seed = _integer(path, "seed", data["seed"], 0)
    if seed > MAX_SEED:
        raise _fail(path, "seed", f"must be < 2**63, got {seed}")
    repetitions = _integer(path, "repetitions", data["repetitions"], 1)
    visions = data["vision_radius"]
    visions = visions if isinstance(visions, list) else [visions]
    if not visions:
        raise _fail(path, "vision_radius", "no vision radius given")
    vision = tuple(_number(path, f"vision_radius[{i}]", v, 1.0, True) for i, v in enumerate(visions))
    if len(set(vision)) != len(vision):
        raise _fail(path, "vision_radius", f"lists a radius twice: {list(vision)}")
    rules = data.get("rules", DEFAULT_RULES)
    rules = rules if isinstance(rules, list) else [rules]
    if not rules:
        raise _fail(path, "rules", "no rule set given")
    switches = {}
    for key, values in SWITCHES.items():
        value = data.get(key, "")
        if value != "" and value not in values:
            raise _fail(path, key, f"must be one of {', '.join(values)}, got {value!r}")
        switches[key] = value
    for i, rule_set in enumerate(rules):
        if not isinstance(rule_set, str) or rule_set not in RULE_SETS:
            raise _fail(path, f"rules[{i}]", f"must be one of {', '.join(RULE_SETS)}, got {rule_set!r}")
    if len(set(rules)) != len(rules):
        raise _fail(path, "rules", f"lists a rule set twice: {rules}")
    reference = data.get("reference", "")
    if reference:
        if not isinstance(reference, str):
            raise _fail(path, "reference", f"must be a file name, got {reference!r}")
        try:
            load_reference(path.parent / reference)
        except SwarmError as exc:
            raise _fail(path, "reference", str(exc)) from None
    max_ticks = _integer(path, "max_ticks", data.get("max_ticks", DEFAULT_MAX_TICKS), 1)
    wiggle = _number(path, "wiggle_deg", data.get("wiggle_deg", DEFAULT_WIGGLE_DEG), 0.0, True)
    world_radius = _integer(path, "world_radius", data.get("world_radius", DEFAULT_RADIUS), 3)
    try:
        check_world_memory(world_radius)
    except SwarmError as exc:
        raise _fail(path, "world_radius", str(exc)) from None
    fail_fraction = _number(path, "fail_fraction", data.get("fail_fraction", 0.0), 0.0, True)
    fail_tick = _integer(path, "fail_tick", data.get("fail_tick", 0), 0)
    try:
        RunParams(robots=5, fail_fraction=fail_fraction, fail_tick=fail_tick, max_ticks=max_ticks)
    except SwarmError as exc:
        raise _fail(path, "fail_fraction", str(exc)) from None
    for i, v in enumerate(vision):
        try:
            RunParams(robots=5, vision_radius=v).check_vision(world_radius)
        except SwarmError as exc:
            raise _fail(path, f"vision_radius[{i}]", str(exc)) from None
    shapes = _load_shapes(path, data["shapes"], World(world_radius))
    exp = Experiment(name=name.strip(), seed=seed, repetitions=repetitions, vision_radius=vision,
                     max_ticks=max_ticks, wiggle_deg=wiggle, world_radius=world_radius, fail_fraction=fail_fraction,
                     fail_tick=fail_tick, shapes=shapes, rules=tuple(rules), reference=reference, **switches)
    for shape, _, _, sizes in exp.shapes:  # the parameters of every grid point
        for n in sizes:
            for v in vision:
                try:
                    RunParams(robots=n, vision_radius=v, seed=0, max_ticks=max_ticks, wiggle_deg=wiggle,
                              fail_fraction=fail_fraction, fail_tick=fail_tick)
                except SwarmError as exc:
                    raise _fail(path, f"shapes.{shape}", str(exc)) from None
    return exp


def _load_shapes(path: Path, shapes: object, world: World) -> tuple[tuple[str, str, int, tuple[int, ...]], ...]:
    if not isinstance(shapes, dict) or not shapes:
        raise _fail(path, "shapes", "must map at least one shape to its group sizes, e.g. 'star: [1025, patches]'")
    out, names = [], set()
    for key, sizes in shapes.items():
        where = f"shapes.{key}"
        source = str(key)
        if Path(source).suffix.lower() in (".txt", ".png") or "/" in source:
            source = str((path.parent / source).resolve())
        try:
            shape = Shape.load(source, world)
        except SwarmError as exc:
            raise _fail(path, where, str(exc)) from None
        if shape.name in names:
            raise _fail(path, where, f"a second shape named '{shape.name}'")
        names.add(shape.name)
        if not isinstance(sizes, list) or not sizes:
            raise _fail(path, where, f"must be a non-empty list of group sizes (integers or '{PATCHES}')")
        robots = []
        for i, n in enumerate(sizes):
            if n == PATCHES:
                n = shape.patches
            n = _integer(path, f"{where}[{i}]", n, 5)
            if n > shape.free_patches:
                raise _fail(path, f"{where}[{i}]", f"{n} robots do not fit on the {shape.free_patches} free "
                                                   f"patches of the {world.size} x {world.size} world")
            robots.append(n)
        out.append((shape.name, source, shape.patches, tuple(sorted(set(robots)))))
    return tuple(out)


# -- the results file -------------------------------------------------------------


def result_row(spec: RunSpec, summary: dict) -> dict:
    """A results.csv row from a run's coordinates and its summary.json record."""
    row = {**summary, "shape_file": spec.shape_file, "repetition": spec.repetition}
    return {col: row[col] for col in RESULT_COLUMNS}


def prepare_out_dir(out: Path, exp: Experiment, config: Path, create: bool = True) -> None:
    """Create ``out`` for ``exp``, or check that it holds this same experiment (to resume it).
    With ``create`` False, only check that it could.

    Raises:
        ExperimentError: ``out`` is a file, cannot be created, or holds another experiment.
    """
    record = json.dumps({"config": str(config), "experiment": exp.as_dict()}, indent=2) + "\n"
    marker = out / EXPERIMENT_FILE
    if out.exists() and not out.is_dir():
        raise ExperimentError(f"{out}: exists and is not a directory")
    if marker.exists():
        try:
            before = json.loads(marker.read_text(encoding="utf-8"))["experiment"]
        except (OSError, ValueError, KeyError):
            raise ExperimentError(f"{marker}: unreadable; not a swarm-ros experiment directory") from None
        if before != json.loads(json.dumps(exp.as_dict())):
            raise ExperimentError(f"{out}: holds the results of a different experiment (its {EXPERIMENT_FILE} "
                                  f"differs from {config}); choose another --out")
        return
    if out.exists() and any(out.iterdir()):
        raise ExperimentError(f"{out}: exists, is not empty and holds no {EXPERIMENT_FILE}; choose another --out")
    if not create:
        return
    try:
        out.mkdir(parents=True, exist_ok=True)
        part = out / f".{EXPERIMENT_FILE}.tmp"
        part.write_text(record, encoding="utf-8")
        os.replace(part, marker)
    except OSError as exc:
        raise ExperimentError(f"{out}: cannot create the experiment directory ({exc.strerror or exc})") from None


# -- running ----------------------------------------------------------------------

_SHAPES: dict[tuple[str, int], Shape] = {}


def _shape(spec: RunSpec) -> Shape:
    key = (spec.shape_file, spec.world_radius)
    if key not in _SHAPES:
        _SHAPES[key] = Shape.load(spec.shape_file, World(spec.world_radius))
    return _SHAPES[key]


def run_inprocess(spec: RunSpec) -> dict:
    """Run ``spec`` with the in-process engine; its results.csv row."""
    import time

    from swarm_ros.core.engine import Simulation

    start = time.perf_counter()
    sim = Simulation(_shape(spec), spec.params())
    sim.run()
    return result_row(spec, sim.summary(wall_seconds=time.perf_counter() - start))


def run_ros2(spec: RunSpec, processes: int = 2) -> dict:
    """Run ``spec`` over the ROS 2 graph (``swarm-ros run``, no recording) in a scratch directory."""
    import shutil

    from swarm_ros.app.param_file import RecordingOptions, Settings
    from swarm_ros.app.launcher import Launch

    shape = _shape(spec)
    settings = Settings(shape=spec.shape_file, robots=spec.robots, vision_radius=spec.vision_radius, seed=spec.seed,
                        max_ticks=spec.max_ticks, wiggle_deg=spec.wiggle_deg, world_radius=spec.world_radius,
                        fail_fraction=spec.fail_fraction, fail_tick=spec.fail_tick, rules=spec.rules,
                        join=spec.join, crowding=spec.crowding, steps=spec.steps)
    scratch = Path(tempfile.mkdtemp(prefix="swarm_ros-exp-"))
    try:
        launch = Launch(settings=settings, shape=shape, params=spec.params(), processes=processes,
                        out=scratch / "run", quiet=True, recording=RecordingOptions(enabled=False))
        out = launch.run()
        summary = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    return result_row(spec, summary)


_IN_RUN = False  # in a worker: whether it is running a run now (else it waits for one, with nothing to stop)


def _interrupt(signum: int, frame: object) -> None:
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


def execute(todo: list[RunSpec], jobs: int, engine: str = "inprocess", processes: int = 2) -> Iterator[dict]:
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
            why = (f"ROS_AUTOMATIC_DISCOVERY_RANGE={env['ROS_AUTOMATIC_DISCOVERY_RANGE']} lets runs on different "
                   f"hosts meet in one domain")
        else:
            continue
        raise ExperimentError(f"--engine ros2 on Dask needs a ROS domain of its own for each run, but on worker "
                              f"{worker} {why}; unset it where the workers start")


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

    cluster = client = None
    try:
        if scheduler:
            try:
                client = Client(scheduler, timeout=_CONNECT_TIMEOUT)
            except (OSError, TimeoutError, ValueError) as exc:
                text = str(exc).strip()
                raise ExperimentError(f"cannot reach the Dask scheduler at {scheduler}: "
                                      f"{text.splitlines()[0] if text else type(exc).__name__}") from None
        else:
            cluster = LocalCluster(n_workers=jobs, threads_per_worker=1, processes=True, dashboard_address=":0",
                                   silence_logs=logging.ERROR)
            client = Client(cluster)
        if not quiet:
            where = scheduler or f"a LocalCluster of {jobs} workers"
            print(f"swarm-ros: Dask: {where}, dashboard {client.dashboard_link}", file=sys.stderr, flush=True)
        if engine == "ros2":
            _check_ros_workers(client)
        yield client
    finally:
        if client is not None:
            client.close()
        if cluster is not None:
            cluster.close()


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


def execute_dask(client, todo: list[RunSpec], engine: str, processes: int) -> Iterator[dict]:
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
        future = client.submit(run_specs, specs, engine, processes, pure=False,
                               key=f"swarm_ros-runs-{specs[0].shape}-{specs[0].robots}-{specs[0].repetition}-"
                                   f"{len(specs)}-{uuid.uuid4().hex[:8]}")
        submitted.append(future)
        pending.add(future)

    try:
        while queue and len(submitted) < _IN_FLIGHT * workers:
            submit()
        for future in pending:
            rows = future.result()
            recent.extend(max(float(row["wall_seconds"]), 0.0) for row in rows)
            while queue and pending.count() < _IN_FLIGHT * workers:
                submit()
            yield from rows
    finally:
        client.cancel(submitted)


def default_jobs() -> int:
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


def run_experiment(config: Path, out: Path | None, jobs: int, engine: str, processes: int, quiet: bool,
                   executor: str = "local", scheduler: str | None = None) -> Path:
    """Run (or resume) the experiment of ``config`` into ``out``; build its report; return ``out``.

    ``executor`` "local" runs on ``jobs`` worker processes here; "dask" on the Dask cluster at
    ``scheduler``, or on a LocalCluster of ``jobs`` workers. Either way only this process
    appends to results.csv, a line per finished run, in the order they finish.
    """
    from swarm_ros.app.report import build_report

    exp = load_experiment(config)
    prepare_out_dir(out or EXPERIMENTS_DIR / exp.name, exp, config, create=False)  # before a cluster starts
    closing = None
    with ExitStack() as stack:  # a cluster is reached (or refused) before anything is written
        client = stack.enter_context(dask_client(scheduler, jobs, engine, quiet)) if executor == "dask" else None
        out = _run_grid(exp, config, out, client, jobs, engine, processes, quiet)
        if client is not None:  # every run is in: the cluster stops while the report is built
            closing = threading.Thread(target=stack.pop_all().close, name="swarm_ros-dask-close")
            closing.start()
    try:
        build_report(out)
    finally:
        if closing is not None:
            closing.join()
    return out


def _run_grid(exp: Experiment, config: Path, out: Path | None, client, jobs: int, engine: str, processes: int,
              quiet: bool) -> Path:
    """Run what is not yet in results.csv, locally or (``client``) on Dask; return the experiment directory."""
    from tqdm import tqdm

    out = out or EXPERIMENTS_DIR / exp.name
    prepare_out_dir(out, exp, config)
    if exp.reference:  # the report finds it in the directory, wherever the experiment file goes
        part = out / f".{REFERENCE_FILE}.tmp"
        part.write_bytes((config.parent / exp.reference).read_bytes())
        os.replace(part, out / REFERENCE_FILE)
    results = ResultsFile(out / RESULTS_FILE)
    runs = exp.runs()
    done = results.done()
    todo = [s for s in runs if s.key not in done]
    if not quiet and done:
        print(f"resuming: {len(runs) - len(todo)} of {len(runs)} runs already in {out / RESULTS_FILE}",
              file=sys.stderr)
    try:
        with tqdm(total=len(runs), initial=len(runs) - len(todo), unit="run", desc=exp.name, file=sys.stderr,
                  disable=True if quiet else None, dynamic_ncols=True) as bar:
            rows = execute_dask(client, todo, engine, processes) if client is not None else \
                execute(todo, jobs, engine, processes)
            for row in rows:
                results.append(row)
                bar.update(1)
    except KeyboardInterrupt:
        left = len(runs) - len(results.done() & {s.key for s in runs})
        print(f"swarm-ros: interrupted with {left} of {len(runs)} runs to go; the finished ones are in "
              f"{out / RESULTS_FILE}; run the same command again to resume", file=sys.stderr)
        raise
    finally:
        results.close()
    return out
