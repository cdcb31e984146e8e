#!/usr/bin/env bash
# Starts a ROS master and the node as launched (launch/liver_sim.launch, the liver phantom,
# publish_rate 30), the node pinned to one core, and measures it under a probe driven at 30 Hz
# with scripts/measure_contact_node.py. Build first (scripts/run.sh).
#   scripts/measure_contact_node.sh [SECONDS] [--clouds]   (default 20 s; --clouds: camera clouds registered meanwhile)
source "$(dirname "$0")/ros_env.sh"
roscore -p "$PORT" >/dev/null 2>&1 & MASTER=$!
sleep 3
taskset -c 0 roslaunch liver_sim liver_sim.launch publish_rate:=30 >/dev/null 2>&1 & LAUNCH=$!
trap 'kill $LAUNCH 2>/dev/null; wait $LAUNCH 2>/dev/null; kill $MASTER 2>/dev/null' EXIT
"$REPO/scripts/measure_contact_node.py" "$@"
