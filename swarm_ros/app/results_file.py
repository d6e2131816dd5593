"""The results file of an experiment (``results.csv``): its columns, reading it, appending to it.

:mod:`swarm_ros.app.experiment` writes it and :mod:`swarm_ros.app.report` reads it; both depend
on this module and neither on the other's internals.
"""

from __future__ import annotations

import csv
import io
import math
import os
from pathlib import Path

from swarm_ros.core.algorithm import algorithm_of
from swarm_ros.core.errors import InputError, ParameterError
from swarm_ros.core.inputs import RESULTS_LIMIT, read_bounded
from swarm_ros.core.metrics import ENGINES, Outcome
from swarm_ros.core.params import DARR_NIAZI, EXPERIMENT_AXES, RUN_PARAMETERS, foreign_defaults

RESULTS_FILE = "results.csv"
REFERENCE_FILE = "reference.csv"  #: the experiment's reference numbers, copied into its directory

#: Columns results.csv adds after a run parameter's: the shape's file, the repetition, the shape's size.
_AFTER = {"shape": ("shape_file",), "steps": ("repetition",), "seed": ("shape_patches",)}
#: An algorithm's parameters that are not experiment keys (the rubenstein algorithm's: its runs take their
#: defaults) have no column.
_NOT_YET = {p.name for p in RUN_PARAMETERS if p.algorithm and not p.experiment}
#: One row of results.csv: the run's coordinates (every run parameter an experiment file may set, in its
#: declaration's order), then the summary.json fields of its outcome.
RESULT_COLUMNS = (
    *(c for p in RUN_PARAMETERS if p.recorded and p.name not in _NOT_YET for c in (p.name, *_AFTER.get(p.name, ()))),
    "engine",
    "outcome",
    "convergence_tick",
    "localized",
    "unlocalized",
    "separated",
    "empty_patches",
    "lost_robots",
    "convergence_rate",
    "coverage",
    "fill_50_tick",
    "fill_90_tick",
    "joined_outside",
    "hole_filled",
    "loc_error",
    "wall_seconds",
)
#: A time the run never reached (an empty field): the first ticks at which half and 90% of the shape was filled.
_MAYBE = ("fill_50_tick", "fill_90_tick")
_ACCURACY = ("joined_outside", "hole_filled", "loc_error")  #: 0 under the study's model (its robots localize
#: exactly, on shape patches)
_ADDED = ("algorithm", "coverage", *_MAYBE, *_ACCURACY)  #: columns since 2026-11-27
#: The columns before the algorithm and the comparison's measures: such a file is read with its rows completed
#: (the study's model; the share filled from its counts; no fill ticks, since results.csv never held the curves)
PREVIOUS_COLUMNS = tuple(c for c in RESULT_COLUMNS if c not in _ADDED)
_COUNTS = (
    "repetition",
    "shape_patches",
    "convergence_tick",
    "localized",
    "unlocalized",
    "separated",
    "empty_patches",
    "lost_robots",
)
_INT_COLUMNS = {
    *_COUNTS,
    "joined_outside",
    *_MAYBE,
    *(p.name for p in RUN_PARAMETERS if p.kind is int),
}
_OUTCOMES = tuple(o.value for o in Outcome)
_FLOAT_COLUMNS = {
    "convergence_rate",
    "wall_seconds",
    "coverage",
    "hole_filled",
    "loc_error",
    *(p.name for p in RUN_PARAMETERS if p.kind is float),
}


class ExperimentError(InputError):
    """A bad experiment file or output directory; the message names the file and the key."""


def _csv_line(row: dict) -> str:
    buf = io.StringIO()
    csv.writer(buf, lineterminator="\n").writerow([row[c] for c in RESULT_COLUMNS])
    return buf.getvalue()


