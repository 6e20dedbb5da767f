#!/usr/bin/env bash
# Install everything (scripts/setup.sh), then run the linters, the test suite and the
# strict build of the documentation site. The site and the ROS 2 workspace build beside
# the linters and the tests (their output follows the tests'); a failure of any fails
# the script.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$here"
# Debian's Chromium for the report pages' browser test (tests/conftest.py), beside the
# venv's installation; the test names what is missing if this fails
browser_log="$(mktemp)"
{
  command -v chromium || { apt-get update -qq && apt-get install -y -qq --no-install-recommends chromium; }
} > "$browser_log" 2>&1 &
browser=$!
bash scripts/setup.sh --venv-only
if ! wait "$browser"; then
  echo "[browser] warning: Chromium did not install (the browser test will fail):" >&2
  tail -n 5 "$browser_log" >&2
fi
rm -f "$browser_log"
docs_log="$(mktemp)"
trap 'rm -f "$docs_log"' EXIT
# the documentation site (site/), strict, beside the workspace build, the linters and the
# tests (the venv is all it needs)
bash scripts/docs.sh > "$docs_log" 2>&1 &
docs=$!
# every shipped design verified (`fahv verify` records the pass its runs reuse) and one
# second of Case 1 simulated, beside the workspace build: the test workers then find the
# verdicts and the compiled kernels (numba's disk cache) instead of each making them
warm_log="$(mktemp)"
trap 'rm -f "$docs_log" "$warm_log"' EXIT
{
  for design in offline_design/designs/*.yaml; do .venv/bin/fahv verify "$design"; done
  .venv/bin/fahv simulate offline_design/scenarios/case1.yaml --duration 1 --no-record
} > "$warm_log" 2>&1 &
warm=$!
# the ROS 2 workspace and the live test's client (scripts/setup.sh) beside the linters and
# the tests: a test marked `ros` waits until the build has ended (tests/conftest.py reads
# its exit status from the file FAHV_ROS_BUILD names, written once it is known)
build_log="$(mktemp)"
build_status="$(mktemp -u)"
trap 'rm -f "$docs_log" "$warm_log" "$build_log" "$build_status"' EXIT
{
  if bash scripts/setup.sh > "$build_log" 2>&1; then rc=0; else rc=$?; fi
  echo "$rc" > "$build_status.part" && mv "$build_status.part" "$build_status"
} &
build=$!
export FAHV_ROS_BUILD="$build_status" FAHV_ROS_BUILD_LOG="$build_log"
.venv/bin/ruff check src tests benchmarks ros_ws/src
# layer contracts of pyproject.toml; the ROS packages are analysed from their sources
PYTHONPATH="$(printf '%s:' "$here"/ros_ws/src/hsv_*)" .venv/bin/lint-imports
if ! wait "$warm"; then
  cat "$warm_log" >&2
  echo "[verify] error: a shipped design does not verify, or Case 1 does not run (above)" >&2
  exit 1
fi
grep -E "^(design|verified)" "$warm_log" | sed 's/^/[verify] /'
# on every core, one test file per worker at a time (module fixtures computed once);
# "-n 0" after the command runs the suite in one process
tests=0
.venv/bin/python -m pytest -n auto --dist loadfile "$@" || tests=$?
wait "$build" || true
sed 's/^/[build] /' "$build_log"
if [ "$(cat "$build_status" 2>/dev/null)" != "0" ]; then
  echo "[build] error: scripts/setup.sh failed (above)" >&2
  tests=1
fi
site=0
wait "$docs" || site=$?
echo "[docs] $(tail -n 1 "$docs_log")"
if [ "$site" -ne 0 ]; then
  cat "$docs_log" >&2
  echo "[docs] error: the documentation site does not build (strict), above" >&2
fi
[ "$tests" -eq 0 ] && [ "$site" -eq 0 ]
