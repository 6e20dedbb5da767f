#!/usr/bin/env bash
# Build the ROS 2 workspace (ros_ws/) with colcon from the ROS 2 Jazzy wheels in .venv
# (docs/reference/environment.md). Idempotent: colcon rebuilds only what changed. Needs scripts/setup.sh.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$here/ros_ws"
venv="$here/.venv"
export PATH="$venv/bin:$PATH"
export AMENT_PREFIX_PATH="$venv${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}"
export CMAKE_PREFIX_PATH="$venv${CMAKE_PREFIX_PATH:+:$CMAKE_PREFIX_PATH}"
export PYTHON_EXECUTABLE="$venv/bin/python"
# Filtered out: setuptools' notes that byte-compiling is off (colcon's choice) and colcon's
# warning that the venv on AMENT_PREFIX_PATH is not a colcon prefix (it is the wheels' prefix).
colcon build --event-handlers console_cohesion- summary+ \
  --cmake-args -DPython3_EXECUTABLE="$venv/bin/python" -DBUILD_TESTING=OFF \
  2>&1 | grep -v -E "byte-compiling is disabled|^---$|^--- stderr|^$|had stderr output|doesn't contain any 'local_setup\.\*' files" \
  | tail -n 30
test -f install/setup.bash || { echo "[build_ros] error: ros_ws/install/setup.bash missing" >&2; exit 1; }
"$venv/bin/python" -c "from fahv.sil.workspace import write_build_stamp; write_build_stamp()"
echo "[build_ros] ros_ws built ($(ls install | grep -c hsv_) hsv packages)"
