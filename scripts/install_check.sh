#!/usr/bin/env bash
# The package as an integrator deploys it (scripts/test.sh runs it after the tests; CI too): the
# built workspace installed into a fresh folder (the build's install target), that install space copied
# away from the repository, the workspace's sources renamed out of reach, and from a clean
# environment with only the copy's setup.bash: the node through liver_sim.launch until it
# publishes ~status, simulate and stress on the installed scenes, the OR demo through
# or_demo.launch, record_demo_bag.py then playback.launch (equilibrium first, the press
# coloured, no TF_REPEATED_DATA: test/playback_test.py), catkin_lint without errors, and a package
# built against the install space (test/downstream). Each ROS run on a master of its own port.
#   scripts/install_check.sh        (after scripts/test.sh or build_workspace)
source "$(dirname "$0")/common.sh"
RUN="$REPO/build/install_check"
rm -rf "$RUN" "$WS/install"
mkdir -p "$RUN"
# make, not catkin_make: the workspace is configured and built already, and catkin_make would
# configure it again (CMake, the message and reconfigure generators) for nothing.
make -C "$WS/build" -j2 install >"$RUN/install.log" 2>&1 || { tail -30 "$RUN/install.log"; exit 1; }
cp -a "$WS/install" "$RUN/install"
cp -a "$REPO/test/downstream" "$REPO/test/playback_test.py" "$RUN/"

echo "install_check: catkin_lint"
catkin_lint "$REPO" 2>&1 | grep -v "^catkin_lint: \(cannot load rosdep\|unknown dependencies\)" || true
catkin_lint -q "$REPO" >/dev/null 2>&1 || { echo "install_check: catkin_lint reports errors"; exit 1; }

# The sources out of reach: what the build knew as the package's folder (build/ws/src) is gone
# while the install space runs.
mv "$WS/src" "$WS/src.out_of_reach"
trap 'mv "$WS/src.out_of_reach" "$WS/src"' EXIT

# The check's script as an argument, not on standard input, which the ROS tools it runs would read.
check=$(cat <<'EOF'
cd "$RUN"
# Job control: a non-interactive shell's background jobs ignore SIGINT otherwise, and roslaunch
# would not hear the Ctrl-C that ends it.
set -m
export ROS_HOME="$RUN/ros_home" ROS_LOG_DIR="$RUN/ros_home/log" ROS_IP=127.0.0.1
set +u; source "$RUN/install/setup.bash"; set -u
share=$(rospack find liver_sim)
case "$share" in "$RUN/install/"*) ;; *) echo "install_check: rospack finds liver_sim in $share"; exit 1 ;; esac
free_port() { python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])'; }
wait_for_master() { timeout 30 bash -c 'until rostopic list >/dev/null 2>&1; do sleep 0.2; done'; }
# Starts roslaunch with the arguments on a master of its own, once the master answers; sets
# launch (its pid) and the URI.
start() {
  local port; port=$(free_port)
  export ROS_MASTER_URI="http://127.0.0.1:$port"
  # Unbuffered: roslaunch's "process has finished" must reach the log when it is said, not when
  # roslaunch exits (the wait for the demo below reads it).
  PYTHONUNBUFFERED=1 roslaunch -p "$port" "$@" >"$RUN/$log" 2>&1 &
  launch=$!
  wait_for_master
}
stop() { kill -INT "$launch" 2>/dev/null || true; wait "$launch" 2>/dev/null || true; }
trap stop EXIT

echo "install_check: roslaunch liver_sim liver_sim.launch, until ~status"
log=node.log start liver_sim liver_sim.launch
timeout 90 rostopic echo -n 1 /liver_sim/status/state >"$RUN/status.txt" || { tail -20 "$RUN/node.log"; exit 1; }
echo "  first ~status state: $(head -1 "$RUN/status.txt")"
stop

echo "install_check: rosrun liver_sim simulate; stress --quick"
rosrun liver_sim simulate --scene "$share/config/scenes/aspiration_cube.yaml" --quiet >"$RUN/simulate.json"
python3 -c 'import json, sys; r = json.load(open(sys.argv[1])); print("  simulate:", r["status"]); sys.exit(r["status"] != "converged")' "$RUN/simulate.json"
rosrun liver_sim stress --quick >"$RUN/stress.md" 2>"$RUN/stress.log" || { tail -5 "$RUN/stress.log"; exit 1; }
echo "  stress --quick: every case as expected"

echo "install_check: roslaunch liver_sim or_demo.launch speed:=3"
log=or_demo.log start liver_sim or_demo.launch speed:=3
for _ in $(seq 300); do
  grep -q "or_demo-[0-9]*\] process has \(finished\|died\)" "$RUN/or_demo.log" && break
  sleep 0.5
done
stop
grep "summary" "$RUN/or_demo.log" | sed 's/^/  /'
grep -q "or_demo-[0-9]*\] process has finished cleanly" "$RUN/or_demo.log" || { tail -20 "$RUN/or_demo.log"; exit 1; }

echo "install_check: rosrun liver_sim record_demo_bag.py, then playback.launch"
rosrun liver_sim record_demo_bag.py "$RUN/demo.bag" --duration 5 | sed 's/^/  /'
port=$(free_port)
export ROS_MASTER_URI="http://127.0.0.1:$port"
roscore -p "$port" >"$RUN/roscore.log" 2>&1 &
core=$!
trap 'stop; kill -INT $core 2>/dev/null; wait $core 2>/dev/null || true' EXIT
wait_for_master
python3 "$RUN/playback_test.py" >"$RUN/playback_test.log" 2>&1 &
client=$!
sleep 2
# On the client's master (roslaunch uses the one running on its port).
roslaunch -p "$port" liver_sim playback.launch bag:="$RUN/demo.bag" rviz:=false >"$RUN/playback.log" 2>&1 &
launch=$!
wait "$client" || { cat "$RUN/playback_test.log"; tail -30 "$RUN/playback.log"; exit 1; }
stop
repeated=$(grep -c TF_REPEATED_DATA "$RUN/playback.log" || true)
echo "  playback: bag after the equilibrium, press coloured, no transform repeated; TF_REPEATED_DATA lines: $repeated"
[ "$repeated" -eq 0 ]

echo "install_check: a package built against the install space (test/downstream)"
mkdir -p "$RUN/downstream_ws/src"
mv "$RUN/downstream" "$RUN/downstream_ws/src/liver_sim_downstream"
(cd "$RUN/downstream_ws" && catkin_make -DPYTHON_EXECUTABLE=/usr/bin/python3 >"$RUN/downstream.log" 2>&1) ||
  { tail -30 "$RUN/downstream.log"; exit 1; }
"$RUN/downstream_ws/devel/lib/liver_sim_downstream/downstream_check" "$share/config/scenes/aspiration_cube.yaml" | sed 's/^/  /'
EOF
)
env -i HOME="$HOME" PATH=/usr/bin:/bin LANG=C.UTF-8 RUN="$RUN" bash -euo pipefail -c "$check" </dev/null
echo "install_check: passed"
