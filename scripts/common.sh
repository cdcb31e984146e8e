# Shared by scripts/run.sh and scripts/test.sh: install missing Debian packages, create or reuse
# the catkin workspace build/ws (the package is linked into its src), build in Release.
set -euo pipefail

REPO=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
WS="$REPO/build/ws"
# Debian's ROS Python modules are invisible to a pyenv or venv python3 earlier on PATH.
export PATH="/usr/bin:/bin:/usr/sbin:/sbin:$PATH"
export ROS_HOME="$WS/ros_home" ROS_LOG_DIR="$WS/ros_home/log" ROS_IP=127.0.0.1

PACKAGES=(
  build-essential cmake catkin libroscpp-dev libroslib-dev ros-message-generation ros-message-runtime ros-std-msgs
  libstd-msgs-dev libgeometry-msgs-dev ros-geometry-msgs libsensor-msgs-dev libvisualization-msgs-dev libstd-srvs-dev
  libdiagnostic-msgs-dev libdiagnostic-updater-dev libtf2-dev libtf2-ros-dev libtf2-geometry-msgs-dev libtf2-eigen-dev
  libdynamic-reconfigure-config-init-mutex-dev python3-dynamic-reconfigure
  libpcl-conversions-dev libpcl-dev
  libeigen3-dev libsuitesparse-dev libopenblas0-pthread libyaml-cpp-dev
  libgtest-dev python3-rostest librostest-dev python3-roslaunch python3-rosmaster rosout
  python3-rospy python3-rosbag python3-geometry-msgs python3-sensor-msgs python3-std-srvs
  python3-visualization-msgs python3-diagnostic-msgs python3-matplotlib python3-numpy python3-scipy clang libclang-rt-14-dev
  python3-gmsh libgmsh-dev stress-ng
  libvtk9-dev zlib1g-dev   # make_model: re-surfacing (VTK), compressed label maps (zlib)
  # The scripts' and tests' Python: catkin's module (package_paths.py), YAML, tf and clock messages.
  python3-catkin python3-yaml python3-tf2-msgs python3-rosgraph-msgs catkin-lint
  # The tools' command lines, JSON output and calibrate's minimiser (header-only).
  libcli11-dev nlohmann-json3-dev libboost-dev
  # The ROS command-line tools: rostopic, rosservice, rosnode, rosrun, static_transform_publisher.
  python3-rostopic python3-rosservice python3-rosnode rosbash tf2-tools
)

install_missing_packages() {
  local missing=()
  for p in "${PACKAGES[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
  done
  [ ${#missing[@]} -eq 0 ] && return 0
  echo "liver_sim: installing ${missing[*]}" >&2
  local sudo=""
  [ "$(id -u)" -ne 0 ] && sudo="sudo"
  $sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y --no-install-recommends "${missing[@]}"
}

build_workspace() {
  mkdir -p "$WS/src" "$ROS_LOG_DIR"
  # The package in the workspace: a folder of links to the repository's top-level entries, all
  # but build/ (a link to the repository itself would loop through build/ws/src, and roslaunch
  # and rosrun walk package folders following links).
  [ -L "$WS/src/liver_sim" ] && rm "$WS/src/liver_sim"
  mkdir -p "$WS/src/liver_sim"
  for entry in "$REPO"/* "$REPO"/.ci; do
    name=$(basename "$entry")
    [ "$name" = build ] || ln -sfn "$entry" "$WS/src/liver_sim/$name"
  done
  # Python test nodes need this path in the cached PYTHONPATH of the first configure.
  mkdir -p "$WS/devel/lib/python3/dist-packages"
  (cd "$WS" && catkin_make -j2 -DCMAKE_BUILD_TYPE=Release \
      -DPYTHON_EXECUTABLE=/usr/bin/python3 -DPython3_EXECUTABLE=/usr/bin/python3 "$@")
}
