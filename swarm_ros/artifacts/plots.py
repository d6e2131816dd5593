"""Pictures of a run (matplotlib, headless)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.colors import ListedColormap  # noqa: E402
from matplotlib.patches import Patch  # noqa: E402

from swarm_ros.core.run_result import RunRecord  # noqa: E402
from swarm_ros.core.state import RobotState  # noqa: E402

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
    """The formed shape: walls, shape patches, localized robots, seeds and left-over robots."""
    world, s = run.shape.world, run.state
    r = world.radius
    grid = np.zeros((world.size, world.size), dtype=np.int8)
    grid[world.wall_mask()] = 1
    grid[run.shape.mask] = 2
    occ = s.occupancy.reshape(world.size, world.size)
    grid[occ >= 0] = 3
    grid[np.isin(occ, np.arange(4))] = 4

    fig, ax = plt.subplots(figsize=(6.4, 6.8), dpi=120)
    ax.imshow(grid, origin="lower", cmap=ListedColormap([c for _, c in _CLASSES]), vmin=0, vmax=len(_CLASSES) - 1,
              extent=(-r - 0.5, r + 0.5, -r - 0.5, r + 0.5), interpolation="nearest")
    handles = [Patch(facecolor=c, edgecolor="#999999", label=name) for name, c in _CLASSES[1:]]
    moving = (s.state == RobotState.MOVING_INSIDE) | (s.state == RobotState.MOVING_OUTSIDE)
    for mask, colour, label in ((moving, _MOVING_COLOUR, "wandering robot"),
                                (s.state == RobotState.WALKING, _WALKING_COLOUR, "walking robot"),
                                (s.state == RobotState.SEPARATED, _SEPARATED_COLOUR, "separated robot")):
        if mask.any():
            ax.scatter(s.x[mask], s.y[mask], s=9, c=colour, linewidths=0, zorder=3)
            handles.append(Patch(facecolor=colour, label=f"{label} ({int(mask.sum())})"))
    m, p = run.final, run.params
    ax.set_title(f"{run.shape.name}: {run.outcome} at tick {m.tick}\n"
                 f"{p.robots} robots, rules {p.ruleset.label}, vision {p.vision_radius:g}, seed {p.seed}; "
                 f"{m.localized}/{run.shape.patches} patches filled", fontsize=10)
    ax.set_xlabel("x (patches)")
    ax.set_ylabel("y (patches)")
    ax.set_aspect("equal")
    ax.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, -0.09), ncol=3, fontsize=8, frameon=False)
    fig.tight_layout()
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
    from swarm_ros.core.metrics import METRIC_COLUMNS

    h = run.history
    ticks = h[:, 0]
    fig, ax = plt.subplots(figsize=(7.2, 4.4), dpi=120)
    for column, label, colour in _CONVERGENCE_SERIES:
        style = "--" if column == "stationary" else "-"
        ax.plot(ticks, h[:, METRIC_COLUMNS.index(column)], style, color=colour, lw=1.4, label=label)
    ax.axhline(run.shape.patches, color="#999999", lw=0.8, ls=":", label=f"shape patches ({run.shape.patches})")
    m = run.final
    ax.axvline(m.tick, color="#333333", lw=1.0)
    ax.text(m.tick, 0.97, f"{run.outcome} at tick {m.tick} ", transform=ax.get_xaxis_transform(), ha="right",
            va="top", fontsize=9, color="#333333", bbox={"facecolor": "white", "edgecolor": "none", "alpha": 0.85})
    p = run.params
    ax.set_title(f"{run.shape.name}: {p.robots} robots, rules {p.ruleset.label}, vision {p.vision_radius:g}, "
                 f"seed {p.seed}", fontsize=10)
    ax.set_xlabel("tick")
    ax.set_ylabel("robots or patches")
    ax.set_xlim(0, max(int(m.tick), 1) * 1.03)
    ax.set_ylim(0, max(p.robots, run.shape.patches) * 1.12)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="center right", frameon=False)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
