#!/usr/bin/env bash
# Instructions per ray of one of our structures (STRUCTURE: the BVH medium preset by default, or kdtree)
# and of Embree 3 (medium quality) on a fixed workload, counted by
# callgrind: repeatable on the shared, noisy machine where wall-clock times are not.
#
# Builds duplex_bench_mesh in its own build dir with -O3 plus -g (same code as Release, but with line
# info, so our instructions can be split between traversal and triangle test), runs
#   duplex_bench_mesh --callgrind   (koala, 20,000 random rays; only the trace loops are instrumented)
# under valgrind (--branch-sim=yes: mispredicted conditional branches too), and prints Ir/ray for
# both plus where ours go.
#
# Environment: BUILD_DIR (default build-callgrind), MESH (koala.obj), RAYS (20000),
#              STRUCTURE (bvh:medium; kdtree, bvh:fast, bvh:medium/leaf=4, ...),
#              WHAT (tracers: ours,embree),
#              OUT (bench/results/callgrind.json; empty: do not write), KEEP (1: keep the dumps).
set -euo pipefail

ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
BUILD_DIR=${BUILD_DIR:-$ROOT/build-callgrind}
MESH=${MESH:-koala.obj}
RAYS=${RAYS:-20000}
WHAT=${WHAT:-ours,embree}
STRUCTURE=${STRUCTURE:-bvh:medium}
OUT=${OUT-$ROOT/bench/results/callgrind.json}
JOBS=${JOBS:-2}

command -v valgrind >/dev/null || { echo "bench_callgrind.sh: valgrind not found" >&2; exit 1; }

# Records what is about to be compiled (revision, hash of uncommitted library changes).
. "$ROOT/scripts/bench_library_state.sh"

if [ ! -f "$BUILD_DIR/CMakeCache.txt" ]; then
  cmake -S "$ROOT" -B "$BUILD_DIR" -DCMAKE_BUILD_TYPE=Release -DCMAKE_CXX_FLAGS=-g \
        -DDUPLEX_BUILD_TESTS=OFF -DDUPLEX_BUILD_EXAMPLES=OFF -DDUPLEX_BUILD_BENCH=ON >/dev/null
fi
cmake --build "$BUILD_DIR" -j"$JOBS" --target duplex_bench_mesh >/dev/null
BIN="$BUILD_DIR/bench/duplex_bench_mesh"

DUMPS=$(mktemp -d /tmp/duplex_callgrind.XXXXXX)
cleanup() { if [ "${KEEP:-0}" != 1 ]; then rm -rf "$DUMPS"; else echo "dumps kept in $DUMPS" >&2; fi; }
trap cleanup EXIT

echo "running the workload under callgrind (a minute or two: the build runs uninstrumented but still under valgrind)" >&2
valgrind --tool=callgrind --instr-atstart=no --branch-sim=yes --callgrind-out-file="$DUMPS/callgrind.out" \
  "$BIN" --callgrind --callgrind-mesh "$MESH" --callgrind-rays "$RAYS" --callgrind-what "$WHAT" \
  --callgrind-structure "$STRUCTURE" \
  --out "$DUMPS/workload.json" \
  >"$DUMPS/valgrind.log" 2>&1 || { tail -30 "$DUMPS/valgrind.log" >&2; exit 1; }

if [ -n "$OUT" ]; then
  python3 "$ROOT/scripts/bench_callgrind_report.py" "$DUMPS" "$DUMPS/workload.json" --out "$OUT"
else
  python3 "$ROOT/scripts/bench_callgrind_report.py" "$DUMPS" "$DUMPS/workload.json"
fi
