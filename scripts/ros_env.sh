# Sourced by the scripts that talk to a ROS master next to the built workspace (measure_node.sh,
# soak.sh, screenshot.sh): Debian's Python first, the workspace's setup, a master URI on
# a free port of its own (a master of each run: parallel runs do not meet). Sets REPO and PORT.
set -euo pipefail
REPO=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
export PATH="/usr/bin:/bin:$PATH" ROS_IP=127.0.0.1
PORT=$(python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
export ROS_MASTER_URI="http://127.0.0.1:$PORT"
export ROS_HOME="$REPO/build/ws/ros_home"
set +u; source "$REPO/build/ws/devel/setup.bash"; set -u
