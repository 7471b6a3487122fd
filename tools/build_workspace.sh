#!/usr/bin/env bash
# The ROS workspace install path: `colcon build` of this package in a workspace (WS/src/feeder_ros
# links to the repository) on top of the project venv's ros-* wheels. Afterwards
# `source WS/install/local_setup.sh` gives `ros2 run`'s layout: <prefix>/lib/feeder_ros/<exe>,
# the package in the ament index, and feeder_ros.msg importable.
set -euo pipefail
repo=$(cd "$(dirname "$0")/.." && pwd)
venv=${VENV:-$repo/.venv}
ws=${1:-$repo/.work/ws}

mkdir -p "$ws/src"
ln -sfn "$repo" "$ws/src/feeder_ros"
export AMENT_PREFIX_PATH="$venv" CMAKE_PREFIX_PATH="$venv" PATH="$venv/bin:$PATH"
cd "$ws"
if ! colcon build --cmake-args -G Ninja "-DPython3_EXECUTABLE=$venv/bin/python" -DBUILD_TESTING=OFF \
    > "$ws/colcon-build.log" 2>&1; then
  tail -n 40 "$ws/colcon-build.log" >&2
  echo "colcon build failed; full log: $ws/colcon-build.log" >&2
  exit 1
fi
echo "workspace built: source $ws/install/local_setup.sh"
