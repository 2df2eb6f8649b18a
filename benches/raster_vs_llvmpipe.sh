#!/usr/bin/env bash
# Scan conversion vs Mesa llvmpipe on the same scene (1,003,520 triangles,
# 1920x1080, two point lights, back faces culled), in one run: chiaro's
# raster_bench example, then benches/llvmpipe_raster.py. Reports wall and
# process-CPU ms/frame (medians of $FRAMES) and peak memory (/usr/bin/time).
# Set-up (Debian 12 + PyPI):
#   apt-get install -y libgl1-mesa-dri libegl1 libegl-mesa0 libgbm1 libgles2 time
#   python3 -m venv /tmp/peers-venv && /tmp/peers-venv/bin/pip install moderngl glcontext numpy pillow
# ISSUE4=1 also times every shadow method and transparency mode (issue 4).
set -euo pipefail
cd "$(dirname "$0")/.."
FRAMES=${FRAMES:-5}
PEERS_VENV=${PEERS_VENV:-/tmp/peers-venv}
export PEERS_OUT=${PEERS_OUT:-/tmp/peers-out}
mkdir -p "$PEERS_OUT"
cargo build --release -p chiaro-raster --example raster_bench
echo "== machine: $(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | xargs); load: $(cut -d' ' -f1-3 /proc/loadavg)"
echo "== chiaro-raster"
/usr/bin/time -f "peak RSS %M KB" ./target/release/examples/raster_bench "$FRAMES"
if [ -x "$PEERS_VENV/bin/python" ]; then
  export LIBGL_ALWAYS_SOFTWARE=1
  for mode in phong gouraud flat; do
    echo "== llvmpipe $mode"
    /usr/bin/time -f "peak RSS %M KB" "$PEERS_VENV/bin/python" benches/llvmpipe_raster.py "$mode" "$FRAMES" 1
  done
else
  echo "llvmpipe skipped: no $PEERS_VENV (see the set-up above)" >&2
fi
if [ "${ISSUE4:-0}" = 1 ]; then
  echo "== issue 4: shadows and transparency"
  ./target/release/examples/raster_bench "$FRAMES" --issue4
fi
echo "== load after: $(cut -d' ' -f1-3 /proc/loadavg)"
