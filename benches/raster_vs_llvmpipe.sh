#!/usr/bin/env bash
# Scan conversion vs Mesa llvmpipe on the same scene (1,003,520 triangles,
# 1920x1080, two point lights): chiaro's raster_bench example, then
# /work/shared/peers/gl_llvmpipe.py in the same run. Needs the peer set-up of
# /work/shared/peers/README.md (moderngl in $PEERS_VENV, Mesa's EGL/llvmpipe).
set -euo pipefail
cd "$(dirname "$0")/.."
FRAMES=${FRAMES:-5}
PEERS=${PEERS:-/work/shared/peers}
PEERS_VENV=${PEERS_VENV:-./peers-venv}
export PEERS_OUT=${PEERS_OUT:-./peers-out}
mkdir -p "$PEERS_OUT"
cargo build --release -p chiaro-raster --example raster_bench
echo "== chiaro-raster"
./target/release/examples/raster_bench "$FRAMES"
./target/release/examples/raster_bench "$FRAMES" --no-cull
if [ -x "$PEERS_VENV/bin/python" ]; then
  export LIBGL_ALWAYS_SOFTWARE=1
  for mode in phong gouraud; do
    echo "== llvmpipe $mode"
    "$PEERS_VENV/bin/python" "$PEERS/gl_llvmpipe.py" "$mode" "$FRAMES" egl
  done
else
  echo "llvmpipe skipped: no $PEERS_VENV (see $PEERS/README.md)" >&2
fi