def read_results(path: Path) -> list[dict]:
    """The rows of a results.csv (typed), every one checked before any is returned: its fields
    (:func:`_checked_row`), and that no run is there twice. Lines may end in CRLF (a file saved on Windows).

    Raises:
        ExperimentError: the file is not a results file of this version, a row is bad, a run is listed twice, or
            the last line is cut short (an experiment stopped while writing it: run the experiment again, which
            drops that line and redoes the run, :class:`ResultsFile`).
    """
    try:
        text = read_bounded(path, RESULTS_LIMIT, "results file", ExperimentError).decode("utf-8")
    except UnicodeDecodeError:
        raise ExperimentError(f"{path}: not a swarm-ros results file (not UTF-8 text)") from None
    text = text.replace("\r\n", "\n")
    if text and not text.endswith("\n"):
        raise ExperimentError(
            f"{path}: line {text.count(chr(10)) + 1}: cut short (no end of line): the experiment stopped while "
            "writing it; run the experiment again to resume it (it drops that line and redoes the run)"
        )
    previous = text.split("\n", 1)[0] == ",".join(PREVIOUS_COLUMNS)
    if text.split("\n", 1)[0] != ",".join(RESULT_COLUMNS) and not previous:
        raise ExperimentError(
            f"{path}: not a swarm-ros results file (expected the columns {', '.join(RESULT_COLUMNS)})"
        )
    rows: list[dict] = []
    lines: dict[tuple, int] = {}
    for line, r in enumerate(csv.DictReader(io.StringIO(text)), start=2):
        if previous and None not in r:  # completed: the study's model, no fill ticks, the share filled below
            r = {**r, "algorithm": DARR_NIAZI, **dict.fromkeys(("coverage", *_ACCURACY), "0")}
            r.update(dict.fromkeys(_MAYBE, ""))
        try:
            row = _checked_row(r)
            if previous:
                row["coverage"] = row["localized"] / row["shape_patches"] if row["shape_patches"] else 0.0
            _check_counts(row)
        except ExperimentError as exc:
            raise ExperimentError(f"{path}: line {line}: {exc}") from None
        key = run_key(row)
        if key in lines:
            raise ExperimentError(
                f"{path}: line {line}: the run of line {lines[key]} again ({row['shape']}, {row['robots']} robots, "
                f"{row['algorithm']}, repetition {row['repetition']}): a run counts once"
            )
        lines[key] = line
        rows.append(row)
    return rows


def run_key(row: dict) -> tuple:
    """A row's run: its coordinates in the experiment's grid (shape, group size, every axis, repetition)."""
    return (row["shape"], row["robots"], *(row[a] for a in EXPERIMENT_AXES), row["repetition"])


def _check_counts(row: dict) -> None:
    """What a row's measures must say together (every run this tool writes says it): shares within [0, 1]; the
    robots localized (joined), not localized and lost add up to the group; no more empty patches than the shape has;
    a complete run covers its whole shape; a fill time comes no later than the next one, nor than the run's end.

    Raises:
        ExperimentError: the first that does not hold, in words.
    """
    for k in ("coverage", "hole_filled"):
        if row[k] > 1:
            raise ExperimentError(f"{k} must be a share between 0 and 1, got {row[k]!r}")
    counted = row["localized"] + row["unlocalized"] + row["lost_robots"]
    if counted != row["robots"]:
        raise ExperimentError(
            f"localized + unlocalized + lost_robots must be the {row['robots']} robots, got {counted}"
        )
    if row["empty_patches"] > row["shape_patches"]:
        raise ExperimentError(
            f"empty_patches must be at most the shape's {row['shape_patches']} patches, got {row['empty_patches']}"
        )
    if row["outcome"] in (Outcome.COMPLETE.value, Outcome.COMPLETE_WITH_EXTRAS.value) and (
        row["coverage"] != 1 or row["empty_patches"] != 0
    ):
        raise ExperimentError(
            f"outcome {row['outcome']} needs the whole shape covered, got coverage {row['coverage']!r} and "
            f"empty_patches {row['empty_patches']}"
        )
    times = [t for t in (row["fill_50_tick"], row["fill_90_tick"], row["convergence_tick"]) if t is not None]
    if times != sorted(times):
        raise ExperimentError(
            f"fill_50_tick, fill_90_tick and convergence_tick must come in that order, got {row['fill_50_tick']}, "
            f"{row['fill_90_tick']} and {row['convergence_tick']}"
        )


