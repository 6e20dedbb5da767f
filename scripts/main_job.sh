#!/usr/bin/env bash
# Main job on a fresh machine: install everything, then run the modelling layer of
# Case 1 (trim, TP model, figures) and the tube feasibility study (W, F, Z). The ROS 2 graph run of Case 1 is added to this
# script by the SIL work (issue 4); until then this is what the project can run.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$here"
bash scripts/setup.sh
.venv/bin/fahv trim --grid 3 3
.venv/bin/fahv tp --model dm --vertices 4x5
.venv/bin/fahv figures --out docs/figures
.venv/bin/fahv tube
