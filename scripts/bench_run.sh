#!/usr/bin/env bash
# Builds duplex_bench_mesh (Release) and runs the whole benchmark:
#   main bench  -> bench/results/mesh_bench.json (+ .txt: the table printed on stderr)
#   sweep       -> bench/results/sweep.json      (+ .txt)
#   tables      -> bench/results/structures.txt/.csv
#   charts      -> docs/bench/build_vs_trace.png, docs/bench/throughput_vs_embree.png,
#                  docs/bench/structures_build_vs_trace.png, structures_watertight.png
# Every structure (BVH presets, kd-tree, Embree medium/high/robust) on every default mesh: allow an
# hour on the shared 2-core machine; the 1.6M-triangle mesh is the slow part.
#
# Environment:
#   BUILD_DIR   build directory (default: build-bench)
#   OUTDIR      where JSON and tables go (default: bench/results; with QUICK=1: /tmp/duplex_bench_quick)
#   CHARTDIR    where the charts go (default: docs/bench; with QUICK=1: OUTDIR)
#   QUICK=1     smoke run (--quick: small meshes, few rays, one repetition)
#   MAIN_ARGS   extra arguments for the main bench   (e.g. "--repeat 5" or "--meshes koala.obj:2")
#   SWEEP_ARGS  extra arguments for the sweep        (e.g. "--sweep-meshes koala.obj")
#   SKIP_MAIN=1 / SKIP_SWEEP=1   run only the other part (the charts are drawn from whatever JSON exists)
#   CALLGRIND=1 also run scripts/bench_callgrind.sh (instructions per ray; a few more minutes), in its
#               own -g build dir CALLGRIND_BUILD_DIR (default build-callgrind)
#   JOBS        parallel build jobs (default 2: the machine is shared)
#   PYTHON      interpreter with matplotlib (default: /usr/bin/python3, Debian's python3-matplotlib)
set -euo pipefail

ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
BUILD_DIR=${BUILD_DIR:-$ROOT/build-bench}
JOBS=${JOBS:-2}
if [ "${QUICK:-0}" = 1 ]; then
  OUTDIR=${OUTDIR:-/tmp/duplex_bench_quick}
  CHARTDIR=${CHARTDIR:-$OUTDIR}
  QUICK_ARG=--quick
else
  OUTDIR=${OUTDIR:-$ROOT/bench/results}
  CHARTDIR=${CHARTDIR:-$ROOT/docs/bench}
  QUICK_ARG=
fi
PYTHON=${PYTHON:-/usr/bin/python3}
"$PYTHON" -c "import matplotlib" 2>/dev/null || PYTHON=python3
mkdir -p "$OUTDIR" "$CHARTDIR"

# Records what is about to be compiled (revision, hash of uncommitted library changes).
. "$ROOT/scripts/bench_library_state.sh"

# Tests and examples stay off here: the bench must build while others edit those folders.
cmake -S "$ROOT" -B "$BUILD_DIR" -DCMAKE_BUILD_TYPE=Release -DDUPLEX_BUILD_BENCH=ON \
      -DDUPLEX_BUILD_TESTS=OFF -DDUPLEX_BUILD_EXAMPLES=OFF >/dev/null
cmake --build "$BUILD_DIR" -j"$JOBS" --target duplex_bench_mesh >/dev/null
BIN="$BUILD_DIR/bench/duplex_bench_mesh"

start=$(date +%s)
if [ "${SKIP_MAIN:-0}" != 1 ]; then
  echo "== main bench -> $OUTDIR/mesh_bench.json" >&2
  # shellcheck disable=SC2086
  "$BIN" $QUICK_ARG ${MAIN_ARGS:-} --out "$OUTDIR/mesh_bench.json" 2>&1 | tee "$OUTDIR/mesh_bench.txt" >&2
fi
if [ "${SKIP_SWEEP:-0}" != 1 ]; then
  echo "== sweep -> $OUTDIR/sweep.json" >&2
  # shellcheck disable=SC2086
  "$BIN" --sweep $QUICK_ARG ${SWEEP_ARGS:-} --out "$OUTDIR/sweep.json" 2>&1 | tee "$OUTDIR/sweep.txt" >&2
fi
"$PYTHON" "$ROOT/scripts/plot_bench.py" --main "$OUTDIR/mesh_bench.json" --sweep "$OUTDIR/sweep.json" --outdir "$CHARTDIR"
if [ -f "$OUTDIR/mesh_bench.json" ]; then
  "$PYTHON" "$ROOT/scripts/plot_structures.py" --main "$OUTDIR/mesh_bench.json" --outdir "$OUTDIR" --charts "$CHARTDIR"
fi
if [ "${CALLGRIND:-0}" = 1 ]; then
  # bench_callgrind.sh needs its own -g build, not the BUILD_DIR of this script.
  BUILD_DIR="${CALLGRIND_BUILD_DIR:-$ROOT/build-callgrind}" OUT="$OUTDIR/callgrind.json" "$ROOT/scripts/bench_callgrind.sh" | tee "$OUTDIR/callgrind.txt"
fi
echo "bench_run.sh: done in $(( $(date +%s) - start )) s; results in $OUTDIR, charts in $CHARTDIR" >&2
