#!/usr/bin/env bash
# BVH build time and single-ray throughput of chiaro's BVH next to native
# Embree 3, on the same 1,003,520-triangle grid of icospheres and the same
# rays (the workload of shared/peers/embree_rays.py), both on $THREADS threads.
#
#   benches/embree_bvh.sh [THREADS] [REPS]
#
# Needs root for apt-get (libembree-dev, g++) the first time. The chiaro
# side (crates/chiaro-ray/examples/bvh_bench.rs) writes the mesh and rays to
# $OUT/wl_*.bin, which embree3_native then reads, so both trace identical rays.
# Run on an otherwise idle machine (shared/peers/wait_quiet.sh): a concurrent
# build doubles every figure.
set -euo pipefail
THREADS=${1:-2}
REPS=${2:-5}
ROOT=$(cd "$(dirname "$0")/.." && pwd)
PEERS=${PEERS_DIR:-$ROOT/../shared/peers}
[ -f "$PEERS/embree3_native.cpp" ] || PEERS=/work/shared/peers
OUT=${OUT:-$ROOT/target/bench-embree}
mkdir -p "$OUT"

if ! [ -f /usr/include/embree3/rtcore.h ] || ! command -v g++ >/dev/null; then
    apt-get update -qq && apt-get install -y -qq libembree-dev g++ >/dev/null
fi
if ! [ -x "$OUT/embree3_native" ] || [ "$PEERS/embree3_native.cpp" -nt "$OUT/embree3_native" ]; then
    g++ -O2 -fopenmp -o "$OUT/embree3_native" "$PEERS/embree3_native.cpp" -lembree3
fi

(cd "$ROOT" && cargo build --release -q -p chiaro-ray --example bvh_bench)
echo "== chiaro (crates/chiaro-ray/examples/bvh_bench.rs) =="
"$ROOT/target/release/examples/bvh_bench" --threads "$THREADS" --reps "$REPS" --dump "$OUT"
echo "== Embree $(dpkg-query -W -f='${Version}' libembree3-3 2>/dev/null || echo 3) (shared/peers/embree3_native.cpp) =="
PEERS_OUT="$OUT" "$OUT/embree3_native" "$THREADS" "$REPS"
