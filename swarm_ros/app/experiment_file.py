"""An experiment file: a grid of shapes x group sizes x axes x repetitions, read and checked.

An experiment file is YAML::

    name: paper                 # names the default output directory, experiments/<name>
    seed: 2026                  # experiment seed; each run's seed derives from it and the run's coordinates
    repetitions: 10
    vision_radius: [1]          # an axis: one number or a list
    rules: [paper, local]       # an axis: one rule set or a list (default: paper)
    algorithm: [darr-niazi, rubenstein]  # an axis (default: darr-niazi); a rubenstein run takes the study's
                                # model's parameters (vision_radius, rules, ...) at their defaults, once
    crowding: disc              # optional: override a switch (join, crowding, steps) for every rule set
    reference: study_reference.csv  # optional: published numbers to set beside ours (relative to this file)
    max_ticks: 100000           # optional, as for one run
    wiggle_deg: 45              # optional
    world_radius: 32            # optional
    fail_fraction: 0.1          # optional: this fraction of the robots fails at the end of tick fail_tick
    fail_tick: 500
    shapes:                     # built-in name or shape file (relative to this file) -> group sizes
      star: [1025, 1030, 1035, 1040, 1045, patches]   # 'patches' = the shape's exact patch count

Which run parameters a file may set, and which of them may list several values (the axes),
comes from their declaration (``swarm_ros.core.params.RUN_PARAMETERS``); every value is
checked by it. A run's seed depends only on the experiment seed and its coordinates (shape,
group size, vision radius, repetition), never on the rule set or the order runs finish: the
rule sets of one experiment start from the same placements (common random numbers).
"""

from __future__ import annotations

import itertools
import math
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from swarm_ros.app.param_file import read_yaml
from swarm_ros.app.published import load_reference
from swarm_ros.app.results_file import ExperimentError
from swarm_ros.core.errors import InputError
from swarm_ros.core.grid import World
from swarm_ros.core.params import (
    EXPERIMENT_AXES,
    MAX_SEED,
    RUN_PARAMETER,
    RUN_PARAMETERS,
    Param,
    RunParams,
    Settings,
    foreign_defaults,
)
from swarm_ros.core.resources import check_world_memory
from swarm_ros.core.run_bounds import check_run
from swarm_ros.core.shapes import Shape

#: The most runs an experiment may hold: its runs are listed (and results.csv holds a line each) before the
#: first starts. The study's protocol is 360 runs; a million take days on a cluster.
MAX_RUNS = 1_000_000
PATCHES = "patches"  #: a group size written as this word is the shape's exact patch count
AXES = EXPERIMENT_AXES  #: run parameters that may list several values
FIXED = tuple(p.name for p in RUN_PARAMETERS if p.experiment == "fixed")  #: one value for every run
#: The experiment's own keys, declared as run parameters are (checked the same way).
_OWN = {
    p.name: p
    for p in (
        Param("name", "", "the experiment's name"),
        Param("seed", 0, "experiment seed", low=0, high=MAX_SEED),
        Param("repetitions", 1, "runs per grid point", low=1, high=MAX_RUNS),
        Param("reference", "", "a reference file, relative to the experiment file"),
    )
}
_GROUP = Param("robots", 5, "a group size", low=5)  # the four seeds and at least one robot to join
_KEYS = ("name", "seed", "repetitions", *AXES, *FIXED, "reference", "shapes")
_REQUIRED = ("seed", "repetitions", "vision_radius", "shapes")


@dataclass(frozen=True)
class RunSpec:
    """One run of an experiment: its coordinates and everything needed to run it in another process."""

    shape: str  #: the shape's name (the file stem for a shape file)
    repetition: int
    settings: Settings  #: every run parameter; its ``shape`` is what Shape.load takes (a name or an absolute path)

    def __getattr__(self, name: str) -> Any:  # a run parameter, typed by its declaration
        if name in RUN_PARAMETER and name != "shape":
            return getattr(self.settings, name)
        raise AttributeError(name)

    @property
    def shape_file(self) -> str:
        return self.settings.shape

    @property
    def key(self) -> tuple:
        """The run's coordinates: shape, group size, each axis, repetition (as results.csv's rows give them)."""
        return (self.shape, self.settings.robots, *(getattr(self.settings, a) for a in AXES), self.repetition)

    def params(self) -> RunParams:
        return self.settings.run_params()


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
    shapes: tuple[tuple[str, str, int, tuple[int, ...]], ...]  #: (name, file, patches, sizes)
    axes: dict[str, tuple]  #: each axis's values, in the file's order
    fixed: Settings  #: the value of every other run parameter (shape, robots and seed are per run)
    reference: str = ""  #: the reference file as the experiment file names it (relative to it), or ""

    def __getattr__(self, name: str) -> object:
        if name in AXES:
            return self.__dict__["axes"][name]
        if name in FIXED:
            return getattr(self.__dict__["fixed"], name)
        raise AttributeError(name)

    def points(self) -> list[dict[str, Any]]:
        """The grid's points (a value of each axis), in the canonical order. A rubenstein point takes the study's
        model's parameters at their defaults, whatever their axes list, so it comes once, not once a value."""
        out, seen = [], set()
        for values in itertools.product(*(self.axes[a] for a in AXES)):
            point = dict(zip(AXES, values))
            foreign = {a: v for a, v in foreign_defaults(point["algorithm"]).items() if a in AXES}
            if foreign:
                point.update(foreign)
                if tuple(point.values()) in seen:
                    continue
                seen.add(tuple(point.values()))
            out.append(point)
        return out

    def runs(self) -> list[RunSpec]:
        """Every run, in the canonical order: shape, group size, each axis, repetition. A rubenstein run takes the
        study's model's fixed parameters at their defaults too."""
        out = []
        for name, file, _, sizes in self.shapes:
            for n in sizes:
                for values in self.points():
                    fixed = self.fixed.updated(**foreign_defaults(values["algorithm"]))
                    point = fixed.updated(shape=file, robots=n, **values)
                    out += [
                        RunSpec(name, r, point.updated(seed=run_seed(self.seed, name, n, point.vision_radius, r)))
                        for r in range(self.repetitions)
                    ]
        return out

    def as_dict(self) -> dict:
        return {
            "name": self.name,
            "seed": self.seed,
            "repetitions": self.repetitions,
            **{a: list(self.axes[a]) for a in AXES},
            **{f: getattr(self.fixed, f) for f in FIXED},
            "shapes": [[n, f, p, list(s)] for n, f, p, s in self.shapes],
            "reference": self.reference,
        }


