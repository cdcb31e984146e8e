#!/usr/bin/env bash
# Starts a ROS master and liver_sim_node on the aspiration cube, pinned to one core, and measures
# idle CPU and pose-to-mesh latency with scripts/measure_node.py. Build first (scripts/run.sh).
source "$(dirname "$0")/ros_env.sh"
roscore -p "$PORT" >/dev/null 2>&1 & MASTER=$!
sleep 3
taskset -c 0 "$REPO/build/ws/devel/lib/liver_sim/liver_sim_node" _scene:="$REPO/config/scenes/aspiration_cube.yaml" >/dev/null 2>&1 & NODE=$!
trap 'kill $NODE $MASTER 2>/dev/null' EXIT
"$REPO/scripts/measure_node.py" "$NODE"
