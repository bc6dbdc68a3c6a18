#!/usr/bin/env bash
# Ray packets against single rays and Embree 3's packets (docs/bench.md, "Ray packets"): runs
# duplex_bench_packets on meshes of ../shared/data/meshes and on the paper's scenes (generated as
# scripts/bench_update.sh generates them), once per SIMD path (DUPLEX_ISA: packets of 16, 8 and 4
# rays; the narrower paths on the meshes only), writes bench/results/packets/*.json and packets.txt,
# and draws docs/bench/packets/*.png.
#
# Environment:
#   BUILD_DIR   build directory (default: build)
#   OUTDIR      JSON and table (default: bench/results/packets)
#   CHARTDIR    charts (default: docs/bench/packets)
#   SCENE_DIR   generated scenes (default: out/paper)
#   SCENES      scenes (default: "paper-1 paper-2 robot5")
#   MESHES      meshes (default: "spot.obj hammer.obj koala.obj abb_irb6640/link_1.stl")
#   ARGS        extra arguments of duplex_bench_packets (e.g. "--side 512 --reps 5")
set -euo pipefail
ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
BUILD_DIR=${BUILD_DIR:-$ROOT/build}
OUTDIR=${OUTDIR:-$ROOT/bench/results/packets}
CHARTDIR=${CHARTDIR:-$ROOT/docs/bench/packets}
SCENE_DIR=${SCENE_DIR:-$ROOT/out/paper}
SCENES=${SCENES:-"paper-1 paper-2 robot5"}
MESHES=${MESHES:-"spot.obj hammer.obj koala.obj abb_irb6640/link_1.stl"}
ARGS=${ARGS:-}
DATA=$ROOT/../shared/data/meshes
DUPLEX=$BUILD_DIR/bin/duplex
BENCH=$BUILD_DIR/bench/duplex_bench_packets
if [ ! -d "$DATA" ]; then echo "bench_packets.sh: $DATA is absent" >&2; exit 1; fi
cmake -S "$ROOT" -B "$BUILD_DIR" -DCMAKE_BUILD_TYPE=Release -DDUPLEX_BUILD_EXAMPLES=ON -DDUPLEX_BUILD_BENCH=ON >/dev/null
cmake --build "$BUILD_DIR" -j2 --target duplex_cli duplex_bench_packets >/dev/null
mkdir -p "$OUTDIR" "$SCENE_DIR"

# shellcheck source=paper_scenes.sh
source "$ROOT/scripts/paper_scenes.sh"
scene_files=()
for name in $SCENES; do
  make_scene "$name"
  scene_files+=("$SCENE_DIR/$name.json")
done

# shellcheck disable=SC2086
DUPLEX_ISA=avx512 "$BENCH" --meshes $MESHES --scenes "${scene_files[@]}" $ARGS --out "$OUTDIR/packets_avx512.json"
for isa in avx2 sse2; do
  # shellcheck disable=SC2086
  DUPLEX_ISA=$isa "$BENCH" --meshes $MESHES --threads 1 $ARGS --out "$OUTDIR/packets_$isa.json"
done
/usr/bin/python3 "$ROOT/scripts/plot_packets.py" --json "$OUTDIR/packets_avx512.json" --json "$OUTDIR/packets_avx2.json" \
  --json "$OUTDIR/packets_sse2.json" --outdir "$OUTDIR" --charts "$CHARTDIR"
