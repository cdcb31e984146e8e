#!/usr/bin/env bash
# Soak of the node on its default scene (the phantom), as launched (launch/liver_sim.launch),
# pinned to core 0, with scripts/soak.py on core 1: scripts/soak.sh [SECONDS] (default 600).
# Build first (scripts/run.sh or scripts/test.sh). Writes build/soak.json.
set -euo pipefail
REPO=$(cd "$(dirname "$0")/.." && pwd)
export PATH="/usr/bin:/bin:$PATH" ROS_IP=127.0.0.1 ROS_MASTER_URI=http://127.0.0.1:11497
export ROS_HOME="$REPO/build/ws/ros_home"
set +u; source "$REPO/build/ws/devel/setup.bash"; set -u
roscore -p 11497 >/dev/null 2>&1 & MASTER=$!
sleep 3
taskset -c 0 roslaunch -p 11497 liver_sim liver_sim.launch >"$REPO/build/soak_node.log" 2>&1 & NODE=$!
trap 'kill $NODE 2>/dev/null; sleep 2; kill $MASTER 2>/dev/null' EXIT
taskset -c 1 "$REPO/scripts/soak.py" --duration "${1:-600}" --json "$REPO/build/soak.json"
