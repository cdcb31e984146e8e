#!/bin/bash
# The calibration demonstration: measurements synthesized with E_p = 30 kPa and a capsule of
# E_c = 3 MPa, t = 93 um at two load levels, then both moduli fitted from a start a factor 10
# off (E_p0 = 3 kPa, E_c0 = 30 MPa) with the thickness given. calibrate exits 3 when a fitted
# modulus is more than 1% from the truth.
#   calibrate_demo.sh CALIBRATE_BINARY SCENE.yaml
set -euo pipefail
[ $# -eq 2 ] || { echo "usage: $0 CALIBRATE_BINARY SCENE.yaml" >&2; exit 2; }
calibrate=$1 scene=$2
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

"$calibrate" --scene "$scene" --set parenchyma.young_modulus=30000 --set capsule.young_modulus=3e6 \
  --set capsule.thickness=93e-6 --levels 0.5,1 --synthesize "$tmp/measured.csv"
cat "$tmp/measured.csv"
"$calibrate" --scene "$scene" --set capsule.thickness=93e-6 --measured "$tmp/measured.csv" \
  --start-parenchyma 3000 --start-capsule 30e6 --expect-parenchyma 30000 --expect-capsule 3e6 --tolerance 0.01
