#!/usr/bin/env bash
# Whitted ray tracing time: chiaro on scenes/whitted.toml next to POV-Ray 3.7
# on shared/peers/whitted.pov (a similar but not identical Whitted-style
# scene: checkerboard, mirror sphere, glass sphere, point lights), both at
# 640x480 with adaptive anti-aliasing, 2 threads, in the same run.
#
#   benches/whitted_povray.sh [REPS]
set -euo pipefail
REPS=${1:-3}
ROOT=$(cd "$(dirname "$0")/.." && pwd)
PEERS=${PEERS_DIR:-$ROOT/../shared/peers}
[ -f "$PEERS/whitted.pov" ] || PEERS=/work/shared/peers
OUT=${OUT:-$ROOT/target/bench-whitted}
mkdir -p "$OUT" "$HOME/.povray/3.7"
command -v povray >/dev/null || { apt-get update -qq && apt-get install -y -qq povray >/dev/null; }
(cd "$ROOT" && cargo build --release -q -p chiaro-ray --example whitted_render)
for i in $(seq "$REPS"); do
    echo "== chiaro whitted.toml, adaptive AA, threshold 0.05 (scene default) (run $i)"
    "$ROOT/target/release/examples/whitted_render" "$ROOT/scenes/whitted.toml" "$OUT/chiaro_whitted.png" \
        --size 640x480 --adaptive --threads 2
    echo "== chiaro whitted.toml, adaptive AA, threshold 0.3 as POV-Ray's +A0.3 (run $i)"
    "$ROOT/target/release/examples/whitted_render" "$ROOT/scenes/whitted.toml" "$OUT/chiaro_whitted_t03.png" \
        --size 640x480 --adaptive --threshold 0.3 --threads 2
    echo "== chiaro whitted.toml, 4 stratified samples (run $i)"
    "$ROOT/target/release/examples/whitted_render" "$ROOT/scenes/whitted.toml" "$OUT/chiaro_whitted_ss4.png" \
        --size 640x480 --samples 4 --threads 2
    echo "== POV-Ray whitted.pov +A0.3 +AM1 +R3 (run $i)"
    /usr/bin/time -f "process %es" povray -D -GA +WT2 +I"$PEERS/whitted.pov" +O"$OUT/pov_whitted.png" \
        +W640 +H480 +A0.3 +AM1 +R3 +FN 2>&1 | grep -E "Trace Time|Render Time|process" || true
done
