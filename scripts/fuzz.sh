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
# Line tables are all the sanitizers need for file:line in their reports (full -g costs more to compile).
FLAGS=(-std=c++17 -O1 -gline-tables-only -fsanitize=fuzzer,address,undefined -fno-sanitize-recover=undefined
       -I"$REPO/include" -I/usr/include/eigen3)
# The targets' harnesses (test/fuzz/<target>.cpp) and the sources and libraries each links.
TARGETS=(fuzz_mesh fuzz_vessel fuzz_scene fuzz_surface fuzz_label_map)
sources() {
  local core="$REPO/src/core"
  case $1 in
    fuzz_mesh) echo "$core/geometry/mesh.cpp $core/io/mesh_io.cpp" ;;
    fuzz_vessel) echo "$core/geometry/vessel_tree.cpp $core/io/vessel_io.cpp $core/io/vtk_polydata.cpp -lyaml-cpp" ;;
    fuzz_scene) echo "$core/scene/scene.cpp $core/scene/scene_overrides.cpp $core/scene/options.cpp $core/geometry/region.cpp -lyaml-cpp" ;;
    fuzz_surface) echo "$core/io/surface_io.cpp $core/io/vtk_polydata.cpp $core/meshing/surface_repair.cpp" ;;
    fuzz_label_map) echo "$core/io/label_map_io.cpp -lz" ;;
  esac
}
build() {  # target: rebuilt when a source it may use is newer
  local target=$1
  if [ ! -x "$OUT/$target" ] || [ -n "$(find "$REPO/src/core" "$REPO/include" "$REPO/test/fuzz" -newer "$OUT/$target" -print -quit)" ]; then
    # shellcheck disable=SC2046  # the sources' list splits into its words
    clang++ "${FLAGS[@]}" "$REPO/test/fuzz/$target.cpp" $(sources "$target") -o "$OUT/$target"
  fi
}
fuzz() {  # target: fuzzes it, its output in build/fuzz/<target>.log
  local target=$1 corpus="$OUT/corpus_${1#fuzz_}"
  [ "$DESCRIPTION" = smoke ] && corpus="$OUT/smoke_${target#fuzz_}" && rm -rf "$corpus"
  mkdir -p "$corpus"
  (cd "$OUT" && "./$target" "${LIMIT[@]}" -print_final_stats=1 -timeout=10 -rss_limit_mb=2048 \
     "$corpus" "$REPO/test/fuzz/seeds/${target#fuzz_}" >"$OUT/$target.log" 2>&1) || {
    tail -40 "$OUT/$target.log"; echo "fuzz: $target FAILED (log: $OUT/$target.log)" >&2; return 1; }
}
# Runs the function on every target, two at a time (the targets are independent, each one
# process on one core); fails when any of them failed, after all have ended.
each_target() {
  local status=0 running=0
  for target in "${TARGETS[@]}"; do
    if [ "$running" -ge 2 ]; then wait -n || status=1; running=$((running - 1)); fi
    "$1" "$target" &
    running=$((running + 1))
  done
  for _ in $(seq "$running"); do wait -n || status=1; done
  return "$status"
}
each_target build
each_target fuzz
for target in "${TARGETS[@]}"; do
  corpus="$OUT/corpus_${target#fuzz_}"
  [ "$DESCRIPTION" = smoke ] && corpus="$OUT/smoke_${target#fuzz_}"
  runs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$OUT/$target.log" | grep -o '[0-9]*$')
  echo "fuzz: $target ($DESCRIPTION): $runs inputs, corpus $(ls "$corpus" | wc -l) files, no crash"
done
