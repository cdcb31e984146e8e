#!/usr/bin/env bash
# Quick start 1: install, build, and play an OR session on a liver (SOFA's liver2), headless: the node
# with a ROS master of its own, a grasper lifting the right lobe's edge, a probe pressing above
# the tumour, a depth camera's clouds registering (scripts/or_demo.py). One status line per
# second, a summary at the end; about 30 s after the build.
#   scripts/run.sh [--rviz] [--speed F]
#     --rviz     also open rviz with the package's config (installs rviz if missing; needs a display)
#     --speed F  session speed factor, > 0 (default 1)
#     --help     this text
source "$(dirname "$0")/common.sh"
usage() { sed -n '2,9s/^# \{0,1\}//p' "$0"; }
rviz=false
speed=1
while [ $# -gt 0 ]; do
  case "$1" in
    --rviz) rviz=true ;;
    --speed) [ $# -ge 2 ] || { usage >&2; exit 2; }; speed=$2; shift ;;
    -h|--help) usage; exit 0 ;;
    *) echo "run.sh: unknown option '$1'" >&2; usage >&2; exit 2 ;;
  esac
  shift
done
if $rviz; then PACKAGES+=(rviz); fi
install_missing_packages
build_workspace >&2
set +u; source "$WS/devel/setup.bash"; set -u

# A master of its own on a free port: a running ROS system is not disturbed.
port=$(python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
export ROS_MASTER_URI="http://127.0.0.1:$port"
roslaunch -p "$port" liver_sim liver_sim.launch scene:="$REPO/config/scenes/sofa_liver_or.yaml" rviz:="$rviz" output:=log >"$ROS_LOG_DIR/run.log" 2>&1 &
launch=$!
trap 'kill -INT $launch 2>/dev/null; wait $launch 2>/dev/null || true' EXIT
"$REPO/scripts/or_demo.py" --speed "$speed"
