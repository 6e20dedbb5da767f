#!/usr/bin/env bash
# Install everything (scripts/setup.sh), then run the linters, the test suite and the
# strict build of the documentation site; the site builds beside the workspace build and
# the tests (its output follows theirs) and a failure of either fails the script.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$here"
bash scripts/setup.sh --venv-only
docs_log="$(mktemp)"
trap 'rm -f "$docs_log"' EXIT
# the documentation site (site/), strict, beside the workspace build, the linters and the
# tests (the venv is all it needs)
bash scripts/docs.sh > "$docs_log" 2>&1 &
docs=$!
bash scripts/setup.sh
.venv/bin/ruff check src tests benchmarks ros_ws/src
# layer contracts of pyproject.toml; the ROS packages are analysed from their sources
PYTHONPATH="$(printf '%s:' "$here"/ros_ws/src/hsv_*)" .venv/bin/lint-imports
# on every core, one test file per worker at a time (module fixtures computed once);
# "-n 0" after the command runs the suite in one process
tests=0
.venv/bin/python -m pytest -n auto --dist loadfile "$@" || tests=$?
site=0
wait "$docs" || site=$?
echo "[docs] $(tail -n 1 "$docs_log")"
if [ "$site" -ne 0 ]; then
  cat "$docs_log" >&2
  echo "[docs] error: the documentation site does not build (strict), above" >&2
fi
[ "$tests" -eq 0 ] && [ "$site" -eq 0 ]
