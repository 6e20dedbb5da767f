#!/usr/bin/env bash
# Install everything (scripts/setup.sh) and run the test suite and the linter.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$here"
bash scripts/setup.sh
.venv/bin/ruff check src tests benchmarks ros_ws/src
# layer contracts of pyproject.toml; the ROS packages are analysed from their sources
PYTHONPATH="$(printf '%s:' "$here"/ros_ws/src/hsv_*)" .venv/bin/lint-imports
# on every core, one test file per worker at a time (module fixtures computed once);
# "-n 0" after the command runs the suite in one process
.venv/bin/python -m pytest -n auto --dist loadfile "$@"
bash scripts/docs.sh  # the documentation site, strict (site/)
