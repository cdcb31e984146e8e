#!/usr/bin/env bash
# Soak of the node on its default scene (the phantom), as launched (launch/liver_sim.launch),
# pinned to core 0, with scripts/soak.py on core 1: scripts/soak.sh [SECONDS] (default 600).
# Build first (scripts/run.sh or scripts/test.sh). Writes build/soak.json.
source "$(dirname "$0")/ros_env.sh" 11497
roscore -p 11497 >/dev/null 2>&1 & MASTER=$!
sleep 3
taskset -c 0 roslaunch -p 11497 liver_sim liver_sim.launch >"$REPO/build/soak_node.log" 2>&1 & NODE=$!
trap 'kill $NODE 2>/dev/null; sleep 2; kill $MASTER 2>/dev/null' EXIT
taskset -c 1 "$REPO/scripts/soak.py" --duration "${1:-600}" --json "$REPO/build/soak.json"
