"""The code passes the project's linter (ruff, configured in pyproject.toml): imports in order, no unused names,
no likely bugs. Run ``.venv/bin/ruff check --fix .`` to fix most of what it finds."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.unit

ROOT = Path(__file__).resolve().parents[1]


def test_ruff_finds_nothing():
    ruff = shutil.which("ruff", path=str(Path(sys.executable).parent))
    assert ruff, "ruff is not installed in this venv (requirements.txt pins it; scripts/setup.sh installs it)"
    done = subprocess.run([ruff, "check", "--output-format", "concise", "--no-cache", "."], cwd=ROOT,
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stdout + done.stderr
