#!/usr/bin/env bash
# Radiosity benchmark: time to converge the unit Cornell box (built in code
# by crates/chiaro-radiosity/examples/radiosity_bench.rs) to 1% unshot
# energy, per solver, form-factor method and element count. One process per
# configuration (so the peak-RSS column is that configuration's), each
# limited to $LIMIT seconds. Prints a Markdown table for BENCHMARKS.md.
#
#   benches/radiosity_bench.sh            # all configurations
#   LIMIT=60 benches/radiosity_bench.sh   # shorter per-run limit
set -u
cd "$(dirname "$0")/.."
LIMIT=${LIMIT:-240}
cargo build --release -p chiaro-radiosity --example radiosity_bench >&2 || exit 1
BIN=target/release/examples/radiosity_bench
echo "| solver | form factors | patch | elements | seconds | iterations | unshot | HR leaves | HR links | peak RSS MiB | ceiling mean radiance |"
echo "|---|---|---|---|---|---|---|---|---|---|---|"
run() {
  timeout "$LIMIT" "$BIN" "$@" || echo "| $1 | $2 | $3 | - | > $LIMIT (stopped) | - | - | - | - | - | - |"
}
# Hierarchical growth with N (display elements = 4^depth per source triangle).
for p in 0.25 0.125 0.0625 0.03125 0.015625; do run hierarchical raycast $p; done
# ~1k elements (patch 0.18 gives 1k uniform elements).
for s in jacobi gauss-seidel progressive; do
  for f in raycast hemicube analytic; do run $s $f 0.18; done
done
run hierarchical analytic 0.25
# ~10k and ~50k elements.
for s in progressive gauss-seidel; do run $s raycast 0.055; done
run progressive hemicube 0.055
run progressive raycast 0.025
