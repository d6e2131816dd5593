"""A run's parameters, declared once, as the fields of :class:`Settings`: everything else is derived from them.

Each field carries its declaration (:class:`Param`: meaning, bounds or choices, command-line flag, role in
an experiment file); :data:`RUN_PARAMETERS` is those declarations, in the fields' order. From them come the
model's resolved parameters (:class:`RunParams`: the same declarations of the ``model`` fields), the command-line
flags (``swarm_ros.app.cli``), the keys of a parameter file and of each node's ROS parameters, the keys of an
experiment file (``swarm_ros.app.experiment_file``), the columns of ``results.csv``, the launch file's arguments
and the docs' tables of parameters (``scripts/docs_tables.py``).
Every value is checked by :meth:`Param.check`, so every input path says the same thing about a bad value:
``<name> must be <what>, got <value>``.

A node's own parameters (the world's restart policy, the monitor's output folder, ...) are
declared the same way in :data:`NODE_PARAMETERS`.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, fields, replace
from typing import TYPE_CHECKING, Any

from .algorithm import DARR_NIAZI, RUBENSTEIN, algorithm_of, names
from .darr_niazi.rulesets import CROWDING_VALUES, DEFAULT_RULES, JOIN_VALUES, RULE_SETS, STEPS_VALUES, RuleSet
from .errors import ParameterError
from .grid import DEFAULT_RADIUS, MIN_RADIUS, World
from .param_decl import INT64_MAX, Param

if TYPE_CHECKING:
    from .shapes import Shape

DEFAULT_SEED = 1
DEFAULT_VISION = 1.0
DEFAULT_WIGGLE_DEG = 45.0
MAX_SEED = INT64_MAX
#: The largest tick limit: far beyond any run (the study's is 100,000; 10^9 ticks take days at the fastest),
#: and the graph's world keeps a row of metrics per tick in its checkpoint, a sparse file this many rows long.
MAX_TICKS = 10**9
MIN_ROBOTS = 4  # the four seeds
_DN, _RB = {"algorithm": DARR_NIAZI}, {"algorithm": RUBENSTEIN, "experiment": ""}  # experiments: the model only


def _param(default: Any, meaning: str, **declaration: Any) -> Any:
    """A dataclass field with its default, carrying the parameter's declaration (:class:`Param`; its name is the
    field's)."""
    return field(default=default, metadata={"param": Param("", default, meaning, **declaration)})


# The run parameters are declared once, as the fields of the four classes below; :class:`Settings` has them all,
# :class:`RunParams` the model's (``model``). They are four only for the order of results.csv's columns, which is
# Settings' fields' order: a dataclass puts its bases' fields first, the last base's first.


@dataclass(frozen=True)
class _Where:
    """Where the swarm forms its shape: the first columns."""

    shape: str = _param(
        "star",
        "built-in shape name (2D or 3D), or a shape file: a .txt grid (layers separated by "
        "--- for 3D), a .png image, or an .stl/.obj/.ply mesh",
        experiment="",
    )
    mesh_scale: float = _param(
        1.0,
        "voxels per mesh unit, for a mesh shape",
        low=0.0,
        low_open=True,
        high=1000.0,
        experiment="",
        recorded=False,
    )
    shape_scale: int = _param(
        1,
        "integer upscale of a 2D shape: each pixel becomes a k x k block (3: the star's 1,036 patches become "
        "9,324); --world-radius must hold it",
        low=1,
        high=100,
        recorded=False,
    )


