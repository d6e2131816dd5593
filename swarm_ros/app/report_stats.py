"""The statistics and tables of an experiment's report: per grid point, from results.csv's rows
(:mod:`swarm_ros.app.report` writes them, with the figures)."""

from __future__ import annotations

import csv
import io
import math
from collections import defaultdict

import numpy as np
from scipy import stats as st

from swarm_ros.app.published import Reference
from swarm_ros.core.algorithm import DARR_NIAZI, names
from swarm_ros.core.darr_niazi.rulesets import RULE_SETS, RuleSet
from swarm_ros.core.metrics import Outcome
from swarm_ros.core.params import RUN_PARAMETER

STATS_CSV, STATS_MD, FIGURES = "stats.csv", "stats.md", "figures"
OUTCOMES = tuple(o.value for o in Outcome)
STATS_COLUMNS = (
    "shape",
    "shape_patches",
    "robots",
    "vision_radius",
    "rules",
    "runs",
    "mean_convergence_tick",
    "sd_convergence_tick",
    "ci95_low",
    "ci95_high",
    "mean_localized",
    "mean_unlocalized",
    "mean_separated",
    "mean_empty_patches",
    "mean_lost_robots",
    *OUTCOMES,
    "completed_fraction",
    "mean_convergence_rate",
    "mean_coverage",
    "mean_fill_50_tick",
    "mean_fill_90_tick",
    "mean_joined_outside",
    "mean_hole_filled",
    "mean_loc_error",
    *(f"{what}_{k}" for k in ("coverage", "fill_50_tick", "fill_90_tick") for what in ("ci95_half", "runs")),
)
COMPARED = ("coverage", "fill_50_tick", "fill_90_tick", "joined_outside", "hole_filled", "loc_error")
_COLOURS = ("#0072b2", "#d55e00", "#009e73", "#cc79a7", "#e69f00", "#56b4e9", "#000000")


def rules_label(row: dict) -> str:
    """The rule set a results row ran under: its name, plus any switch overrides (``local+crowding=disc``); the
    label of a run of an algorithm without rule sets (rubenstein) is the algorithm's name."""
    algorithm = row.get("algorithm", DARR_NIAZI)
    if RUN_PARAMETER["rules"].algorithm not in ("", algorithm):
        return algorithm
    return RuleSet(row["rules"], row["join"], row["crowding"], row["steps"]).label


def is_algorithm_label(label: str) -> bool:
    """Whether a :func:`rules_label` names an algorithm without rule sets (and vision radius) rather than a rule set."""
    return label in names()


def _setting(rules: str, vision: float) -> str:
    """A figure's words for what its runs ran: the rule set and vision radius, or the algorithm that has neither."""
    return f"the {rules} algorithm" if is_algorithm_label(rules) else f"rules {rules}, vision radius {vision:g}"


def _mean(values: list) -> float:
    """The mean of the values that are there (a fill tick a run never reached is None); nan if none is."""
    there = [v for v in values if v is not None]
    return float(np.mean(there)) if there else math.nan


def _half_ci(values: list) -> tuple[float, int]:
    """The half-width of the 95% confidence interval (Student t) of the mean of the values that are there, and how
    many are (a fill tick a run never reached is None); nan with fewer than two."""
    there = np.array([v for v in values if v is not None], dtype=float)
    if there.size < 2:
        return math.nan, int(there.size)
    return float(st.t.ppf(0.975, there.size - 1) * there.std(ddof=1) / math.sqrt(there.size)), int(there.size)


def group_stats(rows: list[dict]) -> list[dict]:
    """One statistics row per (shape, group size, vision radius, rule set), sorted by them.

    ``rules`` is the rule set's label (:func:`rules_label`). ``completed_fraction`` is the
    fraction of runs that completed the shape (outcome complete or complete_with_extras);
    ``mean_convergence_rate`` is the mean of the runs' convergence rates (robots joined per tick).
    """
    groups: dict[tuple, list[dict]] = defaultdict(list)
    for r in rows:
        groups[(r["shape"], r["robots"], r["vision_radius"], rules_label(r))].append(r)
    out = []
    for (shape, robots, vision, rules), runs in sorted(groups.items()):
        ticks = np.array([r["convergence_tick"] for r in runs], dtype=float)
        n = ticks.size
        mean = float(ticks.mean())
        sd = float(ticks.std(ddof=1)) if n > 1 else math.nan
        half = float(st.t.ppf(0.975, n - 1) * sd / math.sqrt(n)) if n > 1 else math.nan
        counts = {o: sum(r["outcome"] == o for r in runs) for o in OUTCOMES}
        out.append(
            {
                "shape": shape,
                "shape_patches": runs[0]["shape_patches"],
                "robots": robots,
                "vision_radius": vision,
                "rules": rules,
                "runs": n,
                "mean_convergence_tick": mean,
                "sd_convergence_tick": sd,
                "ci95_low": mean - half,
                "ci95_high": mean + half,
                **{
                    f"mean_{k}": float(np.mean([r[k] for r in runs]))
                    for k in ("localized", "unlocalized", "separated", "empty_patches", "lost_robots")
                },
                **counts,
                "completed_fraction": (counts["complete"] + counts["complete_with_extras"]) / n,
                "mean_convergence_rate": float(np.mean([r["convergence_rate"] for r in runs])),
                **{f"mean_{k}": _mean([r.get(k) for r in runs]) for k in COMPARED},
            }
        )
        for k in ("coverage", "fill_50_tick", "fill_90_tick"):
            out[-1][f"ci95_half_{k}"], out[-1][f"runs_{k}"] = _half_ci([r.get(k) for r in runs])
    return out


