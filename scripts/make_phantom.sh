#!/usr/bin/env bash
# Regenerates the liver phantom in config/phantom (scripts/make_phantom.py), installing gmsh's
# Python module if missing. Arguments go to the script (--check compares with the committed files).
source "$(dirname "$0")/common.sh"
install_missing_packages
exec /usr/bin/python3 "$REPO/scripts/make_phantom.py" "$@"
