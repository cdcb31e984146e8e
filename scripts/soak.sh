#!/usr/bin/env bash
# Soak of the node on its default scene (the phantom), as launched (launch/liver_sim.launch),
# pinned to core 0, with scripts/soak.py on core 1: scripts/soak.sh [SECONDS] [LOAD] (default 600
# s, no load). LOAD > 0 runs that many CPU-bound workers (stress-ng --cpu) beside them on both
# cores, as a build or another program on the OR computer would. Faults are injected into every
# 40th frame (~test_fault_every). Further arguments go to roslaunch (e.g. background_refresh:=true).
# Build first (scripts/run.sh or scripts/test.sh). Writes build/soak.json.
source "$(dirname "$0")/ros_env.sh"
roscore -p "$PORT" >/dev/null 2>&1 & MASTER=$!
sleep 3
taskset -c 0 roslaunch -p "$PORT" liver_sim liver_sim.launch test_fault_every:=40 "${@:3}" >"$REPO/build/soak_node.log" 2>&1 & NODE=$!
LOAD=""
if [ "${2:-0}" -gt 0 ]; then
  taskset -c 0,1 stress-ng --cpu "$2" --quiet & LOAD=$!
fi
trap 'kill $NODE $LOAD 2>/dev/null; sleep 2; kill $MASTER 2>/dev/null' EXIT
taskset -c 1 "$REPO/scripts/soak.py" --duration "${1:-600}" --json "$REPO/build/soak.json"
