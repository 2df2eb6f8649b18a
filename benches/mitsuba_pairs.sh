#!/bin/bash
# chiaro's path tracer against Mitsuba 3's llvm_ad_rgb on Mitsuba's Cornell
# box (as benches/mitsuba_cbox.sh, box pixel filter, 64 spp, 2 threads), in
# alternating back-to-back pairs: this machine's speed drifts by 10-20 %
# over tens of seconds (both renderers' CPU time per sample moves), so a
# ratio of two medians taken a minute apart is noisier than the median of
# per-pair ratios. Each side renders twice per pair in its own process and
# keeps the faster render (the first of a process may pay one-off costs).
# usage: benches/mitsuba_pairs.sh [PAIRS=9] [SPP=64]
# needs what benches/mitsuba_cbox.sh needs ($MITSUBA_VENV, libllvm19).
# CHIARO_TARGET_RUSTFLAGS, when set, builds chiaro with those flags for the
# target only (e.g. "-C target-cpu=x86-64-v4 -C target-feature=-prefer-256-bit"
# for the AVX-512 kernel; BENCHMARKS.md, session 14) into target/bench-flags;
# with BOTH=1 as well, each pair also renders with the default build, so the
# two builds are compared render by render (columns chiaro_s, flags_s).
# BEFORE=PATH (a path_bench binary copied aside before a change) renders in
# each pair as well, in place of the flags build: before, after and Mitsuba
# share one run (columns chiaro_s, before_s; the medians of after over
# Mitsuba, before over Mitsuba and after's samples/s over before's).
set -euo pipefail
cd "$(dirname "$0")/.."
pairs=${1:-9}
spp=${2:-64}
venv=${MITSUBA_VENV:-/tmp/mvenv}
export DRJIT_LIBLLVM_PATH=${DRJIT_LIBLLVM_PATH:-/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1}
profile=${CHIARO_PROFILE:-release}
if [ -n "${CHIARO_TARGET_RUSTFLAGS:-}" ]; then
    # --target keeps build scripts native (they would not run otherwise
    # where the flags name features the build machine lacks).
    triple=$(rustc -vV | sed -n 's/^host: //p')
    RUSTFLAGS="$CHIARO_TARGET_RUSTFLAGS" CARGO_TARGET_DIR=target/bench-flags \
        cargo build --profile "$profile" -q -p chiaro-ray --example path_bench --target "$triple"
    bench=target/bench-flags/$triple/$profile/examples/path_bench
else
    bench=""
fi
cargo build --profile "$profile" -q -p chiaro-ray --example path_bench
default=target/$profile/examples/path_bench
flags=""
if [ -z "$bench" ]; then
    bench=$default
elif [ "${BOTH:-0}" = 1 ]; then
    flags=$bench
    bench=$default
fi
label=flags
if [ -n "${BEFORE:-}" ]; then
    [ -x "$BEFORE" ] || { echo "BEFORE=$BEFORE is not an executable" >&2; exit 1; }
    flags=$BEFORE
    label=before
fi
# mitsuba_cbox.py builds Mitsuba's scene with `chiaro export` (benches/chiaro_export.py).
cargo build --release -q -p chiaro-cli
out=target/mitsuba-bench
mkdir -p "$out"
fastest() { grep -o 'render\[[0-9]*\]=[0-9.]*' "$1" | cut -d= -f2 | sort -n | head -1; }
if [ -n "$flags" ]; then
    echo "pair  mitsuba_s  chiaro_s  ratio  ${label}_s  ${label}_ratio (chiaro samples/s over Mitsuba's)"
else
    echo "pair  mitsuba_s  chiaro_s  ratio (chiaro samples/s over Mitsuba's)"
fi
for i in $(seq "$pairs"); do
    "$venv/bin/python" benches/mitsuba_cbox.py render llvm_ad_rgb "$spp" box "$i" "$out/pair_mi.npy" 2 > "$out/pair_mi.log"
    "$bench" scenes/mitsuba-cbox.toml "$out/pair_chiaro" --spp "$spp" --repeats 2 --seed "$i" > "$out/pair_chiaro.log"
    m=$(fastest "$out/pair_mi.log")
    c=$(fastest "$out/pair_chiaro.log")
    if [ -n "$flags" ]; then
        "$flags" scenes/mitsuba-cbox.toml "$out/pair_flags" --spp "$spp" --repeats 2 --seed "$i" > "$out/pair_flags.log"
        f=$(fastest "$out/pair_flags.log")
        awk -v i="$i" -v m="$m" -v c="$c" -v f="$f" \
            'BEGIN { printf "%4d  %9.3f  %8.3f  %.3f  %7.3f  %.3f\n", i, m, c, m / c, f, m / f }'
    else
        awk -v i="$i" -v m="$m" -v c="$c" 'BEGIN { printf "%4d  %9.3f  %8.3f  %.3f\n", i, m, c, m / c }'
    fi
done | tee "$out/pairs.log"
median_of() {
    awk -v k="$1" '{ print $k }' "$out/pairs.log" | sort -n | awk -v name="$2" '{ r[NR] = $1 } END {
        printf "median %s %.3f over %d pairs (range %.3f-%.3f)\n", name, r[int((NR + 1) / 2)], NR, r[1], r[NR]
    }'
}
median_of 4 ratio
if [ -n "$flags" ]; then
    median_of 6 "$label ratio"
    awk '{ print $5 / $3 }' "$out/pairs.log" | sort -n | awk -v l="$label" '{ r[NR] = $1 } END {
        printf "median %s_s / chiaro_s %.3f (range %.3f-%.3f)\n", l, r[int((NR + 1) / 2)], r[1], r[NR]
    }'
fi