@dataclass(frozen=True)
class _Model:
    """The model's parameters, first part: ``robots = 0`` means the shape's patch count; ``join``, ``crowding`` and
    ``steps`` = "" the rule set's own."""

    robots: int = _param(0, "robots N, seeds included", low=MIN_ROBOTS, blank="the shape's patch count", experiment="")
    algorithm: str = _param(
        DARR_NIAZI,
        "shape-formation algorithm: darr-niazi (the study's model) or rubenstein (Rubenstein et al.'s "
        "Kilobot self-assembly); see docs/model.md",
        choices=names,  # the algorithms registered (core.algorithm), asked for when a value is checked
        experiment="axis",
    )
    vision_radius: float = _param(
        DEFAULT_VISION, "vision radius in patches", low=1.0, high=100.0, flag="--vision", experiment="axis", **_DN
    )
    rules: str = _param(
        DEFAULT_RULES,
        "rule set: paper (join walk, crowding ahead, steps one), local (join local), "
        "literal (join local, steps literal); see docs/model.md",
        choices=tuple(RULE_SETS),
        experiment="axis",
        **_DN,
    )
    join: str = _param(
        "", "override the rule set's join switch", choices=JOIN_VALUES, blank="the rule set's own", **_DN
    )
    crowding: str = _param(
        "", "override the rule set's crowding switch", choices=CROWDING_VALUES, blank="the rule set's own", **_DN
    )
    steps: str = _param(
        "", "override the rule set's steps switch", choices=STEPS_VALUES, blank="the rule set's own", **_DN
    )
    seed: int = _param(DEFAULT_SEED, "run seed", low=0, high=MAX_SEED, experiment="")
    max_ticks: int = _param(
        0,
        "tick limit",
        low=1,
        high=MAX_TICKS,
        blank=", ".join(f"{algorithm_of(a).max_ticks} under {a}" for a in (DARR_NIAZI, RUBENSTEIN)),
    )
    wiggle_deg: float = _param(
        DEFAULT_WIGGLE_DEG, "max turn per tick, degrees", low=0.0, high=180.0, flag="--wiggle", **_DN
    )


@dataclass(frozen=True)
class _World:
    world_radius: int = _param(DEFAULT_RADIUS, "the world spans [-R, R] patches", low=MIN_RADIUS)


@dataclass(frozen=True)
class _ModelRest:
    """The model's parameters, second part: its robot failures, then the rubenstein algorithm's."""

    fail_fraction: float = _param(
        0.0, "fraction of the robots that fail at the end of fail_tick", low=0.0, high=1.0, flag="", **_DN
    )
    fail_tick: int = _param(0, "the tick at whose end fail_fraction of the robots fail", low=0, flag="", **_DN)
    # Rubenstein et al.'s algorithm (docs/model.md): lengths in robot diameters d
    pixel_size: float = _param(1.2, "side of a shape pixel, in robot diameters", low=0.5, high=10.0, **_RB)
    comm_range: float = _param(3.5, "communication range C, in robot diameters", low=1.0, high=20.0, **_RB)
    gradient_range: float = _param(
        1.5, "a neighbour closer than this counts for the gradient (G; d < DESIRED < G < sqrt(3) d)", low=1.0, **_RB
    )
    desired_distance: float = _param(1.3, "edge-following distance DESIRED, in d", low=1.0, low_open=True, **_RB)
    yield_distance: float = _param(2.5, "stop while the edge-follower ahead is closer (YIELD)", low=1.0, **_RB)
    yield_patience: int = _param(
        60,
        "... for at most this many ticks in a row, then edge-follow on (a yielding robot can block the one ahead)",
        low=0,
        **_RB,
    )
    step_length: float = _param(0.05, "forward step per tick, in d", low=0.0, low_open=True, high=0.5, **_RB)
    turn_deg: float = _param(7.0, "turn per tick while edge-following, degrees", low=0.0, high=90.0, **_RB)
    range_noise: float = _param(0.0, "measured distances err uniformly within +-this, in d", low=0.0, high=0.5, **_RB)
    loc_gain: float = _param(
        0.25,
        "localization: the share of the way to each anchor's circle per sweep",
        low=0.0,
        low_open=True,
        high=1.0,
        **_RB,
    )
    loc_sweeps: int = _param(
        10,
        "localization sweeps over the anchors per tick (one lags a moving robot: docs/model.md)",
        low=1,
        high=100,
        **_RB,
    )
    loc_min_angle_deg: float = _param(
        15.0, "localization needs an anchor triangle whose smallest angle exceeds this", low=0.0, high=60.0, **_RB
    )
    loc_settle: float = _param(
        0.1, "localized once the estimate moves less than this a tick, in d, ...", low=0.0, low_open=True, **_RB
    )
    loc_settle_ticks: int = _param(10, "... for this many ticks in a row", low=1, **_RB)
    loc_stale_ticks: int = _param(
        20, "a moving robot drops its estimate after this many ticks without 3 anchors (0: never)", low=0, **_RB
    )
    startup_ticks: int = _param(200, "ticks every robot waits at the start (START)", low=0, **_RB)
    stall_ticks: int = _param(
        20_000, "the run ends incomplete after this many ticks without a robot joining", low=1, **_RB
    )


