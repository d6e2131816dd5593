"""The code passes the project's linter and formatter (ruff, configured in pyproject.toml): imports in order, no
unused names, no likely bugs, one layout. Run ``.venv/bin/ruff check --fix . && .venv/bin/ruff format .`` to fix
most of what they find. No tracked file links to or cites the project's private inputs (the behaviour-contract
folder beside the repository and its notes): the repository stands on its own."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.process

ROOT = Path(__file__).resolve().parents[1]


def test_ruff_finds_nothing():
    ruff = shutil.which("ruff", path=str(Path(sys.executable).parent))
    assert ruff, "ruff is not installed in this venv (requirements.txt pins it; scripts/setup.sh installs it)"
    done = subprocess.run(
        [ruff, "check", "--output-format", "concise", "--no-cache", "."],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 0, done.stdout + done.stderr


def test_the_code_is_laid_out_as_ruff_format_lays_it_out():
    ruff = shutil.which("ruff", path=str(Path(sys.executable).parent))
    assert ruff, "ruff is not installed in this venv (requirements.txt pins it; scripts/setup.sh installs it)"
    done = subprocess.run(
        [ruff, "format", "--check", "--no-cache", "."], cwd=ROOT, capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, "run .venv/bin/ruff format .\n" + done.stdout + done.stderr


def test_the_pre_commit_hooks_pass_on_the_whole_tree(tmp_path):
    """.pre-commit-config.yaml's hooks (ruff, its formatter, the docs' tables, the layers, mypy), run as
    ``pre-commit run --all-files`` runs them before a commit: the configuration works, offline, with the venv's
    own tools."""
    if not (ROOT / ".git").exists():
        pytest.skip("not a git checkout: pre-commit runs on a repository's files")
    pre_commit = shutil.which("pre-commit", path=str(Path(sys.executable).parent))
    assert pre_commit, "pre-commit is not installed in this venv (requirements.txt pins it)"
    env = {
        "PATH": str(Path(sys.executable).parent) + ":/usr/bin:/bin",
        "HOME": str(tmp_path),
        "PRE_COMMIT_HOME": str(tmp_path / "pre-commit"),
        "SKIP": "mypy",  # 16 s cold: test_mypy_finds_nothing_in_the_layers_it_checks runs it
    }
    done = subprocess.run(
        [pre_commit, "run", "--all-files", "--show-diff-on-failure"],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    assert done.stdout.count("Passed") == 4 and done.stdout.count("Skipped") == 1, done.stdout  # every hook ran


def test_the_mypy_hook_runs_what_the_mypy_test_runs():
    """The pre-commit test skips the mypy hook (16 s cold): the hook is the command the next test runs."""
    import yaml

    hooks = {
        h["id"]: h
        for repo in yaml.safe_load((ROOT / ".pre-commit-config.yaml").read_text())["repos"]
        for h in repo["hooks"]
    }
    assert hooks["mypy"]["entry"] == ".venv/bin/mypy" and hooks["mypy"]["pass_filenames"] is False


def test_mypy_finds_nothing_in_the_layers_it_checks():
    """The type checker over every layer (pyproject.toml's [tool.mypy]): the model's code, the contract between
    processes, the run's files, the ROS adapters, the nodes and the app as their annotations say. No cache is
    written."""
    mypy = shutil.which("mypy", path=str(Path(sys.executable).parent))
    assert mypy, "mypy is not installed in this venv (requirements.txt pins it; scripts/setup.sh installs it)"
    done = subprocess.run(
        [mypy, "--cache-dir", "/dev/null", "--python-executable", sys.executable],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stdout + done.stderr


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