def stats_csv(stats: list[dict]) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(STATS_COLUMNS)
    for s in stats:
        w.writerow([_fmt(s[c]) for c in STATS_COLUMNS])
    return buf.getvalue()


def _fmt(value: object) -> str:
    if isinstance(value, float):
        return "nan" if math.isnan(value) else f"{value:.6g}" if abs(value) < 1e6 else f"{value:.1f}"
    return str(value)


def _ci(s: dict) -> str:
    """The interval as stats.md shows it: a lower bound below 0 (wide t-intervals of a few runs) as 0, since a
    time is never negative (stats.csv keeps the interval as computed)."""
    return "–" if math.isnan(s["ci95_low"]) else f"[{max(s['ci95_low'], 0):.0f}, {s['ci95_high']:.0f}]"


def _rules_order(stats: list[dict]) -> list[str]:
    """The rule set labels of the stats: the named sets in their own order (paper, local, literal), each
    before its variants with overrides, then any other label alphabetically."""
    names = list(RULE_SETS)
    return sorted(
        {s["rules"] for s in stats},
        key=lambda label: (names.index(label.split("+")[0]) if label.split("+")[0] in names else len(names), label),
    )


def _sections(stats: list[dict]) -> list[tuple[str, float]]:
    """(rule set, vision radius) of the stats, rule sets in :func:`_rules_order`, radii ascending."""
    return [(r, v) for r in _rules_order(stats) for v in sorted({s["vision_radius"] for s in stats if s["rules"] == r})]


def stats_markdown(stats: list[dict], reference: dict[str, Reference] | None = None) -> str:
    """The summary table, one section per rule set and vision radius, in the original study's layout;
    with ``reference``, a comparison with the published numbers after it."""
    lines = []
    for rules, vision in _sections(stats):
        if is_algorithm_label(rules):  # no vision radius; its counts are of robots joined and pixels covered
            title, cells, counts = "### The rubenstein algorithm", "pixels", "joined | not joined | uncovered pixels"
        else:
            title, cells, counts = (
                f"### Rules `{rules}`, vision radius {vision:g}",
                "patches",
                ("localized | unlocalized | empty patches"),
            )
        lines += [
            title,
            "",
            f"| shape | {cells} | robots | runs | mean time (ticks) | 95% CI | {counts} | outcomes |",
            "|---|---:|---:|---:|---:|---|---:|---:|---:|---|",
        ]
        for s in (s for s in stats if s["vision_radius"] == vision and s["rules"] == rules):
            outcomes = ", ".join(f"{s[o]} {o}" for o in OUTCOMES if s[o])
            mark = " **=**" if s["robots"] == s["shape_patches"] else ""
            lines.append(
                f"| {s['shape']} | {s['shape_patches']} | {s['robots']}{mark} | {s['runs']} | "
                f"{s['mean_convergence_tick']:.0f} | {_ci(s)} | {s['mean_localized']:.1f} | "
                f"{s['mean_unlocalized']:.1f} | {s['mean_empty_patches']:.1f} | {outcomes} |"
            )
        lines.append("")
    lines.append(
        "Times are convergence ticks (the tick the run ended). 95% CI: Student t on the runs' "
        "convergence ticks, its lower bound shown as 0 where it falls below (stats.csv keeps it as computed). "
        "**=** marks the group size equal to the shape's patch count. Under the rubenstein algorithm the counts "
        "are of robots joined, robots not joined, and shape pixels no joined robot covers."
    )
    lines += ["", *time_and_accuracy(stats)]
    if reference:
        lines += ["", *against_reference([s for s in stats if not is_algorithm_label(s["rules"])], reference)]
    return "\n".join(lines) + "\n"


