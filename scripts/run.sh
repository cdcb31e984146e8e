#!/usr/bin/env bash
# Quick start 1: install, build, and run the default scene (the reference aspiration test).
#   scripts/run.sh [simulate options]   e.g. scripts/run.sh --set capsule.enabled=false
source "$(dirname "$0")/common.sh"
install_missing_packages
build_workspace >&2
exec "$WS/devel/lib/liver_sim/simulate" --scene "$REPO/config/scenes/aspiration_tube.yaml" "$@"