@dataclass(frozen=True)
class Settings(_ModelRest, _World, _Model, _Where):
    """What a run needs before the shape is loaded: every run parameter with its default, in the order of
    results.csv's columns (:data:`RUN_PARAMETERS` is read from these fields)."""

    def updated(self, **values: Any) -> Settings:
        """A copy with the given non-None values."""
        return replace(self, **{k: v for k, v in values.items() if v is not None})

    def run_params(self, robots: int | None = None) -> RunParams:
        """The model's parameters these settings stand for, ``robots`` resolved (0: the shape's count)."""
        values = {p.name: getattr(self, p.name) for p in RUN_PARAMETERS if p.model}
        values["robots"] = robots or self.robots
        return RunParams(**values)

    def resolve(self) -> tuple[Shape, RunParams]:
        """The shape and run parameters these settings stand for (every engine and node derives them so).

        Raises:
            InputError: a bad shape, a bad value, or more robots than free patches.
        """
        from .resources import check_world_memory
        from .shapes import Shape

        RUN_PARAMETER["world_radius"].check(self.world_radius)
        check_world_memory(self.world_radius)
        shape = Shape.load(self.shape, World(self.world_radius), mesh_scale=self.mesh_scale, scale=self.shape_scale)
        check_world_memory(self.world_radius, dims=shape.dims)
        params = self.run_params(self.robots or shape.patches)
        from .run_bounds import check_run

        check_run(shape, params)
        return shape, params


_MODEL = {f.name for part in (_Model, _ModelRest) for f in fields(part)}
#: The run's parameters, in the order of results.csv's columns: :class:`Settings`' fields' declarations.
RUN_PARAMETERS: tuple[Param, ...] = tuple(
    replace(f.metadata["param"], name=f.name, model=f.name in _MODEL) for f in fields(Settings)
)
RUN_PARAMETER = {p.name: p for p in RUN_PARAMETERS}
EXPERIMENT_AXES = tuple(p.name for p in RUN_PARAMETERS if p.experiment == "axis")  #: may list several values

BATCH_LOSS_POLICIES = ("restart", "remove")  #: what the graph does when a robot-batch process dies
MAX_RESTARTS = 3  #: restarts of one robot batch's process, at most, before its robots are removed

#: Each ROS node's own parameters (not run parameters: they do not change what the swarm does).
#: How many world processes share the world's work by region (``swarm-ros run --world-shards``, the launch file's
#: ``world_shards``, the monitor's): 1, the one world node; S > 1, S world shard nodes, each owning the strips of
#: consecutive robot batches (at most one shard per batch).
WORLD_SHARDS = Param("world_shards", 1, "world processes S: 1 the world node, S > 1 world shards by region", low=1)

#: Every how many ticks the robots' rows go into the recording and the bag (the world's and the monitor's: the
#: world publishes them that often, with its per-tick tallies in between, and the monitor checks that it was told
#: the same). Metrics: every tick.
RECORD_EVERY = Param(
    "record_every",
    0,
    "log the robots every k-th tick (metrics: every tick)",
    low=1,
    blank="chosen from the swarm's size",
)
#: robot rows the recording and the bag take per tick, on average, when ``record_every`` is chosen from the size
POSES_PER_TICK = 10_000


