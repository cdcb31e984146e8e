#!/usr/bin/env bash
# Fuzzes the mesh, vessel-tree, scene, surface and label-map loaders with libFuzzer (clang, AddressSanitizer
# + UBSan): any crash, sanitizer report or exception other than MeshError/VesselError/SceneError
# fails the run.
#   scripts/fuzz.sh [SECONDS_PER_TARGET]   (default 300) the corpus grows in build/fuzz/corpus_*
#   scripts/fuzz.sh smoke                  20,000 inputs per target from the seeds, fixed random
#                                          seed: a bounded run for the test command
source "$(dirname "$0")/common.sh"
if [ "${1:-}" = smoke ]; then
  LIMIT=(-runs=20000 -seed=1)
  DESCRIPTION="smoke"
else
  LIMIT=(-max_total_time="${1:-300}")
  DESCRIPTION="${1:-300} s"
fi
OUT="$REPO/build/fuzz"
mkdir -p "$OUT"
FLAGS=(-std=c++17 -O1 -g -fsanitize=fuzzer,address,undefined -fno-sanitize-recover=undefined
       -I"$REPO/include" -I/usr/include/eigen3)
build() {  # target sources... [libraries]
  local target=$1; shift
  if [ ! -x "$OUT/$target" ] || [ -n "$(find "$REPO/src/core" "$REPO/include" "$REPO/test/fuzz" -newer "$OUT/$target" -print -quit)" ]; then
    clang++ "${FLAGS[@]}" "$@" -o "$OUT/$target"
  fi
}
build fuzz_mesh "$REPO/test/fuzz/fuzz_mesh.cpp" "$REPO/src/core/geometry/mesh.cpp" "$REPO/src/core/io/mesh_io.cpp"
build fuzz_vessel "$REPO/test/fuzz/fuzz_vessel.cpp" "$REPO/src/core/geometry/vessel_tree.cpp" "$REPO/src/core/io/vessel_io.cpp" "$REPO/src/core/io/vtk_polydata.cpp" \
  -lyaml-cpp
build fuzz_scene "$REPO/test/fuzz/fuzz_scene.cpp" "$REPO/src/core/scene/scene.cpp" "$REPO/src/core/scene/scene_overrides.cpp" \
  "$REPO/src/core/scene/options.cpp" \
  "$REPO/src/core/geometry/region.cpp" -lyaml-cpp
build fuzz_surface "$REPO/test/fuzz/fuzz_surface.cpp" "$REPO/src/core/io/surface_io.cpp" "$REPO/src/core/io/vtk_polydata.cpp" \
  "$REPO/src/core/meshing/surface_repair.cpp"
build fuzz_label_map "$REPO/test/fuzz/fuzz_label_map.cpp" "$REPO/src/core/io/label_map_io.cpp" -lz
for target in fuzz_mesh fuzz_vessel fuzz_scene fuzz_surface fuzz_label_map; do
  corpus="$OUT/corpus_${target#fuzz_}"
  [ "$DESCRIPTION" = smoke ] && corpus="$OUT/smoke_${target#fuzz_}" && rm -rf "$corpus"
  mkdir -p "$corpus"
  log="$OUT/$target.log"
  (cd "$OUT" && "./$target" "${LIMIT[@]}" -print_final_stats=1 -timeout=10 -rss_limit_mb=2048 \
     "$corpus" "$REPO/test/fuzz/seeds/${target#fuzz_}" >"$log" 2>&1) || {
    tail -40 "$log"; echo "fuzz: $target FAILED (log: $log)" >&2; exit 1; }
  runs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$log" | grep -o '[0-9]*$')
  echo "fuzz: $target ($DESCRIPTION): $runs inputs, corpus $(ls "$corpus" | wc -l) files, no crash"
done