def _checked_row(raw: dict) -> dict:
    """A results.csv row typed, and every field checked: run parameters by their declarations, the outcome and
    engine against their sets, counts and times non-negative.

    Raises:
        ExperimentError: the first bad field, in words naming it (the caller adds the file and the line).
    """
    row: dict = {}
    for k, v in raw.items():
        if k is None or v is None:
            raise ExperimentError("the row has another number of fields than the header")
        if k in _MAYBE and v == "":
            row[k] = None
            continue
        try:
            row[k] = int(v) if k in _INT_COLUMNS else float(v) if k in _FLOAT_COLUMNS else v
        except ValueError:
            raise ExperimentError(f"{k} must be a number, got {v!r}") from None
    for p in RUN_PARAMETERS:
        if p.name in row:
            try:
                p.check(row[p.name])
            except ParameterError as exc:
                raise ExperimentError(str(exc)) from None
    if row["outcome"] not in _OUTCOMES:
        raise ExperimentError(f"outcome must be one of {', '.join(_OUTCOMES)}, got {row['outcome']!r}")
    if row["engine"] not in ENGINES:
        raise ExperimentError(f"engine must be one of {', '.join(ENGINES)}, got {row['engine']!r}")
    for k in (*_COUNTS, "convergence_rate", "wall_seconds", "coverage", *_ACCURACY, *_MAYBE):
        if row[k] is not None and not (row[k] >= 0 and math.isfinite(row[k])):
            raise ExperimentError(f"{k} must be a number >= 0, got {raw[k]!r}")
    return row


class ResultsFile:
    """results.csv, appended one whole line per finished run, flushed and synced at once."""

    def __init__(self, path: Path) -> None:
        self.path = path
        if path.exists():
            text = path.read_bytes()
            cut = text.rfind(b"\n") + 1
            if cut < len(text):  # a line cut short by a crash: drop it, the run is redone
                with open(path, "r+b") as f:
                    f.truncate(cut)
            self.rows = read_results(path)
            if not text.startswith((",".join(RESULT_COLUMNS) + "\n").encode()):  # the previous columns: rewritten
                part = path.with_name(f".{path.name}.tmp")
                part.write_text("".join([",".join(RESULT_COLUMNS) + "\n", *map(_csv_line, self.rows)]), "utf-8")
                part.replace(path)
        else:
            part = path.with_name(f".{path.name}.tmp")
            part.write_text(",".join(RESULT_COLUMNS) + "\n", encoding="utf-8")
            part.replace(path)
            self.rows = []
        self._file = open(path, "a", encoding="utf-8")

    def done(self) -> set[tuple]:
        """The coordinates of the runs in the file, as :attr:`~swarm_ros.app.experiment_file.RunSpec.key`."""
        return {run_key(r) for r in self.rows}

    def append(self, row: dict) -> None:
        self._file.write(_csv_line(row))
        self._file.flush()
        os.fsync(self._file.fileno())
        self.rows.append(row)

    def close(self) -> None:
        self._file.close()


def stored_shape_file(shape_file: str) -> str:
    """What an experiment stores of a run's shape (results.csv's ``shape_file``, experiment.json): a built-in shape's
    name as it is; a shape file's path relative to the working directory when it lies under it (an experiment run
    from a repository's root stores paths relative to the repository, the same in any clone), else its absolute
    path. Shape.load reads either from the same working directory."""
    if "/" not in shape_file:
        return shape_file
    path = Path(shape_file).resolve()
    try:
        return str(path.relative_to(Path.cwd().resolve()))
    except ValueError:
        return str(path)


def result_row(spec, summary: dict) -> dict:
    """A results.csv row from a run's coordinates (a :class:`~swarm_ros.app.experiment_file.RunSpec`) and its
    summary.json record."""
    as_study_row = algorithm_of(summary.get("algorithm", DARR_NIAZI)).hook("as_study_row")
    if as_study_row is not None:  # an algorithm whose summary has columns of its own
        summary = as_study_row(summary)
    # the study's model localizes robots exactly on shape patches: none outside (nor in a hole), no error
    row = {
        **foreign_defaults(summary["algorithm"]),  # an algorithm's row holds the others' parameters at their defaults
        "joined_outside": 0,
        "hole_filled": 0.0,
        "loc_error": 0.0,
        **summary,
        "shape_file": spec.shape_file,
        "repetition": spec.repetition,
    }
    return {col: row[col] for col in RESULT_COLUMNS}
