"""The repository stands on its own: no file links to or cites the project's private inputs
(the behaviour-contract folder beside the repository and its notes), and the model page states
the whole model."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest

pytestmark = pytest.mark.unit

ROOT = Path(__file__).resolve().parents[1]
USAGE = ROOT / "docs" / "usage.md"  # the reference of every command
# Built from pieces so that this file does not match itself.
FORBIDDEN = ("../" + "shared", "ROS2" + "_NOTES", "MODEL" + ".md", "STYLE" + ".md")


def tracked_text_files() -> list[Path]:
    try:
        names = (
            subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True, timeout=60)
            .stdout.decode()
            .split("\0")
        )
        files = [ROOT / n for n in names if n]
    except (OSError, subprocess.CalledProcessError):  # not a git checkout: every file but the venv's
        files = [p for p in ROOT.rglob("*") if p.is_file() and ".venv" not in p.parts and ".git" not in p.parts]
    out = []
    for path in files:
        data = path.read_bytes() if path.is_file() else b""
        if b"\0" not in data[:4096]:
            out.append(path)
    return out


def test_no_file_links_to_or_cites_the_private_inputs():
    files = tracked_text_files()
    assert len(files) > 50  # the listing found the repository
    hits = [
        f"{p.relative_to(ROOT)}:{n}: {line.strip()[:100]}"
        for p in files
        for n, line in enumerate(p.read_text(errors="replace").splitlines(), start=1)
        if any(word in line for word in FORBIDDEN)
    ]
    assert not hits, "\n".join(hits)


def test_the_model_page_states_the_whole_model():
    text = (ROOT / "docs" / "model.md").read_text()
    for heading in (
        "## World",
        "## Robots",
        "## Rule sets",
        "## Ticks and determinism",
        "## Termination",
        "## Metrics",
        "## Formal specification",
        "## Experiment protocol",
    ):
        assert f"\n{heading}" in text, heading
    for word in ("`paper`", "`local`", "`literal`", "`walk`", "`ahead`", "`disc`", "`one`"):
        assert word in text, word


def test_the_usage_page_lists_every_summary_field():
    """The usage page's summary.json row names each field a run writes (losses and restarts included)."""
    import re

    from swarm_ros.core import RunParams, Shape, Simulation, World
    from swarm_ros.core.run_result import summary_of

    sim = Simulation(Shape.load("rectangle", World()), RunParams(robots=442, max_ticks=3))
    sim.run()
    fields = set(summary_of(sim, wall_seconds=0.0))
    row = next(ln for ln in USAGE.read_text().splitlines() if ln.startswith("| `summary.json` |"))
    listed = set(re.findall(r"\b[a-z][a-z0-9]*(?:_[a-z0-9]+)+\b|\b[a-z]+\b", row.split("|")[2]))
    assert fields <= listed, sorted(fields - listed)
    assert "restarts" in fields and "losses" in fields


def test_generated_output_directories_are_ignored_by_git():
    ignored = (ROOT / ".gitignore").read_text().split()
    assert "runs/" in ignored and "experiments/" in ignored


def test_the_usage_synopses_name_every_flag_of_simulate_and_run():
    import re

    from swarm_ros.app.cli import build_parser

    readme = USAGE.read_text()
    subparsers = next(a for a in build_parser()._actions if a.__class__.__name__ == "_SubParsersAction")
    for command in ("simulate", "run"):
        synopsis = re.search(rf"```\nswarm-ros {command} (.*?)```", readme, re.S).group(1)
        if command == "run":  # '... the same options as simulate, except --check'
            synopsis += re.search(r"```\nswarm-ros simulate (.*?)```", readme, re.S).group(1)
        flags = {
            f
            for a in subparsers.choices[command]._actions
            for f in a.option_strings
            if f.startswith("--") and f != "--help"
        }
        missing = sorted(f for f in flags if f not in synopsis)
        assert not missing, f"the usage page's synopsis of {command} omits {missing}"


_LINK = re.compile(r"\]\(([^)\s#]+)(?:#[^)]*)?\)")  # a markdown link's target, without its anchor
#: a repository path in backticks: a file with its extension, or a folder with its slash (`swarm_ros/world`, a
#: status name, is neither)
_NAMED = re.compile(r"`((?:config|scripts|shapes|docs|launch|test|swarm_ros|rviz)/[\w./-]*(?:\.\w+|/))`")


def _docs() -> list[Path]:
    return [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]


@pytest.mark.parametrize("page", _docs(), ids=lambda p: p.name)
def test_every_file_a_page_links_to_or_names_exists(page):
    """A relative link resolves from the page; a repository path in backticks (``config/experiments/x.yaml``)
    exists in the repository (a path with a placeholder, ``<run>``, is not one)."""
    text = page.read_text(encoding="utf-8")
    missing = [
        t
        for t in _LINK.findall(text)
        if "://" not in t and not t.startswith("mailto:") and not (page.parent / t).exists()
    ]
    missing += [t for t in _NAMED.findall(text) if not (ROOT / t.rstrip(".")).exists()]
    assert not missing, f"{page.name} names what does not exist: {missing}"


def test_every_error_line_the_docs_quote_is_a_row_the_bad_input_test_runs():
    """An error line quoted in a page (``swarm-ros: error: ...``, ``swarm_ros <node>: error: ...``) holds the
    message of a row of docs/bad_input.md, which test_bad_input.py runs: a quoted text that drifted fails here."""
    rows = [
        m.group(1)
        for m in re.finditer(
            r"^\| \d+ \| .+? \| `.+?` \| `(.+?)` \|$", (ROOT / "docs" / "bad_input.md").read_text(), re.M
        )
    ]
    quoted = [
        (page.name, line.strip())
        for page in _docs()
        if page.name != "bad_input.md"
        for line in page.read_text(encoding="utf-8").splitlines()
        if re.match(r"\s*swarm[-_]ros( \w+)?: error: ", line)
    ]
    assert quoted, "no quoted error line found: the pattern is stale"
    stray = [(name, line) for name, line in quoted if not any(row in line for row in rows)]
    assert not stray, stray


def test_the_docs_tables_of_parameters_are_the_declarations():
    """Each table between ``<!-- table: NAME -->`` markers is what scripts/docs_tables.py writes from
    swarm_ros.core.params, and every declared parameter is in one (run it to update them)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("docs_tables", ROOT / "scripts" / "docs_tables.py")
    tables = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(tables)
    from swarm_ros.core.params import NODE_PARAMETERS

    for page in tables.PAGES:
        text = page.read_text()
        assert tables.render(text) == text, f"{page.name}: a table is stale: run scripts/docs_tables.py"
    names = set(re.findall(r"<!-- table: (\w+) -->", "".join(p.read_text() for p in tables.PAGES)))
    assert names == {"run", *NODE_PARAMETERS}, names
