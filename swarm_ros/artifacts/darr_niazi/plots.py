"""Pictures of a run (matplotlib, headless)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from swarm_ros.artifacts.mpl import ListedColormap, Patch, plt
from swarm_ros.core.darr_niazi.run_result import RunRecord
from swarm_ros.core.darr_niazi.state import RobotState

# Patch classes of the picture and their colours (colour-blind safe, Okabe-Ito based).
_CLASSES = (
    ("free", "#ffffff"),
    ("wall", "#4d4d4d"),
    ("empty shape patch", "#f3d9a4"),
    ("localized robot", "#0072b2"),
    ("seed robot", "#d55e00"),
)
_MOVING_COLOUR = "#009e73"
_WALKING_COLOUR = "#e69f00"
_SEPARATED_COLOUR = "#cc79a7"


def save_final_png(run: RunRecord, path: Path) -> None:
    """The formed shape: walls, shape patches, localized robots, seeds and left-over robots (a 3D run:
    :func:`save_final_png_3d`)."""
    if run.shape.dims == 3:
        save_final_png_3d(run, path)
        return
    world, s = run.shape.world, run.state
    r = world.radius
    grid = np.zeros((world.size, world.size), dtype=np.int8)
    grid[world.wall_mask()] = 1
    grid[run.shape.mask] = 2
    occ = s.occupancy.reshape(world.size, world.size)
    grid[occ >= 0] = 3
    grid[np.isin(occ, np.arange(4))] = 4

    fig, ax = plt.subplots(figsize=(6.4, 6.8), dpi=120)
    ax.imshow(
        grid,
        origin="lower",
        cmap=ListedColormap([c for _, c in _CLASSES]),
        vmin=0,
        vmax=len(_CLASSES) - 1,
        extent=(-r - 0.5, r + 0.5, -r - 0.5, r + 0.5),
        interpolation="nearest",
    )
    handles = [Patch(facecolor=c, edgecolor="#999999", label=name) for name, c in _CLASSES[1:]]
    moving = (s.state == RobotState.MOVING_INSIDE) | (s.state == RobotState.MOVING_OUTSIDE)
    for mask, colour, label in (
        (moving, _MOVING_COLOUR, "wandering robot"),
        (s.state == RobotState.WALKING, _WALKING_COLOUR, "walking robot"),
        (s.state == RobotState.SEPARATED, _SEPARATED_COLOUR, "separated robot"),
    ):
        if mask.any():
            ax.scatter(s.x[mask], s.y[mask], s=9, c=colour, linewidths=0, zorder=3)
            handles.append(Patch(facecolor=colour, label=f"{label} ({int(mask.sum())})"))
    m, p = run.final, run.params
    ax.set_title(
        f"{run.shape.name}: {run.outcome} at tick {m.tick}\n"
        f"{p.robots} robots, rules {p.ruleset.label}, vision {p.vision_radius:g}, seed {p.seed}; "
        f"{m.localized}/{run.shape.patches} patches filled",
        fontsize=10,
    )
    ax.set_xlabel("x (patches)")
    ax.set_ylabel("y (patches)")
    ax.set_aspect("equal")
    ax.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, -0.09), ncol=3, fontsize=8, frameon=False)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


# The three views of a 3D run's final.png: (title, axis projected away, horizontal and vertical axes).
_VIEWS_3D = (
    ("from above (along z)", 0, "x", "y"),
    ("from the front (along y)", 1, "x", "z"),
    ("from the side (along x)", 2, "y", "z"),
)


def save_final_png_3d(run: RunRecord, path: Path) -> None:
    """A 3D run's formed shape as three projections, from above, the front and the side.

    Each cell of a view is a line of voxels through the world: white if the line meets no
    shape voxel, else coloured by the fraction of its shape voxels that are filled (a
    localized robot or a seed on them), so an empty voxel anywhere along a line shows. The
    left-over robots are drawn where they stand, projected. The views are zoomed to the shape
    and 3 voxels round it: the legend counts every robot, and says how many stand outside the zoom.
    """
    world, s, shape = run.shape.world, run.state, run.shape
    r = world.radius
    filled = (s.occupancy >= 0).reshape(world.grid_shape)  # [iz, iy, ix]
    assert s.z is not None, "a 3D run's state has z"
    position = {"x": s.x, "y": s.y, "z": s.z}
    fig, axes = plt.subplots(1, 3, figsize=(13.5, 5.0), dpi=110, layout="constrained")
    image = None
    for ax, (title, axis, across, up) in zip(axes, _VIEWS_3D):
        total = shape.mask.sum(axis=axis)
        done = filled.sum(axis=axis)
        fraction = np.where(total > 0, done / np.maximum(total, 1), np.nan)
        image = ax.imshow(
            fraction,
            origin="lower",
            cmap="cividis",
            vmin=0.0,
            vmax=1.0,
            interpolation="nearest",
            extent=(-r - 0.5, r + 0.5, -r - 0.5, r + 0.5),
        )
        lo, hi = shape.bbox[:3], shape.bbox[3:]  # zoomed to the shape, 3 voxels round it
        a, u = "xyz".index(across), "xyz".index(up)
        ax.set_xlim(lo[a] - 3.5, hi[a] + 3.5)
        ax.set_ylim(lo[u] - 3.5, hi[u] + 3.5)
        for state, colour in (
            (RobotState.MOVING_INSIDE, _MOVING_COLOUR),
            (RobotState.MOVING_OUTSIDE, _MOVING_COLOUR),
            (RobotState.WALKING, _WALKING_COLOUR),
            (RobotState.SEPARATED, _SEPARATED_COLOUR),
        ):
            mask = s.state == state
            if mask.any():
                ax.scatter(position[across][mask], position[up][mask], s=6, c=colour, linewidths=0, zorder=3)
        ax.set_title(title, fontsize=10)
        ax.set_xlabel(f"{across} (voxels)")
        ax.set_ylabel(f"{up} (voxels)")
        ax.set_aspect("equal")
    assert image is not None  # three views: each drew one
    fig.colorbar(image, ax=list(axes), shrink=0.8, label="filled fraction of the shape voxels along the line")
    low, high = np.asarray(shape.bbox[:3]), np.asarray(shape.bbox[3:])
    xyz = np.stack([s.x, s.y, s.z], axis=1)
    beyond = ((xyz < low - 3.5) | (xyz > high + 3.5)).any(axis=1)  # outside the zoomed box: missing from some view

    def counted(states: tuple[RobotState, ...]) -> str:
        mask = np.isin(s.state, states)
        away = int((mask & beyond).sum())
        return f"{int(mask.sum())}" + (f"; {away} outside the zoom" if away else "")

    handles = [
        Patch(facecolor=c, label=f"{label} ({counted(states)})")
        for label, c, states in (
            ("wandering robot", _MOVING_COLOUR, (RobotState.MOVING_INSIDE, RobotState.MOVING_OUTSIDE)),
            ("walking robot", _WALKING_COLOUR, (RobotState.WALKING,)),
            ("separated robot", _SEPARATED_COLOUR, (RobotState.SEPARATED,)),
        )
    ]
    m, p = run.final, run.params
    fig.suptitle(
        f"{shape.name} (3D): {run.outcome} at tick {m.tick}; {p.robots} robots, rules {p.ruleset.label}, "
        f"vision {p.vision_radius:g}, seed {p.seed}; {m.localized}/{shape.patches} voxels filled",
        fontsize=11,
    )
    fig.legend(handles=handles, loc="outside lower center", ncol=3, fontsize=8, frameon=False)  # room made for it
    fig.savefig(path)
    plt.close(fig)


# Series of convergence.png: metrics.csv column, legend label, colour (as in the recording).
_CONVERGENCE_SERIES = (
    ("localized", "localized robots (seeds included)", "#0072b2"),
    ("stationary", "stationary robots (localized + separated)", "#e69f00"),
    ("inside", "robots wandering inside the shape", "#c9b800"),
    ("walking", "robots walking to the frontier", "#56b4e9"),
    ("empty_patches", "empty shape patches", "#cc79a7"),
)


def save_convergence_png(run: RunRecord, path: Path) -> None:
    """Stationary, localized, wandering-inside and walking robots, and empty patches against ticks, with the
    outcome marked."""
    from swarm_ros.core.darr_niazi.metrics import METRIC_COLUMNS

    h = run.history
    ticks = h[:, 0]
    fig, ax = plt.subplots(figsize=(7.2, 4.4), dpi=120)
    for column, label, colour in _CONVERGENCE_SERIES:
        style = "--" if column == "stationary" else "-"
        ax.plot(ticks, h[:, METRIC_COLUMNS.index(column)], style, color=colour, lw=1.4, label=label)
    ax.axhline(run.shape.patches, color="#999999", lw=0.8, ls=":", label=f"shape patches ({run.shape.patches})")
    m = run.final
    ax.axvline(m.tick, color="#333333", lw=1.0)
    ax.text(
        m.tick,
        0.97,
        f"{run.outcome} at tick {m.tick} ",
        transform=ax.get_xaxis_transform(),
        ha="right",
        va="top",
        fontsize=9,
        color="#333333",
        bbox={"facecolor": "white", "edgecolor": "none", "alpha": 0.85},
    )
    p = run.params
    ax.set_title(
        f"{run.shape.name}: {p.robots} robots, rules {p.ruleset.label}, vision {p.vision_radius:g}, seed {p.seed}",
        fontsize=10,
    )
    ax.set_xlabel("tick")
    ax.set_ylabel("robots or patches")
    ax.set_xlim(0, max(int(m.tick), 1) * 1.03)
    ax.set_ylim(0, max(p.robots, run.shape.patches) * 1.12)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="center right", frameon=False)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
