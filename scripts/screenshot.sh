#!/usr/bin/env bash
# Headless rviz screenshot of the OR session of scripts/run.sh (for the README): the node on the
# OR demo's liver, rviz and scripts/or_demo.py (launch/or_demo.launch) on a virtual X display;
# captures doc/or_session.png.
#   scripts/screenshot.sh [SECONDS [SURFACE_ALPHA]]   seconds into the session (default 15: the
#                                                     grasper holds the edge up, the probe has pressed
#                                                     5 mm above the tumour and not yet slid);
#                                                     the surface's opacity (default 0.5)
# Needs: apt-get install rviz xvfb xauth imagemagick x11-utils libgl1-mesa-dri; a built workspace.
source "$(dirname "$0")/ros_env.sh"
# A free display: Xvfb writes the number it took to descriptor 3.
displayfile=$(mktemp)
Xvfb -displayfd 3 -screen 0 1280x800x24 3>"$displayfile" 2>/dev/null & XVFB=$!
for _ in $(seq 50); do [ -s "$displayfile" ] && break; sleep 0.1; done
export DISPLAY=":$(cat "$displayfile")"
rm -f "$displayfile"
roslaunch -p "$PORT" liver_sim or_demo.launch rviz:=true surface_alpha:="${2:-0.5}" >"$REPO/build/screenshot.log" 2>&1 & LAUNCH=$!
trap 'kill $LAUNCH 2>/dev/null; sleep 2; kill $XVFB 2>/dev/null' EXIT
# The session's clock starts when the demo prints its first line.
for _ in $(seq 240); do grep -q "camera pixels" "$REPO/build/screenshot.log" && break; sleep 0.5; done
sleep "${1:-15}"
import -window root "$REPO/doc/or_session.png"
echo "wrote $REPO/doc/or_session.png"
