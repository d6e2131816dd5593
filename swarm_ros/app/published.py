"""Published numbers to set beside an experiment's own: a reference file.

A reference file is CSV (lines starting with ``#`` are comments), one row per shape::

    shape,study_robots,mean_ticks,ci95_low,ci95_high,group_sizes,sizes_mean_min,sizes_mean_max
    star,1036,861.8,599.1,1124.49,1025-1045,125.7,739.7

``mean_ticks`` [``ci95_low``, ``ci95_high``] is the published mean convergence time at
``study_robots`` robots, the shape's exact patch count in that study; it is set beside
this project's runs at N = the shape's own patch count (the shapes' patch counts differ
slightly between the study and here). ``sizes_mean_min``/``sizes_mean_max`` is the range
of the published mean over the study's other group sizes (``group_sizes``, as text).
``config/experiments/study_reference.csv`` holds the original study's numbers.
"""

from __future__ import annotations

import csv
import io
import math
from dataclasses import dataclass
from pathlib import Path

from swarm_ros.core.errors import InputError
from swarm_ros.core.inputs import YAML_LIMIT, read_bounded

COLUMNS = (
    "shape",
    "study_robots",
    "mean_ticks",
    "ci95_low",
    "ci95_high",
    "group_sizes",
    "sizes_mean_min",
    "sizes_mean_max",
)


class ReferenceFileError(InputError):
    """A reference file cannot be read or is malformed; the message names the file and the line."""


@dataclass(frozen=True)
class Reference:
    """One shape's published numbers (ticks)."""

    shape: str
    study_robots: int
    mean: float
    ci95_low: float
    ci95_high: float
    group_sizes: str
    sizes_mean_min: float
    sizes_mean_max: float

    def contains(self, value: float) -> bool:
        """Whether ``value`` lies in the published 95% CI."""
        return self.ci95_low <= value <= self.ci95_high


def load_reference(path: Path) -> dict[str, Reference]:
    """The rows of a reference file by shape name.

    Raises:
        ReferenceFileError: unreadable, wrong columns, a bad number, a CI that does not hold
            its mean, or a shape listed twice.
    """
    try:
        text = read_bounded(path, YAML_LIMIT, "reference file", ReferenceFileError).decode("utf-8")
    except UnicodeDecodeError:
        raise ReferenceFileError(f"{path}: cannot read the reference file (not UTF-8 text)") from None
    lines = [(n, ln) for n, ln in enumerate(text.splitlines(), start=1) if ln.strip() and not ln.startswith("#")]
    if not lines or next(csv.reader([lines[0][1]])) != list(COLUMNS):
        raise ReferenceFileError(f"{path}: expected the columns {','.join(COLUMNS)}")
    out: dict[str, Reference] = {}
    for n, line in lines[1:]:
        values = next(csv.reader(io.StringIO(line)))
        if len(values) != len(COLUMNS):
            raise ReferenceFileError(f"{path}:{n}: expected {len(COLUMNS)} values, got {len(values)}")
        row = dict(zip(COLUMNS, values))
        try:
            ref = Reference(
                shape=row["shape"].strip(),
                study_robots=int(row["study_robots"]),
                mean=float(row["mean_ticks"]),
                ci95_low=float(row["ci95_low"]),
                ci95_high=float(row["ci95_high"]),
                group_sizes=row["group_sizes"].strip(),
                sizes_mean_min=float(row["sizes_mean_min"]),
                sizes_mean_max=float(row["sizes_mean_max"]),
            )
        except ValueError:
            raise ReferenceFileError(f"{path}:{n}: a value is not a number") from None
        numbers = (ref.mean, ref.ci95_low, ref.ci95_high, ref.sizes_mean_min, ref.sizes_mean_max)
        if not ref.shape or not all(math.isfinite(v) for v in numbers) or ref.study_robots < 1:
            raise ReferenceFileError(f"{path}:{n}: needs a shape name, finite numbers and study_robots >= 1")
        if not ref.ci95_low <= ref.mean <= ref.ci95_high or ref.sizes_mean_min > ref.sizes_mean_max:
            raise ReferenceFileError(f"{path}:{n}: the CI must hold the mean, and sizes_mean_min <= sizes_mean_max")
        if ref.shape in out:
            raise ReferenceFileError(f"{path}:{n}: shape '{ref.shape}' listed twice")
        out[ref.shape] = ref
    return out
