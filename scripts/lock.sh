#!/usr/bin/env bash
# Re-resolve the project's dependencies and write them, exactly pinned, to constraints.txt
# (pip's "repeatable installs": a fresh venv, pyproject.toml's dependencies with the
# extras dev and ros resolved by pip, then `pip freeze`). scripts/setup.sh installs with
# `-c constraints.txt`, so a new release on PyPI cannot move a regression reference
# (tests/data/results_reference.json) until this script is run and the references are
# regenerated (docs/reference/environment.md, "Pinned dependencies").
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$here"
PY="${PYTHON:-python3}"
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
"$PY" -m venv "$tmp/venv"
"$tmp/venv/bin/python" -m pip install --quiet --upgrade pip 2>&1 | grep -v "^WARNING: Location" || true
"$tmp/venv/bin/python" -m pip install --quiet ".[dev,ros]" 2>&1 | grep -v "^WARNING: Location" || true
{
  echo "# Exact versions of every distribution scripts/setup.sh installs (pip constraints)."
  echo "# Written by scripts/lock.sh on $(date -u +%Y-%m-%d) with $("$tmp/venv/bin/python" --version); do not edit by hand."
  "$tmp/venv/bin/python" -m pip freeze --exclude fahv --exclude pip --exclude setuptools --exclude wheel
} > constraints.txt.new
mv constraints.txt.new constraints.txt
echo "[lock] constraints.txt: $(grep -vc '^#' constraints.txt) distributions pinned"
