#!/usr/bin/env bash
# Quick start 2: install, build, and run every test (unit tests without a ROS master, the
# rostest integration tests, a short fixed-size fuzzing of the loaders). Exits non-zero when any
# test fails.
source "$(dirname "$0")/common.sh"
install_missing_packages
build_workspace
make -C "$WS/build" -j2 tests
"$REPO/scripts/fuzz.sh" smoke
cd "$WS/build" && ctest --output-on-failure
