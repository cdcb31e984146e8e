#!/usr/bin/env bash
# The OR recipe of doc/performance.md: a ROS master, the node as launched on the phantom with the
# simulation on core 0 (its callbacks, clouds and background work on the other cores), and
# scripts/measure_or.py driving a probe at 30 Hz (and clouds with --clouds). Build first (scripts/run.sh).
#   scripts/measure_or.sh [--clouds HZ] [--duration S] [--busy CORE] [--json FILE] [-- NODE_ARGS...]
#     --busy CORE   one more process keeps CORE busy meanwhile (stress-ng)
#     NODE_ARGS     liver_sim.launch arguments, e.g. cpu_affinity:=[0] (the default) rate:=30
source "$(dirname "$0")/ros_env.sh"
measure=() busy=""
while [ $# -gt 0 ]; do
  case "$1" in
    --clouds|--duration|--json) measure+=("$1" "$2"); shift ;;
    --busy) busy=$2; shift ;;
    --) shift; break ;;
    *) echo "measure_or.sh: unknown option '$1'" >&2; exit 2 ;;
  esac
  shift
done
roslaunch -p "$PORT" liver_sim liver_sim.launch output:=log cpu_affinity:=[0] "$@" >/dev/null 2>&1 & LAUNCH=$!
pids=("$LAUNCH")
if [ -n "$busy" ]; then taskset -c "$busy" stress-ng --cpu 1 --timeout 600 >/dev/null 2>&1 & pids+=($!); fi
trap 'kill -INT "${pids[@]}" 2>/dev/null; wait 2>/dev/null' EXIT
"$REPO/scripts/measure_or.py" "${measure[@]}"
