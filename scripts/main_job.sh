#!/usr/bin/env bash
# Main job on a fresh machine: install everything (venv, ROS 2 wheels, colcon build of
# ros_ws), then run Case 1 through the ROS 2 node graph in lockstep on the shipped design
# (re-checked by `fahv verify` first, no synthesis), recorded to bags/<run>/ (rosbag2
# folder with one .mcap). Prints the certificate checks, the metrics table, the wall time
# and the real-time factor. Extra arguments go to `fahv sil` (e.g. --duration 60).
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$here"
bash scripts/setup.sh
.venv/bin/fahv sil offline_design/scenarios/case1.yaml "$@"
