#!/usr/bin/env bash
# Whitted ray tracing time: chiaro and POV-Ray 3.7 on the same scene,
# scenes/whitted.toml, which benches/whitted_pov.py translates term for term
# into benches/whitted.pov (compare_images.py checks the two pictures agree).
# 640x480, 2 threads, REPS runs of each, alternating, in one run:
#  - no anti-aliasing: one ray through each pixel centre in both (the same
#    rays; the pictures agree but at edge pixels, see BENCHMARKS.md);
#  - adaptive anti-aliasing: chiaro's scene default (Whitted's corner
#    subdivision, threshold 0.05, 3 levels = 1/8 pixel) against POV-Ray's
#    method 2, the same corner subdivision, at +R4 (3 levels) and +A0.05,
#    where both trace about the same number of camera rays (printed).
# POV-Ray's time is its own "Trace Time" statistic (no parsing or start-up);
# chiaro's is the render time whitted_render prints (scene already loaded).
# CPU seconds (all threads) are printed beside them, the steadier figure on a
# busy machine: POV-Ray's own "CPU-seconds total" of the trace, chiaro's
# process user + system time (the scene load included).
#
#   benches/whitted_povray.sh [REPS]
set -euo pipefail
REPS=${1:-3}
ROOT=$(cd "$(dirname "$0")/.." && pwd)
OUT=${OUT:-$ROOT/target/bench-whitted}
mkdir -p "$OUT" "$HOME/.povray/3.7"
command -v povray >/dev/null || { apt-get update -qq && apt-get install -y -qq povray >/dev/null; }
(cd "$ROOT" && cargo build --release -q -p chiaro-ray --example whitted_render)
python3 "$ROOT/benches/whitted_pov.py" "$ROOT/scenes/whitted.toml" -o "$OUT/whitted.pov" --size 640x480
cmp -s "$OUT/whitted.pov" "$ROOT/benches/whitted.pov" ||
    echo "note: benches/whitted.pov is stale; regenerate it with benches/whitted_pov.py"
echo "machine: $(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | xargs); $(uptime)"

chiaro() { # $1 = label, rest = whitted_render options; prints "seconds cpu-seconds"
    local line
    line=$(/usr/bin/time -f "cpu %U %S" "$ROOT/target/release/examples/whitted_render" \
        "$ROOT/scenes/whitted.toml" "$OUT/chiaro_$1.png" --size 640x480 --threads 2 "${@:2}" 2>&1)
    echo "chiaro $1: $(xargs <<<"$line")" >&2
    echo "$(sed -nE 's/.*: ([0-9.]+)s,.*/\1/p' <<<"$line") $(awk '/^cpu/ {print $2 + $3}' <<<"$line")"
}
povray_trace() { # $1 = label, rest = POV-Ray options; prints seconds
    local log
    log=$(povray -D -V +WT2 +I"$OUT/whitted.pov" +O"$OUT/pov_$1.png" +FN +W640 +H480 "${@:2}" 2>&1 |
        tr '\r' '\n')
    local px smp
    px=$(sed -nE 's/^Pixels: +([0-9]+).*/\1/p' <<<"$log")
    smp=$(sed -nE 's/.*Samples: +([0-9]+).*/\1/p' <<<"$log")
    echo "povray $1: $(grep -E '^Rays:' <<<"$log" | xargs), camera rays $((px + smp));" \
        "$(grep -E -A1 'Trace Time' <<<"$log" | xargs)" >&2
    echo "$(sed -nE 's/.*Trace Time:.*\(([0-9.]+) seconds\).*/\1/p' <<<"$log")" \
        "$(grep -A1 'Trace Time' <<<"$log" | sed -nE 's/.*with ([0-9.]+) CPU-seconds.*/\1/p')"
}
median() { tr ' ' '\n' | grep . | sort -g | awk '{v[NR]=$1} END {print (NR%2 ? v[(NR+1)/2] : (v[NR/2]+v[NR/2+1])/2)}'; }

# Per case: wall and CPU seconds of chiaro and POV-Ray, one run per entry.
cw1=() cc1=() pw1=() pc1=() cw2=() cc2=() pw2=() pc2=()
for i in $(seq "$REPS"); do
    echo "== run $i"
    read -r w c < <(chiaro noaa --samples 1); cw1+=("$w"); cc1+=("$c")
    read -r w c < <(povray_trace noaa -A); pw1+=("$w"); pc1+=("$c")
    read -r w c < <(chiaro adaptive --adaptive); cw2+=("$w"); cc2+=("$c")
    read -r w c < <(povray_trace adaptive +A0.05 +AM2 +R4); pw2+=("$w"); pc2+=("$c")
done
report() { # $1 = label, $2 / $3 = chiaro / POV-Ray seconds, space-separated; $4 = what
    local mc mp
    mc=$(median <<<"$2")
    mp=$(median <<<"$3")
    printf '%s, %s: chiaro median %.3f s (%s), POV-Ray median %.3f s (%s), ratio %.2f\n' \
        "$1" "$4" "$mc" "$2" "$mp" "$3" "$(awk -v a="$mc" -v b="$mp" 'BEGIN {print a / b}')"
}
report "no AA, 1 ray per pixel" "${cw1[*]}" "${pw1[*]}" "render / trace time"
report "no AA, 1 ray per pixel" "${cc1[*]}" "${pc1[*]}" "CPU time"
report "adaptive AA (chiaro 0.05 / 3 levels, POV-Ray +A0.05 +AM2 +R4)" "${cw2[*]}" "${pw2[*]}" "render / trace time"
report "adaptive AA (chiaro 0.05 / 3 levels, POV-Ray +A0.05 +AM2 +R4)" "${cc2[*]}" "${pc2[*]}" "CPU time"
