"""``swarm-ros experiment``: run (or resume) an experiment's grid into its directory, then build its report.

The file format is :mod:`swarm_ros.app.experiment_file`'s; where runs go, :mod:`swarm_ros.app.executors`'.
Each finished run is appended at once, as one line, to
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
import os
import sys
import threading
from contextlib import ExitStack, closing
from pathlib import Path

from swarm_ros.app.curves import CURVE, write_curve
from swarm_ros.app.executors import dask_client, execute, execute_dask
from swarm_ros.app.experiment_file import Experiment, load_experiment
from swarm_ros.app.results_file import REFERENCE_FILE, RESULTS_FILE, ExperimentError, ResultsFile, stored_shape_file
from swarm_ros.core.params import DARR_NIAZI
from swarm_ros.core.signals import InterruptSaid

EXPERIMENTS_DIR = Path("experiments")
EXPERIMENT_FILE = "experiment.json"


def prepare_out_dir(out: Path, exp: Experiment, config: Path, create: bool = True) -> None:
    """Create ``out`` for ``exp``, or check that it holds this same experiment (to resume it).
    With ``create`` False, only check that it could.

    Raises:
        ExperimentError: ``out`` is a file, cannot be created, or holds another experiment.
    """
    record = json.dumps({"config": str(config), "experiment": _as_stored(exp.as_dict())}, indent=2) + "\n"
    marker = out / EXPERIMENT_FILE
    if out.exists() and not out.is_dir():
        raise ExperimentError(f"{out}: exists and is not a directory")
    if marker.exists():
        try:
            before = json.loads(marker.read_text(encoding="utf-8"))["experiment"]
            before.setdefault("algorithm", [DARR_NIAZI])  # written before the algorithm was an axis
        except (OSError, ValueError, KeyError):
            raise ExperimentError(f"{marker}: unreadable; not a swarm-ros experiment directory") from None
        if _as_stored(before) != json.loads(json.dumps(_as_stored(exp.as_dict()))):
            raise ExperimentError(
                f"{out}: holds the results of a different experiment (its {EXPERIMENT_FILE} "
                f"differs from {config}); choose another --out"
            )
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


def _as_stored(record: dict) -> dict:
    """An experiment's record as its directory keeps it: its shape files' paths as results.csv stores them
    (:func:`~swarm_ros.app.results_file.stored_shape_file`; a record written with absolute paths reads the same)."""
    shapes = [[name, stored_shape_file(str(file)), *rest] for name, file, *rest in record.get("shapes", [])]
    return {**record, "shapes": shapes}


def run_experiment(
    config: Path,
    out: Path | None,
    jobs: int,
    engine: str,
    processes: int,
    quiet: bool,
    executor: str = "local",
    scheduler: str | None = None,
) -> tuple[Path, int]:
    """Run (or resume) the experiment of ``config`` into ``out``; build its report; return ``out`` and the
    workers it ran on.

    ``executor`` "local" runs on ``jobs`` worker processes here; "dask" on the Dask cluster at
    ``scheduler``, or on a LocalCluster of ``jobs`` workers; ``jobs`` is capped at the experiment's runs (a
    worker more has nothing to do). Either way only this process appends to results.csv, a line per finished
    run, in the order they finish.
    """
    from swarm_ros.app.report import build_report
    from swarm_ros.core.algorithm import check_can

    exp = load_experiment(config)
    if engine == "ros2":  # every algorithm of the grid runs over the graph: refused before anything is written
        for algorithm in dict.fromkeys(spec.algorithm for spec in exp.runs()):
            check_can(algorithm, "graph")
    jobs = max(1, min(jobs, len(exp.runs())))
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
    return out, jobs


def _run_grid(
    exp: Experiment, config: Path, out: Path | None, client, jobs: int, engine: str, processes: int, quiet: bool
) -> Path:
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
        print(f"resuming: {len(runs) - len(todo)} of {len(runs)} runs already in {out / RESULTS_FILE}", file=sys.stderr)
    try:
        with tqdm(
            total=len(runs),
            initial=len(runs) - len(todo),
            unit="run",
            desc=exp.name,
            file=sys.stderr,
            disable=True if quiet else None,
            dynamic_ncols=True,
        ) as bar:
            rows = (
                execute_dask(client, todo, engine, processes)
                if client is not None
                else execute(todo, jobs, engine, processes)
            )
            with closing(rows):  # closed here, on Ctrl-C too: its tasks are cancelled while the client is open
                for row in rows:
                    curve = row.pop(CURVE, None)
                    if curve is not None:  # before its row: a row in results.csv has its curve, if it made one
                        write_curve(out, row, curve)
                    results.append({**row, "shape_file": stored_shape_file(row["shape_file"])})
                    bar.update(1)
    except KeyboardInterrupt:
        left = len(runs) - len(results.done() & {s.key for s in runs})
        print(
            f"swarm-ros: interrupted with {left} of {len(runs)} runs to go; the finished ones are in "
            f"{out / RESULTS_FILE}; run the same command again to resume",
            file=sys.stderr,
        )
        raise InterruptSaid from None
    finally:
        results.close()
    return out
