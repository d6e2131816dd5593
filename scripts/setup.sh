#!/usr/bin/env bash
# Set up (or refresh) the project's virtual environment in .venv: pinned dependencies
# from requirements.txt and swarm_ros itself in editable mode; and colcon in .venv-colcon. Safe to run again.
set -euo pipefail
cd "$(dirname "$0")/.."

PYTHON="${PYTHON:-python3.11}"
command -v "$PYTHON" >/dev/null 2>&1 || PYTHON=python3
"$PYTHON" -c 'import sys; sys.exit(0 if sys.version_info >= (3, 11) else 1)' \
  || { echo "setup: Python >= 3.11 is needed (found $("$PYTHON" --version 2>&1))" >&2; exit 2; }

if [ ! -x .venv/bin/python ]; then
  "$PYTHON" -m venv .venv
fi
stamp=.venv/.swarm_ros-installed
if [ ! -f "$stamp" ] || [ requirements.txt -nt "$stamp" ] || [ setup.py -nt "$stamp" ]; then
  # A pip new enough for PEP 660 editable installs (the one venv bundles is not).
  .venv/bin/python -m pip install --quiet --disable-pip-version-check pip==26.3
  .venv/bin/python -m pip install --quiet --disable-pip-version-check -r requirements.txt
  .venv/bin/python -m pip install --quiet --disable-pip-version-check --no-deps --no-build-isolation -e .
  touch "$stamp"
fi
# The package's own bytecode: the environment may set PYTHONDONTWRITEBYTECODE, and then every node process
# would compile swarm_ros from source as it starts (about 0.15 s of CPU each).
.venv/bin/python -m compileall -q swarm_ros
# colcon, for the test that builds the package as a ROS 2 workspace. Its own venv: colcon-core pulls in
# pytest plugins that must not load into the project's tests (requirements-colcon.txt pins it all). It is
# installed while the kernels compile (below).
colcon_venv() {
  local cstamp=.venv-colcon/.installed
  if [ ! -f "$cstamp" ] || [ requirements-colcon.txt -nt "$cstamp" ]; then
    "$PYTHON" -m venv .venv-colcon
    .venv-colcon/bin/python -m pip install --quiet --disable-pip-version-check pip==26.3
    .venv-colcon/bin/python -m pip install --quiet --disable-pip-version-check -r requirements-colcon.txt
    touch "$cstamp"
  fi
}
colcon_venv &
colcon_pid=$!
# numba's cache of each algorithm's kernels (nothing to do when it is full), one process each, side by side on
# the two cores, so the first run does not compile them (scripts/bench_compile.py: about 40 s and 17 s alone)
.venv/bin/python -m swarm_ros.core.kernels darr-niazi &
study_pid=$!
.venv/bin/python -m swarm_ros.core.kernels rubenstein &
rubenstein_pid=$!
failed=0
wait "$study_pid" || failed=1
wait "$rubenstein_pid" || failed=1
wait "$colcon_pid" || { echo "setup: could not install colcon into .venv-colcon" >&2; exit 1; }
if [ "$failed" != 0 ]; then
  echo "setup: compiling the numba kernels failed" >&2
  exit 1
fi
