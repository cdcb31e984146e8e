# Sourced by the scripts that talk to a ROS master next to the built workspace (measure_node.sh,
# soak.sh, screenshot.sh): Debian's Python first, the workspace's setup, a master URI on
# the port given as $1. Sets REPO.
set -euo pipefail
REPO=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
export PATH="/usr/bin:/bin:$PATH" ROS_IP=127.0.0.1 ROS_MASTER_URI="http://127.0.0.1:$1"
export ROS_HOME="$REPO/build/ws/ros_home"
set +u; source "$REPO/build/ws/devel/setup.bash"; set -u
