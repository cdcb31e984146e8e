#!/usr/bin/env bash
# The whole test suite (gtest and rostest) built with AddressSanitizer and
# UndefinedBehaviorSanitizer, in its own workspace build/ws_sanitize. Exits non-zero on any
# failure or sanitizer report. Eigen switches to its own aligned allocator under ASan, while the
# Debian libraries it meets (orocos-kdl through tf2) were built with malloc; the two must agree
# (ASan's malloc is 16-byte aligned, as glibc's), or a vector allocated by one is freed by the other.
source "$(dirname "$0")/common.sh"
install_missing_packages
WS="$REPO/build/ws_sanitize"
build_workspace -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  "-DCMAKE_CXX_FLAGS=-fsanitize=address,undefined -fno-omit-frame-pointer -fno-sanitize-recover=undefined -DEIGEN_MALLOC_ALREADY_ALIGNED=1"
make -C "$WS/build" -j2 tests
export ASAN_OPTIONS=detect_leaks=1:abort_on_error=1 UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1
cd "$WS/build" && ctest --output-on-failure
