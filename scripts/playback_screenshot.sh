#!/usr/bin/env bash
# Headless rviz screenshot of a demo playback (for the README): records the demo bag, plays it
# into the node with rviz on a virtual X display, captures doc/playback.png mid-press.
# Needs: apt-get install rviz xvfb xauth imagemagick x11-utils libgl1-mesa-dri; a built workspace.
source "$(dirname "$0")/ros_env.sh" 11499
export DISPLAY=:99
BAG="$REPO/build/demo.bag"
"$REPO/scripts/record_demo_bag.py" "$BAG"
Xvfb :99 -screen 0 1280x800x24 >/dev/null 2>&1 & XVFB=$!
roslaunch -p 11499 liver_sim playback.launch bag:="$BAG" >"$REPO/build/playback.log" 2>&1 & LAUNCH=$!
trap 'kill $LAUNCH 2>/dev/null; sleep 2; kill $XVFB 2>/dev/null' EXIT
for _ in $(seq 60); do xwininfo -root -tree 2>/dev/null | grep -q RViz && break; sleep 0.5; done
sleep "${1:-6}"   # seconds into the session: the probe is pressing
import -window root "$REPO/doc/playback.png"
echo "wrote $REPO/doc/playback.png"