def auto_every(params: RunParams) -> int:
    """``record_every`` of a run, when the user chose none, one rule for every algorithm: its algorithm's own
    cadence (the entry's ``record_every``: the study's model every tick, the rubenstein algorithm, whose robots
    step 0.05 d a tick, every 20th), or every ceil(robots / :data:`POSES_PER_TICK`)-th tick if that is rarer. Logged
    every tick, the robots of a 50,000-robot run made the in-process engine's run 1.5x as long and took a fifth of
    the monitor's CPU; in the graph, every robot's row every tick bounded the run by the monitor."""
    return max(algorithm_of(params.algorithm).record_every, -(-params.robots // POSES_PER_TICK))


NODE_PARAMETERS: dict[str, tuple[Param, ...]] = {
    "world": (
        Param(
            "monitor_window", 128, "max ticks the world runs ahead of the monitor", low=0, blank="do not wait for one"
        ),
        Param("start_timeout", 60.0, "seconds to wait for robot batches to cover every robot", low=0, low_open=True),
        Param(
            "on_batch_loss",
            "restart",
            "restart: wait for a lost batch process to come back; remove: remove its robots",
            choices=BATCH_LOSS_POLICIES,
        ),
        Param(
            "max_restarts",
            MAX_RESTARTS,
            "restarts per node process (each batch, the world, the monitor); a "
            "batch lost once more has its robots removed, a world or monitor lost once more ends the run",
            low=0,
        ),
        Param(
            "checkpoint",
            "",
            "file the world saves its checkpoint into (tick 0, then every 1,000 ticks or so), from which a restarted "
            "world goes on",
            blank="none: a lost world ends the run",
        ),
        Param("incarnation", 0, "0 for the world's first process; the launcher counts restarts up from 1", low=0),
        Param(
            "tick_rate",
            0.0,
            "at most this many ticks a second, to watch a run live; results do not change",
            low=1,
            high=1000,
            blank="as fast as the graph goes",
        ),
        RECORD_EVERY,
    ),
    "robot_batch": (
        Param("batch", 0, "this process decides for the robots in strip `batch` of `batches` ...", low=0),
        Param("batches", 1, "... of this many strips of the world along x", low=1),
        Param(
            "region_cuts",
            "",
            "x positions where strips 1.. start, e.g. -20,0,20 (patches; rubenstein: d); every batch needs the same",
            blank="cut so that each strip starts with as many robots",
            list_text=True,
        ),
        Param("incarnation", 0, "0 for a batch's first process; the launcher counts restarts up from 1", low=0),
    ),
    "monitor": (
        Param("out_dir", "", "run directory", blank="runs/<time>_<shape>_n<N>_v<R>_s<seed>"),
        Param("overwrite", False, "replace an existing run directory"),
        Param("record", True, "write recording.rrd (Rerun) into the run directory"),
        RECORD_EVERY,
        Param("bag", True, "write bag/, a rosbag2 (MCAP) of every message on the swarm's topics"),
        Param("viewer_url", "", "also stream live to this Rerun viewer, e.g. rerun+http://127.0.0.1:9876/proxy"),
        Param("incarnation", 0, "0 for the monitor's first process; a restarted one goes on from its bag", low=0),
        WORLD_SHARDS,
    ),
}

#: A world shard (``--world-shards``) has the world's parameters, the batches' cut, and which shard it is.
NODE_PARAMETERS["world_shard"] = (
    *NODE_PARAMETERS["world"],
    Param("shard", 0, "this process is world shard `shard` of `shards` ...", low=0),
    Param("shards", 1, "... each owning the strips of consecutive robot batches", low=1),
    *(p for p in NODE_PARAMETERS["robot_batch"] if p.name in ("batches", "region_cuts")),
)


def node_parameter(kind: str, name: str) -> Param:
    """The declaration of node ``kind``'s own parameter ``name``."""
    return next(p for p in NODE_PARAMETERS[kind] if p.name == name)


def node_defaults(kind: str) -> dict[str, Any]:
    """A node's own parameters and their defaults."""
    return {p.name: p.default for p in NODE_PARAMETERS[kind]}


@dataclass(frozen=True)
class RunParams(_ModelRest, _Model):
    """Everything that, with the shape, fixes a run: the model's run parameters (the :class:`Settings` fields
    declared ``model``, in their order, with their defaults), validated on construction, ``robots`` resolved (>= 4:
    0 is refused) and the rule set's switches resolved ("" becomes the rule set's own value)."""

    def __post_init__(self) -> None:
        for p in RUN_PARAMETERS:
            if p.model and p.name not in ("join", "crowding", "steps", "rules"):
                object.__setattr__(self, p.name, p.check(getattr(self, p.name)))
        if self.max_ticks == 0:  # the algorithm's own
            object.__setattr__(self, "max_ticks", algorithm_of(self.algorithm).max_ticks)
        # the default rule set's switches, resolved, are its defaults too (a summary's parameters hold them so)
        unset = dict(zip(("join", "crowding", "steps"), RULE_SETS[DEFAULT_RULES]))
        for p in RUN_PARAMETERS:
            value = getattr(self, p.name, p.default)
            if p.algorithm not in ("", self.algorithm) and value not in (p.default, unset.get(p.name)):
                raise ParameterError(
                    f"{p.name} is a parameter of the {p.algorithm} algorithm, not of {self.algorithm}, got {value!r}"
                )
        own_checks = algorithm_of(self.algorithm).hook("check_params")
        if own_checks is not None:
            own_checks(self)
        if self.robots == 0:
            raise ParameterError(f"robots must be an integer >= {MIN_ROBOTS}, got 0")
        ruleset = RuleSet.resolve(self.rules, self.join, self.crowding, self.steps)
        for name in ("join", "crowding", "steps"):
            object.__setattr__(self, name, getattr(ruleset, name))
        if self.fail_fraction > 0 and self.fail_tick < 1:
            raise ParameterError(f"fail_tick must be >= 1 when fail_fraction > 0, got {self.fail_tick}")
        if self.fail_fraction > 0 and self.fail_tick >= self.max_ticks:
            raise ParameterError(
                f"fail_tick must be before max_ticks ({self.max_ticks}) when fail_fraction > 0, "
                f"got {self.fail_tick}: no robot would fail"
            )

    def check_shape(self, shape: Shape) -> None:
        """Refuse a shape the algorithm cannot form (rubenstein: 3D; the algorithm's own check), or a vision radius
        beyond the world."""
        own_check = algorithm_of(self.algorithm).hook("check_shape")
        if own_check is not None:
            own_check(self, shape)

    def check_vision(self, world_radius: int) -> None:
        """Refuse a vision radius beyond the world's radius: a robot would see across the whole world.

        Raises:
            ParameterError: ``vision_radius > world_radius``.
        """
        if self.vision_radius > world_radius:
            raise ParameterError(
                f"vision_radius must be <= the world radius {world_radius} (a robot would see "
                f"across the whole world), got {self.vision_radius:g}"
            )

    @property
    def failures(self) -> int:
        """How many robots fail at ``fail_tick``: ``round(fail_fraction * robots)``."""
        return round(self.fail_fraction * self.robots)

    @property
    def ruleset(self) -> RuleSet:
        """The rule set in force, switches resolved."""
        return RuleSet(self.rules, self.join, self.crowding, self.steps)

    @property
    def wiggle_rad(self) -> float:
        return math.radians(self.wiggle_deg)

    def as_dict(self) -> dict:
        return asdict(self)


def check_vision_fits(params: RunParams, shape: Shape) -> None:
    """The study's model's shape check (core.algorithm): a vision radius beyond the shape's world is refused."""
    params.check_vision(shape.world.radius)


def foreign_defaults(algorithm: str) -> dict[str, Any]:
    """The run parameters of every other algorithm, at their defaults: what a run of ``algorithm`` takes for them
    (an experiment's run, a results.csv row)."""
    return {p.name: p.default for p in RUN_PARAMETERS if p.algorithm not in ("", algorithm)}
