"""The report's figure of the algorithms side by side (``figures/algorithms.png``): every rule set and algorithm of
an experiment on shared axes, a row per shape."""

from __future__ import annotations

import numpy as np

from swarm_ros.app.report_stats import _COLOURS, _rules_order, _setting
from swarm_ros.artifacts.mpl import plt


def algorithms_figure(stats: list[dict]) -> plt.Figure:
    """Every rule set and algorithm of the report side by side on shared axes, a row per shape: (a) ticks to 50% and
    90% filled and to the end against the group size (log scale: the algorithms' ticks differ a hundredfold),
    (b) the share of the shape filled, each with its 95% CI."""
    shapes = sorted({s["shape"] for s in stats})
    order = _rules_order(stats)
    fig, axes = plt.subplots(len(shapes), 2, figsize=(11, 3.6 * len(shapes)), dpi=110, squeeze=False)
    fig.suptitle("The algorithms side by side (means over the runs, 95% CI)", fontsize=12)
    for (a, b), shape in zip(axes, shapes):
        for k, rules in enumerate(order):
            for vision in sorted({s["vision_radius"] for s in stats if s["rules"] == rules}):
                group = [
                    s for s in stats if s["shape"] == shape and s["rules"] == rules and s["vision_radius"] == vision
                ]
                if not group:
                    continue
                label = _setting(rules, vision)
                colour = _COLOURS[k % len(_COLOURS)]
                n = np.array([s["robots"] for s in group])
                end = np.array([s["mean_convergence_tick"] for s in group])
                a.errorbar(
                    n,
                    end,
                    yerr=np.nan_to_num(
                        np.vstack(
                            [
                                end - np.maximum([s["ci95_low"] for s in group], 1),
                                [s["ci95_high"] - s["mean_convergence_tick"] for s in group],
                            ]
                        )
                    ),
                    fmt="o-",
                    capsize=3,
                    color=colour,
                    label=f"{label}: end",
                )
                for key, style in (("fill_50_tick", "^:"), ("fill_90_tick", "v--")):
                    mean = np.array([s[f"mean_{key}"] for s in group])
                    half = np.nan_to_num([s[f"ci95_half_{key}"] for s in group])
                    a.errorbar(n, mean, yerr=half, fmt=style, capsize=3, color=colour, label=f"{label}: {key[5:7]}%")
                filled = 100 * np.array([s["mean_coverage"] for s in group])
                half = 100 * np.nan_to_num([s["ci95_half_coverage"] for s in group])
                b.errorbar(n, filled, yerr=half, fmt="o-", capsize=3, color=colour, label=label)
        a.set_yscale("log")
        a.set_title(f"{shape}: (a) ticks to 50% and 90% filled, and to the end", fontsize=10)
        a.set_xlabel("group size N (robots)")
        a.set_ylabel("ticks")
        a.legend(fontsize=6, ncol=2)
        b.set_title(f"{shape}: (b) share of the shape filled", fontsize=10)
        b.set_xlabel("group size N (robots)")
        b.set_ylabel("filled (%)")
        b.set_ylim(0, 105)
        b.legend(fontsize=7)
    fig.tight_layout(rect=(0, 0, 1, 0.985))  # below the suptitle
    return fig