def _fail(path: Path, key: str, message: str) -> ExperimentError:
    return ExperimentError(f"{path}: {key}: {message}" if key else f"{path}: {message}")


def _checked(path: Path, key: str, param: Param, value: object) -> Any:
    try:
        return param.check(value)
    except InputError as exc:
        raise _fail(path, key, str(exc)) from None


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
    own = {
        key: _checked(path, key, _OWN[key], data[key]) for key in ("seed", "repetitions", "reference") if key in data
    }
    axes = {}
    for axis in AXES:
        given = data.get(axis, RUN_PARAMETER[axis].default)
        given = given if isinstance(given, list) else [given]
        if not given:
            raise _fail(path, axis, f"no {axis} given")
        values = tuple(_checked(path, f"{axis}[{i}]", RUN_PARAMETER[axis], v) for i, v in enumerate(given))
        if len(set(values)) != len(values):
            raise _fail(path, axis, f"lists a value twice: {list(values)}")
        axes[axis] = values
    fixed = Settings(**{f: _checked(path, f, RUN_PARAMETER[f], data[f]) for f in FIXED if f in data})
    reference = own.get("reference", "")
    if reference:
        try:
            load_reference(path.parent / reference)
        except InputError as exc:
            raise _fail(path, "reference", str(exc)) from None
    try:
        check_world_memory(fixed.world_radius)
    except InputError as exc:
        raise _fail(path, "world_radius", str(exc)) from None
    try:
        fixed.run_params(robots=5)
    except InputError as exc:
        raise _fail(path, "fail_fraction", str(exc)) from None
    for i, v in enumerate(axes["vision_radius"]):
        try:
            fixed.updated(vision_radius=v).run_params(robots=5).check_vision(fixed.world_radius)
        except InputError as exc:
            raise _fail(path, f"vision_radius[{i}]", str(exc)) from None
    loaded: dict[str, tuple[str, Shape]] = {}
    shapes = _load_shapes(path, data["shapes"], World(fixed.world_radius), loaded, fixed.shape_scale)
    runs = own["repetitions"] * sum(len(sizes) for *_, sizes in shapes) * math.prod(len(v) for v in axes.values())
    # (an upper bound: a rubenstein point comes once whatever the study's model's axes list)
    if runs > MAX_RUNS:
        raise _fail(
            path,
            "repetitions",
            f"the grid holds {runs:,} runs, more than the {MAX_RUNS:,} an experiment "
            f"may hold; split it into several experiments",
        )
    exp = Experiment(
        name=name.strip(),
        seed=own["seed"],
        repetitions=own["repetitions"],
        shapes=shapes,
        axes=axes,
        fixed=fixed,
        reference=reference,
    )
    for spec in exp.runs()[:: exp.repetitions]:  # every grid point, checked as a run checks it (check_run)
        where, shape = loaded[spec.shape]
        try:
            check_run(shape, spec.params())
        except InputError as exc:
            raise _fail(path, where, str(exc)) from None
    return exp


def _load_shapes(
    path: Path,
    shapes: object,
    world: World,
    loaded: dict[str, tuple[str, Shape]] | None = None,
    scale: int = 1,
) -> tuple[tuple[str, str, int, tuple[int, ...]], ...]:
    """The experiment's shapes as (name, source, patches, group sizes), each loaded (at ``shape_scale`` ``scale``) and
    its sizes checked; ``loaded`` (if given) receives each shape's key in the file and the shape, by name."""
    if not isinstance(shapes, dict) or not shapes:
        raise _fail(path, "shapes", "must map at least one shape to its group sizes, e.g. 'star: [1025, patches]'")
    out, names = [], set()
    for key, sizes in shapes.items():
        where = f"shapes.{key}"
        source = str(key)
        if Path(source).suffix.lower() in (".txt", ".png") or "/" in source:
            source = str((path.parent / source).resolve())
        try:
            shape = Shape.load(source, world, scale=scale)
        except InputError as exc:
            raise _fail(path, where, str(exc)) from None
        if shape.name in names:
            raise _fail(path, where, f"a second shape named '{shape.name}'")
        names.add(shape.name)
        if not isinstance(sizes, list) or not sizes:
            raise _fail(path, where, f"must be a non-empty list of group sizes (integers or '{PATCHES}')")
        robots: list[int] = []
        for i, n in enumerate(sizes):
            n = _checked(path, f"{where}[{i}]", _GROUP, shape.patches if n == PATCHES else n)
            try:
                shape.check_room(n)
            except InputError as exc:
                raise _fail(path, f"{where}[{i}]", str(exc)) from None
            robots.append(n)
        out.append((shape.name, source, shape.patches, tuple(sorted(set(robots)))))
        if loaded is not None:
            loaded[shape.name] = (where, shape)
    return tuple(out)