def time_and_accuracy(stats: list[dict]) -> list[str]:
    """Markdown: the measures both algorithms are compared on, per shape and group size, each rule set or
    algorithm in a row."""
    lines = [
        "## Time and accuracy",
        "",
        "Ticks to 50% and 90% of the shape filled, and at the end: the share of the shape filled (patches "
        "localized; under rubenstein, shape pixels a joined robot's disc meets), robots joined outside the "
        "shape, the share of the area of its holes (if any) under a joined robot, and the joined robots' "
        "localization error in robot diameters "
        "(none of these under the study's model, whose robots localize exactly on shape patches). "
        "Means over the runs, with the half-width of their 95% confidence interval (Student t) for t50, t90 and "
        "filled; a time is the mean of the runs that reached it, with how many did when not all; a time no run "
        "reached is –; completed: the share of runs that ended complete or complete_with_extras.",
        "",
        "| shape | robots | rules / algorithm | vision | runs | t50 | t90 | end tick | filled | outside | "
        "hole filled | loc. error | completed |",
        "|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    order = _rules_order(stats)
    for s in sorted(stats, key=lambda s: (s["shape"], s["robots"], order.index(s["rules"]), s["vision_radius"])):
        t50, t90 = (_tick_ci(s, f"fill_{p}_tick") for p in (50, 90))
        vision = "–" if is_algorithm_label(s["rules"]) else f"{s['vision_radius']:g}"  # not a parameter of it
        half = 100 * s["ci95_half_coverage"]
        filled = f"{s['mean_coverage']:.1%}" if math.isnan(half) else f"{100 * s['mean_coverage']:.1f} ± {half:.1f}%"
        lines.append(
            f"| {s['shape']} | {s['robots']} | {s['rules']} | {vision} | {s['runs']} | {t50} | {t90} "
            f"| {s['mean_convergence_tick']:.0f} | {filled} | {s['mean_joined_outside']:.1f} "
            f"| {s['mean_hole_filled']:.1%} | {s['mean_loc_error']:.3f} | {s['completed_fraction']:.0%} |"
        )
    return lines


def _plus_minus(half: float, spec: str) -> str:
    return "" if math.isnan(half) else f" ± {half:{spec}}"


def _tick_ci(s: dict, key: str) -> str:
    """A time's mean, its 95% CI's half-width, and (when not every run reached it) how many did."""
    if math.isnan(s[f"mean_{key}"]):
        return "–"
    reached = s[f"runs_{key}"]
    return f"{s[f'mean_{key}']:.0f}{_plus_minus(s[f'ci95_half_{key}'], '.0f')}" + (
        f" ({reached} of {s['runs']})" if reached < s["runs"] else ""
    )


def against_reference(stats: list[dict], reference: dict[str, Reference]) -> list[str]:
    """Markdown: each shape's result at N = its patch count beside the published one, per rule set and radius;
    and the range of the mean over the other group sizes beside the published range."""
    lines = [
        "## Against the published numbers",
        "",
        "Each shape at N = its exact patch count (the study's count is its own, given in brackets). "
        "Ratio = our mean / the published mean. *In CI*: whether our mean lies in the published 95% CI. "
        "Range: the mean over the other group sizes, lowest to highest.",
        "",
    ]
    for rules, vision in _sections(stats):
        rows = [s for s in stats if s["rules"] == rules and s["vision_radius"] == vision]
        exact = {s["shape"]: s for s in rows if s["robots"] == s["shape_patches"]}
        shapes = [name for name in reference if name in exact]
        if not shapes:
            continue
        lines += [
            f"### Rules `{rules}`, vision radius {vision:g}",
            "",
            "| shape | published mean [95% CI] | ours (N) | our mean [95% CI] | ratio | in CI "
            "| published range | our range |",
            "|---|---|---:|---|---:|---|---|---|",
        ]
        for name in shapes:
            ref, s = reference[name], exact[name]
            others = [o["mean_convergence_tick"] for o in rows if o["shape"] == name and o is not s]
            ours = f"{min(others):.0f}–{max(others):.0f}" if others else "–"
            lines.append(
                f"| {name} ({ref.study_robots}) | {ref.mean:g} [{ref.ci95_low:g}, {ref.ci95_high:g}] | "
                f"{s['robots']} | {s['mean_convergence_tick']:.1f} {_ci(s)} | "
                f"{s['mean_convergence_tick'] / ref.mean:.2f} | "
                f"{'yes' if ref.contains(s['mean_convergence_tick']) else 'no'} | "
                f"{ref.sizes_mean_min:g}–{ref.sizes_mean_max:g} | {ours} |"
            )
        ratios = np.array([exact[n]["mean_convergence_tick"] / reference[n].mean for n in shapes])
        summary = (
            f"Ratio {ratios.min():.2f}–{ratios.max():.2f}, geometric mean "
            f"{float(np.exp(np.log(ratios).mean())):.2f}; our mean within the published CI for "
            f"{sum(reference[n].contains(exact[n]['mean_convergence_tick']) for n in shapes)} of {len(shapes)}"
        )
        if len(shapes) >= 3:
            rho = st.spearmanr(
                [reference[n].mean for n in shapes], [exact[n]["mean_convergence_tick"] for n in shapes]
            ).statistic
            summary += f"; the shapes' order by time against the published order: Spearman ρ = {rho:.2f}"
        lines += ["", summary + ".", ""]
    return lines
