"""``swarm-ros report DIR``: statistics, tables and figures of an experiment, from its results.csv alone.

Per (shape, group size, vision radius, rule set): runs, mean convergence tick, its
standard deviation and 95% confidence interval (Student t), mean localized, unlocalized,
separated and empty patches, outcome counts, and mean convergence rate. Written as
``stats.csv`` and as ``stats.md``, a Markdown table laid out like the original study's
summary (shape, patches, robots, mean time, 95% CI). When the directory holds a
reference file (``reference.csv``, copied there from the experiment's ``reference``),
``stats.md`` also sets each shape's result at N = its patch count beside the published
one: both means and CIs, the ratio, and whether our mean lies in the published CI.

Figures go to ``figures/``, one set per rule set (``<rules>`` below):

- ``<shape>_<rules>_v<R>.png``: (a) mean convergence time against group size, (b) the
  same with 95% CI bars and the published point, (c) completeness (localized,
  unlocalized, empty patches) against group size, (d) one run's convergence curve per
  group size;
- ``all_shapes_<rules>_v<R>.png``: mean convergence time with 95% CI for every shape;
- ``vision.png`` (with more than one radius): convergence time and localized fraction
  against vision radius at each shape's exact patch count, a column per rule set;
- ``study.png`` (with a reference): our time / the published time at each shape's patch
  count, per rule set and radius;
- ``algorithms.png`` (with the rubenstein algorithm beside a rule set): a row per shape, every rule set
  and algorithm on shared axes: ticks to 50% and 90% filled and to the end, and the share filled, with
  95% CIs.

The rubenstein algorithm has no vision radius: its figures are ``<shape>_rubenstein.png`` and
``all_shapes_rubenstein.png``, and its panel (c) counts joined robots, robots not joined and uncovered pixels.

Panel (d) needs per-tick metrics, which results.csv does not hold. The report re-runs
the first repetition of each group size with the in-process engine from the seed in its
row (the engines give identical runs), and checks that the convergence tick matches.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path

import numpy as np

from swarm_ros.app.published import (
    Reference,
    load_reference,
)
from swarm_ros.app.report_compare import algorithms_figure
from swarm_ros.app.report_stats import (
    _COLOURS,
    FIGURES,
    STATS_CSV,
    STATS_MD,
    _rules_order,
    _sections,
    _setting,
    group_stats,
    is_algorithm_label,
    rules_label,
    stats_csv,
    stats_markdown,
)
from swarm_ros.app.results_file import (
    REFERENCE_FILE,
    RESULTS_FILE,
    ExperimentError,
    read_results,
)
from swarm_ros.artifacts.mpl import plt
from swarm_ros.artifacts.run_dir import public_mode
from swarm_ros.core.algorithm import DARR_NIAZI, algorithm_of


def _save(fig: plt.Figure, path: Path) -> None:
    part = path.with_name(f".{path.name}.tmp.png")
    fig.savefig(part)
    plt.close(fig)
    os.replace(part, path)


def _curve(row: dict, out: Path) -> np.ndarray:
    """The step curve (:func:`swarm_ros.app.curves.steps`) of the run in ``row``: the experiment's (``out``/curves),
    or, without one, the run re-run in process (checked against the row), then kept there for the next report."""
    from swarm_ros.app.curves import curve_of, read_curve, steps, write_curve
    from swarm_ros.core.params import RUN_PARAMETERS, Settings

    stored = read_curve(out, row)
    if stored is not None:
        return stored
    values = {p.name: row[p.name] for p in RUN_PARAMETERS if p.name in row and p.name != "shape"}
    shape, params = Settings(shape=row["shape_file"], **values).resolve()  # checked as any run is (check_run)
    sim = algorithm_of(params.algorithm).hook("engine")(shape, params)
    sim.run()
    outcome = sim.outcome.value if sim.outcome is not None else None
    if sim.tick != row["convergence_tick"] or outcome != row["outcome"]:
        raise ExperimentError(
            f"re-running {row['shape']} n={row['robots']} seed {row['seed']} gave "
            f"{sim.outcome} at tick {sim.tick}, the results say {row['outcome']} at tick "
            f"{row['convergence_tick']}"
        )
    curve = steps(curve_of(sim))
    write_curve(out, row, curve)
    return curve


def _cells(rules: str) -> str:
    """What a shape's cells are called in a run of ``rules`` (a rule set, or an algorithm's name): its algorithm's
    ``cells``."""
    return algorithm_of(rules if is_algorithm_label(rules) else DARR_NIAZI).cells


def _counts(rules: str) -> tuple[str, str, str]:
    """The words for results.csv's localized, unlocalized and empty_patches columns in a run of ``rules`` (a rule
    set, or an algorithm's name): its algorithm's ``count_words`` (under rubenstein they count the robots joined,
    the robots not joined and the shape's pixels no joined robot covers)."""
    return algorithm_of(rules if is_algorithm_label(rules) else DARR_NIAZI).count_words


def shape_figure(stats: list[dict], rows: list[dict], path: Path, out: Path, ref: Reference | None = None) -> None:
    """Panels (a)-(d) for one shape at one vision radius and rule set, of the experiment in ``out``; ``ref`` adds
    the published point to (b)."""
    s0 = stats[0]
    n = np.array([s["robots"] for s in stats])
    mean = np.array([s["mean_convergence_tick"] for s in stats])
    lo = np.array([s["ci95_low"] for s in stats])
    hi = np.array([s["ci95_high"] for s in stats])
    patches = s0["shape_patches"]
    fig, axes = plt.subplots(2, 2, figsize=(11, 8), dpi=110)
    (a, b), (c, d) = axes
    fig.suptitle(
        f"{s0['shape']} ({patches} {_cells(s0['rules'])}), {_setting(s0['rules'], s0['vision_radius'])}, "
        f"{s0['runs']} runs per group size",
        fontsize=12,
    )
    a.plot(n, mean, "o-", color=_COLOURS[0])
    a.set_title("(a) mean convergence time", fontsize=10)
    b.errorbar(
        n,
        mean,
        yerr=np.nan_to_num(np.vstack([mean - lo, hi - mean])),
        fmt="o-",
        capsize=4,
        color=_COLOURS[0],
        label="this project",
    )
    b.set_title("(b) mean convergence time, 95% CI (Student t)", fontsize=10)
    if ref is not None:
        b.errorbar(
            [ref.study_robots],
            [ref.mean],
            yerr=[[ref.mean - ref.ci95_low], [ref.ci95_high - ref.mean]],
            fmt="D",
            capsize=4,
            color=_COLOURS[1],
            label=f"published (N = {ref.study_robots})",
        )
        b.axhspan(
            ref.sizes_mean_min,
            ref.sizes_mean_max,
            color=_COLOURS[1],
            alpha=0.08,
            label=f"published range over {ref.group_sizes}",
        )
        b.legend(fontsize=8)
    for ax in (a, b):
        ax.set_xlabel("group size N (robots)")
        ax.set_ylabel("convergence time (ticks)")
    placed, unplaced, empty = _counts(s0["rules"])
    c.plot(n, [s["mean_localized"] for s in stats], "o-", color=_COLOURS[0], label=f"{placed} (left)")
    c.set_ylabel(placed, color=_COLOURS[0])
    right = c.twinx()
    for key, label, colour in (
        ("mean_unlocalized", f"{unplaced} (right)", _COLOURS[1]),
        ("mean_empty_patches", f"{empty} (right)", _COLOURS[3]),
    ):
        right.plot(n, [s[key] for s in stats], "s--", color=colour, label=label)
    right.set_ylabel(f"{unplaced}, {empty}")
    right.set_ylim(bottom=0)
    handles = c.get_legend_handles_labels()[0] + right.get_legend_handles_labels()[0]
    c.legend(handles=handles, fontsize=8, loc="upper center")
    c.set_title("(c) completeness (means over the runs)", fontsize=10)
    c.set_xlabel("group size N (robots)")
    for k, s in enumerate(stats):
        first = min((r for r in rows if r["robots"] == s["robots"]), key=lambda r: r["repetition"])
        h = _curve(first, out)
        d.plot(
            h[:, 0],
            h[:, 1],
            drawstyle="steps-post",
            color=_COLOURS[k % len(_COLOURS)],
            lw=1.2,
            label=f"N = {s['robots']}: {first['outcome']} at {first['convergence_tick']}",
        )
    d.set_yscale("symlog", linthresh=1)
    d.set_ylim(bottom=0)
    d.set_title(f"(d) one run per group size: {empty}", fontsize=10)
    d.set_xlabel("tick")
    d.set_ylabel(empty)
    d.legend(fontsize=7)
    labels = tick_labels(n, keep=patches)
    for ax in (a, b, c):
        ax.set_xticks(n, labels)
        ax.tick_params(axis="x", labelrotation=45 if sum(map(bool, labels)) > 6 else 0)
    for ax in (a, b, c):
        ax.axvline(patches, color="#999999", lw=0.8, ls=":")
        ax.grid(alpha=0.3)
    d.grid(alpha=0.3)
    fig.tight_layout()
    _save(fig, path)


def tick_labels(ticks: np.ndarray, keep: int | None = None, share: float = 0.08) -> list[str]:
    """Labels for x ticks: a tick closer than ``share`` of the axis span to a labelled one gets none.

    Group sizes next to the patch count (1035, 1036) would otherwise print on top of each
    other. ``keep`` (the patch count, marked by a line) is always labelled.
    """
    ticks = np.asarray(ticks)
    span = float(ticks.max() - ticks.min()) if ticks.size else 0.0
    gap = share * span
    chosen: list[float] = [float(keep)] if keep is not None and keep in ticks else []
    for t in sorted(ticks.tolist()):
        if all(abs(t - c) >= gap for c in chosen) or gap == 0:
            chosen.append(float(t))
    return [f"{t:g}" if float(t) in chosen else "" for t in ticks.tolist()]


def all_shapes_figure(stats: list[dict], vision: float, rules: str, path: Path) -> None:
    """Mean convergence time with 95% CI against group size relative to the patch count, every shape."""
    fig, ax = plt.subplots(figsize=(9, 5.5), dpi=110)
    shapes = sorted({s["shape"] for s in stats})
    for k, shape in enumerate(shapes):
        ss = [s for s in stats if s["shape"] == shape]
        x = np.array([s["robots"] - s["shape_patches"] for s in ss])
        m = np.array([s["mean_convergence_tick"] for s in ss])
        err = np.nan_to_num(np.vstack([m - [s["ci95_low"] for s in ss], [s["ci95_high"] for s in ss] - m]))
        ax.errorbar(
            x,
            m,
            yerr=err,
            fmt="o-",
            capsize=3,
            color=_COLOURS[k % len(_COLOURS)],
            label=f"{shape} ({ss[0]['shape_patches']} {_cells(rules)})",
        )
    ax.axvline(0, color="#999999", lw=0.8, ls=":")
    ax.set_title(f"Mean convergence time, 95% CI, {_setting(rules, vision)}", fontsize=11)
    ax.set_xlabel("group size minus the shape's patch count (robots)")
    ax.set_ylabel("convergence time (ticks)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    _save(fig, path)


def vision_figure(stats: list[dict], path: Path) -> None:
    """At each shape's exact patch count: convergence time and localized fraction against vision radius,
    one column per rule set."""
    rules = _rules_order(stats)
    fig, axes = plt.subplots(2, len(rules), figsize=(5.2 * len(rules), 8.4), dpi=110, squeeze=False, sharey="row")
    exact = [s for s in stats if s["robots"] == s["shape_patches"]]
    for col, label in enumerate(rules):
        a, b = axes[0, col], axes[1, col]
        mine = [s for s in exact if s["rules"] == label]
        for k, shape in enumerate(sorted({s["shape"] for s in mine})):
            ss = sorted((s for s in mine if s["shape"] == shape), key=lambda s: s["vision_radius"])
            v = [s["vision_radius"] for s in ss]
            m = np.array([s["mean_convergence_tick"] for s in ss])
            low = np.maximum([s["ci95_low"] for s in ss], 1.0)  # a CI reaching below one tick ends at 1 (log axis)
            err = np.nan_to_num(np.vstack([m - low, [s["ci95_high"] for s in ss] - m]))
            colour = _COLOURS[k % len(_COLOURS)]
            a.errorbar(v, m, yerr=err, fmt="o-", capsize=3, color=colour, label=shape)
            b.plot(v, [s["mean_localized"] / s["shape_patches"] for s in ss], "o-", color=colour, label=shape)
        a.set_title(f"rules {label}: mean convergence time, 95% CI", fontsize=10)
        b.set_title(f"rules {label}: shape patches filled", fontsize=10)
        a.set_yscale("log")
        b.set_ylim(0, 1.05)
        for ax in (a, b):
            ax.set_xlabel("vision radius (patches)")
            ax.grid(alpha=0.3)
            ax.legend(fontsize=8)
    axes[0, 0].set_ylabel("convergence time (ticks), N = patch count")
    axes[1, 0].set_ylabel("mean localized / patches")
    fig.tight_layout()
    _save(fig, path)


def study_figure(stats: list[dict], reference: dict[str, Reference], path: Path) -> None:
    """Our mean time / the published mean at each shape's patch count, per rule set and vision radius."""
    exact = [s for s in stats if s["robots"] == s["shape_patches"] and s["shape"] in reference]
    shapes = [name for name in reference if any(s["shape"] == name for s in exact)]
    series = _sections(exact)
    rule_sets = _rules_order(exact)
    visions = sorted({v for _, v in series})
    fig, ax = plt.subplots(figsize=(9.5, 5.2), dpi=110)
    width = 0.8 / max(len(series), 1)
    for k, (rules, vision) in enumerate(series):
        colour = _COLOURS[rule_sets.index(rules) % len(_COLOURS)]
        marker = "os^Dv<>"[visions.index(vision) % 7]
        xs, ys, lo, hi = [], [], [], []
        for j, name in enumerate(shapes):
            s = next(
                (s for s in exact if s["shape"] == name and s["rules"] == rules and s["vision_radius"] == vision), None
            )
            if s is None:
                continue
            m = reference[name].mean
            xs.append(j - 0.4 + width * (k + 0.5))
            ys.append(s["mean_convergence_tick"] / m)
            lo.append(np.nan_to_num(s["mean_convergence_tick"] - s["ci95_low"]) / m)
            hi.append(np.nan_to_num(s["ci95_high"] - s["mean_convergence_tick"]) / m)
        ax.errorbar(
            xs, ys, yerr=[lo, hi], fmt=marker, capsize=2, ls="none", color=colour, label=f"{rules}, vision {vision:g}"
        )
    for j, name in enumerate(shapes):  # the published CI, relative to its mean
        ref = reference[name]
        ax.fill_between(
            [j - 0.45, j + 0.45], ref.ci95_low / ref.mean, ref.ci95_high / ref.mean, color="#999999", alpha=0.2, lw=0
        )
    ax.axhline(1.0, color="#333333", lw=0.8)
    ax.set_yscale("log")
    ax.set_xticks(range(len(shapes)), [f"{n}\n({reference[n].study_robots})" for n in shapes])
    ax.set_ylabel("our mean time / published mean time")
    ax.set_title(
        "Convergence time at each shape's patch count against the published one (grey: published 95% CI)", fontsize=10
    )
    ax.grid(alpha=0.3, axis="y")
    ax.legend(fontsize=7, ncol=3)
    fig.tight_layout()
    _save(fig, path)


def _safe(label: str, vision: float) -> str:
    """A rule set label and vision radius as a file-name part (``paper_v1``; ``rubenstein``, which has no radius)."""
    return label if is_algorithm_label(label) else f"{label.replace('=', '-')}_v{vision:g}"


def all_figures(stats: list[dict], rows: list[dict], reference: dict, figures: Path, out: Path) -> list[Path]:
    """Every figure of the report of the experiment in ``out``, into ``figures``; return their paths."""
    written = []
    for rules, vision in _sections(stats):
        vs = [s for s in stats if s["vision_radius"] == vision and s["rules"] == rules]
        for shape in sorted({s["shape"] for s in vs}):
            path = figures / f"{shape}_{_safe(rules, vision)}.png"
            shape_figure(
                [s for s in vs if s["shape"] == shape],
                [r for r in rows if r["shape"] == shape and r["vision_radius"] == vision and rules_label(r) == rules],
                path,
                out,
                reference.get(shape) if not is_algorithm_label(rules) else None,  # the study's numbers: its model's
            )
            written.append(path)
        path = figures / f"all_shapes_{_safe(rules, vision)}.png"
        all_shapes_figure(vs, vision, rules, path)
        written.append(path)
    if any(is_algorithm_label(s["rules"]) for s in stats) and len({s["rules"] for s in stats}) > 1:
        _save(algorithms_figure(stats), figures / "algorithms.png")
        written.append(figures / "algorithms.png")
    if len({s["vision_radius"] for s in stats}) > 1:
        vision_figure(stats, figures / "vision.png")
        written.append(figures / "vision.png")
    studied = [s for s in stats if not is_algorithm_label(s["rules"])]
    if any(s["shape"] in reference and s["robots"] == s["shape_patches"] for s in studied):
        study_figure(studied, reference, figures / "study.png")
        written.append(figures / "study.png")
    return written


def _write_text(path: Path, text: str) -> None:
    part = path.with_name(f".{path.name}.tmp")
    part.write_text(text, encoding="utf-8")
    os.replace(part, path)


def build_report(out: Path) -> list[Path]:
    """(Re)build stats.csv, stats.md and figures/ in ``out`` from ``out``/results.csv (and ``out``/reference.csv,
    if present); return what was written.

    Raises:
        ExperimentError: no results file, or it holds no runs.
        ReferenceFileError: a reference file that is malformed.
    """
    results = out / RESULTS_FILE
    if not results.is_file():
        raise ExperimentError(f"{out}: no {RESULTS_FILE} here; is it an experiment directory?")
    final = out / FIGURES
    if final.is_symlink() or (final.exists() and not final.is_dir()):
        raise ExperimentError(f"{final}: not a directory; the report replaces only a {FIGURES}/ of its own pictures")
    if final.is_dir() and any(not (p.is_file() and p.suffix == ".png") for p in final.iterdir()):
        raise ExperimentError(
            f"{final}: holds more than the report's pictures (.png); the report replaces only a {FIGURES}/ of its own"
        )
    rows = read_results(results)
    if not rows:
        raise ExperimentError(f"{results}: holds no finished runs yet")
    reference = load_reference(out / REFERENCE_FILE) if (out / REFERENCE_FILE).is_file() else {}
    stats = group_stats(rows)
    texts = {out / STATS_CSV: stats_csv(stats), out / STATS_MD: stats_markdown(stats, reference)}
    # Everything is made before anything is written: the figures re-run the runs without a stored curve and check
    # them against their rows, and a row they refuse must leave the old report (or none) as it was. figures/ is
    # built whole under a hidden name and swapped in: an interrupt leaves the old set (or none).
    figures = Path(tempfile.mkdtemp(prefix=f".{FIGURES}.tmp-", dir=out))
    try:
        drawn = [final / p.name for p in all_figures(stats, rows, reference, figures, out)]
        public_mode(figures, directory=True)
        for path, text in texts.items():
            _write_text(path, text)
        old = Path(tempfile.mkdtemp(prefix=f".{FIGURES}.old-", dir=out))
        if final.exists():
            final.rename(old / FIGURES)
        figures.rename(final)
        shutil.rmtree(old, ignore_errors=True)
    finally:
        shutil.rmtree(figures, ignore_errors=True)
    return [*texts, *drawn]
