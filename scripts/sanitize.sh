#!/usr/bin/env bash
# The whole test suite (gtest and rostest) built with AddressSanitizer and
# UndefinedBehaviorSanitizer, in its own workspace build/ws_sanitize. Exits non-zero on any
# failure or sanitizer report.
source "$(dirname "$0")/common.sh"
install_missing_packages
WS="$REPO/build/ws_sanitize"
build_workspace -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  "-DCMAKE_CXX_FLAGS=-fsanitize=address,undefined -fno-omit-frame-pointer -fno-sanitize-recover=undefined"
make -C "$WS/build" -j2 tests
export ASAN_OPTIONS=detect_leaks=1:abort_on_error=1 UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1
cd "$WS/build" && ctest --output-on-failure
