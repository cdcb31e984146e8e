#!/usr/bin/env bash
# Starts a ROS master and liver_sim_node on the aspiration cube, pinned to one core, and measures
# idle CPU and pose-to-mesh latency with scripts/measure_node.py. Build first (scripts/run.sh).
set -euo pipefail
REPO=$(cd "$(dirname "$0")/.." && pwd)
export PATH="/usr/bin:/bin:$PATH" ROS_IP=127.0.0.1 ROS_MASTER_URI=http://127.0.0.1:11498
export ROS_HOME="$REPO/build/ws/ros_home"
set +u; source "$REPO/build/ws/devel/setup.bash"; set -u
roscore -p 11498 >/dev/null 2>&1 & MASTER=$!
sleep 3
taskset -c 0 "$REPO/build/ws/devel/lib/liver_sim/liver_sim_node" _scene:="$REPO/config/scenes/aspiration_cube.yaml" >/dev/null 2>&1 & NODE=$!
trap 'kill $NODE $MASTER 2>/dev/null' EXIT
"$REPO/scripts/measure_node.py" "$NODE"
