#!/usr/bin/env bash
# Quick start 2: install, build, and run every test (unit tests without a ROS master, the
# rostest integration tests, a short fixed-size fuzzing of the loaders, the install space run
# without the sources: scripts/install_check.sh). Exits non-zero when any test fails.
source "$(dirname "$0")/common.sh"
install_missing_packages
build_workspace
make -C "$WS/build" -j2 tests
"$REPO/scripts/fuzz.sh" smoke
install_status=0
"$REPO/scripts/install_check.sh" || install_status=$?
cd "$WS/build" && ctest -j2 --output-on-failure
exit "$install_status"
