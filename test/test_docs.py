"""The docs say what the code does: the model page states the whole model, and every page's links, names, tables
and quoted errors are the package's own (that no file cites the project's private inputs is test_lint's: it lists
the repository with git)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

pytestmark = pytest.mark.unit

ROOT = Path(__file__).resolve().parents[1]
USAGE = ROOT / "docs" / "usage.md"  # the reference of every command


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
    from swarm_ros.core.darr_niazi.run_result import summary_of

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


_LINK = re.compile(r"\]\(([^)\s#]+)(?:#[^)]*)?\)")  # a markdown link's target, without its anchor
#: a repository path in backticks: a file with its extension, or a folder with its slash (`swarm_ros/world`, a
#: status name, is neither)
_NAMED = re.compile(r"`((?:config|scripts|shapes|docs|launch|test|swarm_ros|rviz)/[\w./-]*(?:\.\w+|/))`")


def _docs() -> list[Path]:
    return [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md")), *sorted((ROOT / "docs" / "guides").glob("*.md"))]


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


# -- the reference against the code: options, nodes, topics, launch arguments -------------------------------


def _section(path: Path, heading: str) -> str:
    """The text of the section of ``path`` under the heading that starts with ``heading``, to the next heading of
    the same or a higher level."""
    lines = path.read_text().splitlines()
    start = next(i for i, ln in enumerate(lines) if ln.startswith(heading))
    level = len(heading) - len(heading.lstrip("#"))
    end = next(
        (i for i in range(start + 1, len(lines)) if re.match(rf"#{{1,{level}}} ", lines[i])),
        len(lines),
    )
    return "\n".join(lines[start:end])


GUIDE = ROOT / "docs" / "guides" / "graph.md"
#: Where each command's options are documented: (page, heading of its section).
COMMAND_SECTIONS = {
    "simulate": (USAGE, "## `swarm-ros simulate`"),
    "run": (USAGE, "## `swarm-ros run`"),
    "experiment": (USAGE, "## `swarm-ros experiment`"),
    "report": (USAGE, "## `swarm-ros experiment`"),
    "shapes": (USAGE, "## Shapes"),
    "replay": (GUIDE, "## Play a past run back: `swarm-ros replay`"),
    "topics": (GUIDE, "## Look inside a live run: `swarm-ros topics`"),
}


def test_every_option_of_every_command_is_in_its_section_of_the_docs():
    """The reference names every option the parser takes (a run section may say 'the same options as
    simulate' for those it shares)."""
    import argparse

    from swarm_ros.app.cli import build_parser

    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    assert set(sub.choices) == set(COMMAND_SECTIONS), "a command without a documented section"
    shared = {o for a in sub.choices["simulate"]._actions for o in a.option_strings}
    missing = []
    for command, parser in sub.choices.items():
        page, heading = COMMAND_SECTIONS[command]
        text = _section(page, heading)
        assert f"swarm-ros {command}" in text, (command, heading)
        for action in parser._actions:
            for option in action.option_strings:
                if not option.startswith("--") or option == "--help":
                    continue
                if command == "run" and option in shared and "the same options as simulate" in text:
                    continue
                if not re.search(rf"{re.escape(option)}(?![\w-])", text):
                    missing.append(f"{command} {option}")
    assert not missing, missing


def _node_executables() -> list[str]:
    import ast

    tree = ast.parse((ROOT / "setup.py").read_text())
    call = next(n for n in ast.walk(tree) if isinstance(n, ast.Call) and getattr(n.func, "id", "") == "setup")
    scripts = ast.literal_eval(next(k.value for k in call.keywords if k.arg == "entry_points"))["console_scripts"]
    return [s.split("=")[0].strip() for s in scripts if "swarm-ros" not in s]


def test_every_node_executable_is_in_every_list_of_the_nodes():
    """README, architecture.md, the nodes package and the build guide's `ros2 pkg executables` list them all."""
    nodes = _node_executables()
    assert set(nodes) == {"world", "world_shard", "robot_batch", "monitor"}  # one set, for every algorithm
    readme = (ROOT / "README.md").read_text()
    lists = {
        "README layout": next(ln for ln in readme.splitlines() if ln.startswith("swarm_ros/nodes/")),
        "README ros2 run": readme[readme.index("ros2 run swarm_ros") :][:160],
        "architecture.md": next(
            ln for ln in (ROOT / "docs" / "architecture.md").read_text().splitlines() if "swarm_ros/nodes/" in ln
        ),
        "nodes/__init__.py": (ROOT / "swarm_ros" / "nodes" / "__init__.py").read_text().splitlines()[0],
        "usage.md ros2 run": next(ln for ln in USAGE.read_text().splitlines() if "ros2 run swarm_ros world" in ln),
    }
    executables = _section(ROOT / "docs" / "guides" / "ros2_tools.md", "## Build")
    missing = [f"{where}: {n}" for where, text in lists.items() for n in nodes if not re.search(rf"\b{n}\b", text)]
    missing += [f"ros2 pkg executables: {n}" for n in nodes if f"`swarm_ros {n}`" not in executables]
    assert not missing, missing


def test_every_topic_is_a_row_of_the_topic_table():
    """Each topic (or topic family) swarm_ros.protocol.plan names has a row in protocol.md's table."""
    from swarm_ros.protocol import plan

    section = _section(ROOT / "docs" / "protocol.md", "## Topics")
    first_cells = [ln.split("|")[1] for ln in section.splitlines() if ln.startswith("| `/")]
    topics = [v for k, v in vars(plan).items() if k.isupper() and isinstance(v, str) and v.startswith("/")]
    assert {plan.STATUS, plan.HELD, plan.BATCHES, plan.CLOCK} <= set(topics)  # the scan finds them
    missing = [t for t in topics if not any(f"`{t}`" in cell or f"`{t}/" in cell for cell in first_cells)]
    assert not missing, missing


def test_the_launch_arguments_are_the_ones_the_guide_lists():
    """The guide's list of launch arguments is the launch file's DeclareLaunchArgument names, run parameters
    included."""
    import ast

    from swarm_ros.core.params import RUN_PARAMETERS

    tree = ast.parse((ROOT / "launch" / "swarm.launch.py").read_text())
    declared = {
        n.args[0].value
        for n in ast.walk(tree)
        if isinstance(n, ast.Call)
        and getattr(n.func, "id", "") == "DeclareLaunchArgument"
        and isinstance(n.args[0], ast.Constant)
    } | {p.name for p in RUN_PARAMETERS}
    assert {"processes", "world_shards", "region_cuts", "params_file", "out_dir", "enclaves"} <= declared
    text = _section(ROOT / "docs" / "guides" / "ros2_tools.md", "## `ros2 launch`")
    listed = text[text.index("Its launch arguments are") :].split("How they are applied")[0]
    assert set(re.findall(r"`([a-z_]+)`", listed)) == declared


def _slug(heading: str) -> str:
    """A heading's anchor, as GitHub makes it: lower case, punctuation but hyphens dropped, spaces to hyphens."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def _anchors(page: Path) -> set[str]:
    found, code = set(), False
    for line in page.read_text(encoding="utf-8").splitlines():
        if line.startswith("```"):
            code = not code
        elif not code and line.startswith("#"):
            found.add(_slug(line.lstrip("#")))
    return found


@pytest.mark.parametrize("page", _docs(), ids=lambda p: p.name)
def test_every_anchor_a_page_links_to_is_a_heading_of_its_target(page):
    """Pages moved (operations.md became the guides, bag.md and benchmarks.md): a link's #anchor must still
    name a heading of the page it points to."""
    wrong = []
    for target, anchor in re.findall(r"\]\(([^)\s#]*)#([^)\s]+)\)", page.read_text(encoding="utf-8")):
        path = page.parent / target if target else page
        if path.suffix == ".md" and path.exists() and anchor not in _anchors(path):
            wrong.append(f"{target}#{anchor}")
    assert not wrong, f"{page.name} links to anchors that are not there: {wrong}"


_DOTTED = re.compile(r"`(swarm_ros(?:\.[A-Za-z_][A-Za-z0-9_]*)+)`")
_TEXT_NAMES = {"swarm_ros.tag"}  # a message tag's prefix (protocol/rows.py TAG_PREFIX), not a module


def _resolves(dotted: str) -> bool:
    """Whether ``dotted`` is a module of the package, or a name defined in one (a class, then its attributes)."""
    import importlib

    parts = dotted.split(".")
    for cut in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:cut]))
        except ModuleNotFoundError:
            continue
        for name in parts[cut:]:
            if not hasattr(obj, name):
                return False
            obj = getattr(obj, name)
        return True
    return False


@pytest.mark.parametrize("page", _docs(), ids=lambda p: p.name)
def test_every_dotted_name_of_the_package_a_page_gives_is_defined(page):
    """A page that names code as ``swarm_ros.<module>[.<name>...]`` (the glossary, "where a tick is applied",
    "where a message's layout is defined" in architecture.md) names a module or a name the code defines: a
    rename fails here, not in a reader's search."""
    text = page.read_text(encoding="utf-8")
    missing = sorted({n for n in _DOTTED.findall(text) if n not in _TEXT_NAMES and not _resolves(n)})
    assert not missing, f"{page.name} names what the package does not define: {missing}"
