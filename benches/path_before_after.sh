#!/bin/bash
# Two builds of chiaro's path_bench example on one scene, in alternating
# back-to-back pairs (this machine's speed drifts over tens of seconds):
# per pair, each binary renders REPEATS times in its own process and keeps
# its best samples per CPU second (the steadier figure on a shared machine)
# and its best wall time; prints each pair and the medians.
# usage: benches/path_before_after.sh BEFORE_BENCH AFTER_BENCH SCENE [PAIRS=5] [SPP=64] [REPEATS=2]
# (build each with `cargo build --release -p chiaro-ray --example path_bench`
# in its checkout; the binaries are target/release/examples/path_bench.)
set -euo pipefail
before=$1 after=$2 scene=$3
pairs=${4:-5} spp=${5:-64} repeats=${6:-2}
out=$(mktemp -d)
best() { # best Msamples/cpu-s and best wall seconds of one log
    grep -o 'render\[[0-9]*\]=[0-9.]*s.*Msamples/cpu-s' "$1" |
        awk '{ sub(/render\[[0-9]*\]=/, "", $1); sub(/s$/, "", $1); w = $1 + 0;
               c = $(NF - 1) + 0; if (c > bc) bc = c; if (bw == 0 || w < bw) bw = w }
             END { printf "%.3f %.3f", bc, bw }'
}
echo "pair  before_Ms/cpu-s  before_s  after_Ms/cpu-s  after_s"
for i in $(seq "$pairs"); do
    "$before" "$scene" "$out/b" --spp "$spp" --repeats "$repeats" --seed "$i" > "$out/b.log"
    "$after" "$scene" "$out/a" --spp "$spp" --repeats "$repeats" --seed "$i" > "$out/a.log"
    echo "$i $(best "$out/b.log") $(best "$out/a.log")"
done | tee "$out/pairs.log"
med() { awk -v c="$1" '{ print $c }' "$out/pairs.log" | sort -g | awk '{ v[NR] = $1 } END { print v[int((NR + 1) / 2)] }'; }
b=$(med 2) bw=$(med 3) a=$(med 4) aw=$(med 5)
awk -v b="$b" -v bw="$bw" -v a="$a" -v aw="$aw" 'BEGIN {
    printf "median: before %.3f Msamples/cpu-s (%.3f s), after %.3f Msamples/cpu-s (%.3f s), after/before %.3f\n", b, bw, a, aw, a / b
}'
rm -rf "$out"
