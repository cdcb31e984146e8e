#!/usr/bin/env bash
# Starts a ROS master and liver_sim_node on the liver phantom, pinned to one core, and measures
# registration in the node with scripts/measure_registration.py: clouds of a moving surface at
# 15 Hz (about 6,000 and 90,000 points), registered clouds per second, cloud-to-mesh latency, and a 1M-point cloud's filter
# time. Build first (scripts/run.sh). usage: scripts/measure_registration.sh [SECONDS] [NODE ARGUMENTS]
# (e.g. _registration/estimate_hidden_loads:=false)
source "$(dirname "$0")/ros_env.sh"
roscore -p "$PORT" >/dev/null 2>&1 & MASTER=$!
sleep 3
taskset -c 0 "$REPO/build/ws/devel/lib/liver_sim/liver_sim_node" "${@:2}" >/dev/null 2>&1 & NODE=$!
trap 'kill $NODE $MASTER 2>/dev/null' EXIT
taskset -c 1 "$REPO/scripts/measure_registration.py" "${1:-30}"
