#!/bin/bash
# chiaro's path tracer against Mitsuba 3's llvm_ad_rgb on the
# environment-lit glossy spheres (benches/env_spheres.toml through
# benches/mitsuba_env.py; 256x192, box filter, 2 threads) in alternating
# back-to-back pairs, as benches/mitsuba_pairs.sh does for the Cornell box:
# each side renders twice per pair in its own process and keeps the faster
# render; the medians of the per-pair ratios are printed. With BEFORE set
# to another path_bench binary (an earlier build), each pair renders with
# it too, so a change is measured against its baseline and the peer in
# the same run (columns before_s, before_ratio).
# usage: benches/mitsuba_env_pairs.sh [PAIRS=7] [SPP=64]
# needs a venv with mitsuba and numpy ($MITSUBA_VENV, default /tmp/mvenv),
# Debian's libllvm19, and a release chiaro CLI for the export ($CHIARO).
set -euo pipefail
cd "$(dirname "$0")/.."
pairs=${1:-7}
spp=${2:-64}
venv=${MITSUBA_VENV:-/tmp/mvenv}
export DRJIT_LIBLLVM_PATH=${DRJIT_LIBLLVM_PATH:-/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1}
cargo build --release -q -p chiaro-ray --example path_bench
bench=target/release/examples/path_bench
before=${BEFORE:-}
out=target/mitsuba-env-pairs
mkdir -p "$out"
fastest() { grep -o 'render\[[0-9]*\]=[0-9.]*' "$1" | cut -d= -f2 | sort -n | head -1; }
echo "load before: $(cut -d' ' -f1-3 /proc/loadavg)"
if [ -n "$before" ]; then
    echo "pair  mitsuba_s  chiaro_s  ratio  before_s  before_ratio (chiaro samples/s over Mitsuba's)"
else
    echo "pair  mitsuba_s  chiaro_s  ratio (chiaro samples/s over Mitsuba's)"
fi
for i in $(seq "$pairs"); do
    "$venv/bin/python" benches/mitsuba_env.py render llvm_ad_rgb "$spp" "$i" "$out/mi.npy" 2 > "$out/mi.log"
    "$bench" benches/env_spheres.toml "$out/chiaro" --spp "$spp" --threads 2 --repeats 2 --seed "$i" > "$out/chiaro.log"
    m=$(fastest "$out/mi.log")
    c=$(fastest "$out/chiaro.log")
    if [ -n "$before" ]; then
        "$before" benches/env_spheres.toml "$out/before" --spp "$spp" --threads 2 --repeats 2 --seed "$i" > "$out/before.log"
        b=$(fastest "$out/before.log")
        awk -v i="$i" -v m="$m" -v c="$c" -v b="$b" \
            'BEGIN { printf "%4d  %9.3f  %8.3f  %.3f  %8.3f  %.3f\n", i, m, c, m / c, b, m / b }'
    else
        awk -v i="$i" -v m="$m" -v c="$c" 'BEGIN { printf "%4d  %9.3f  %8.3f  %.3f\n", i, m, c, m / c }'
    fi
done | tee "$out/pairs.log"
echo "load after: $(cut -d' ' -f1-3 /proc/loadavg)"
median_of() {
    awk -v k="$1" '{ print $k }' "$out/pairs.log" | sort -n | awk -v name="$2" '{ r[NR] = $1 } END {
        printf "median %s %.3f over %d pairs (range %.3f-%.3f)\n", name, r[int((NR + 1) / 2)], NR, r[1], r[NR]
    }'
}
median_of 4 ratio
if [ -n "$before" ]; then
    median_of 6 "before ratio"
    awk '{ print $5 / $3 }' "$out/pairs.log" | sort -n | awk '{ r[NR] = $1 } END {
        printf "median before_s / chiaro_s (speed-up) %.3f (range %.3f-%.3f)\n", r[int((NR + 1) / 2)], r[1], r[NR]
    }'
fi
