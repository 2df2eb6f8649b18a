#!/bin/bash
# chiaro's path tracer vs Mitsuba 3 on the glass-and-mirror Cornell box
# (benches/glass_cbox.toml = benches/mitsuba_glass.py's Mitsuba dict; 256x256,
# max depth 64 in Mitsuba's count = 63 scattering vertices in chiaro's, box
# pixel filter), in one run:
#   1. the scene file is checked against what mitsuba_glass.py writes,
#   2. correctness: a converged Mitsuba reference (llvm_ad_rgb, REF_SPP) and
#      chiaro at CHIARO_SPP (both cached under target/mitsuba-glass), compared
#      by whole-image and region means,
#   3. speed at 64 spp, REPEATS rounds alternating Mitsuba llvm_ad_rgb (two
#      renders per process, the second timed: the first compiles its kernels),
#      Mitsuba scalar_rgb and chiaro path_bench (2 threads, median of 2), then
#      the medians of the render times and of the per-round ratio,
#   4. chiaro at equal time with llvm_ad_rgb, and the RMSE of each 64-spp image
#      against the reference (whose own noise is in the figures).
# usage: benches/mitsuba_glass.sh [REPEATS=3] [REF_SPP=4096] [CHIARO_SPP=1024]
# MITSUBA_BENCH=env runs the same steps on the environment-lit glossy scene
# instead (benches/env_spheres.toml, built in Mitsuba by benches/mitsuba_env.py;
# 256x192, max depth 8; no scene-file check, the TOML is written by hand).
# needs: a venv with mitsuba, numpy ($MITSUBA_VENV, default /tmp/mvenv) and
# Debian's libllvm19 for the llvm variant.
set -euo pipefail
cd "$(dirname "$0")/.."
repeats=${1:-3}
ref_spp=${2:-4096}
chiaro_spp=${3:-1024}
venv=${MITSUBA_VENV:-/tmp/mvenv}
py="$venv/bin/python"
case "${MITSUBA_BENCH:-glass}" in
    glass) mod=benches/mitsuba_glass.py scene=benches/glass_cbox.toml out=target/mitsuba-glass ;;
    env) mod=benches/mitsuba_env.py scene=benches/env_spheres.toml out=target/mitsuba-env ;;
    *) echo "MITSUBA_BENCH: expected glass or env" >&2; exit 2 ;;
esac
mkdir -p "$out"
export DRJIT_LIBLLVM_PATH=${DRJIT_LIBLLVM_PATH:-/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1}

cargo build --release -q -p chiaro-ray --example path_bench
bench=target/release/examples/path_bench
if [ "$mod" = benches/mitsuba_glass.py ]; then
    "$py" "$mod" scene "$out/scene-check.toml"
    cmp -s "$out/scene-check.toml" "$scene" || {
        echo "$scene differs from $mod's scene: rerun its \`scene\` command" >&2
        exit 1
    }
fi

ref="$out/ref_llvm_${ref_spp}spp.npy"
if [ ! -f "$ref" ]; then
    echo "rendering the ${ref_spp}-spp Mitsuba reference (cached in $ref)"
    "$py" "$mod" render llvm_ad_rgb "$ref_spp" 1000 "$ref" 1 | tee "$out/ref.log"
fi
high="$out/chiaro_${chiaro_spp}"
if [ ! -f "$high.npy" ]; then
    echo "rendering chiaro at ${chiaro_spp} spp (cached in $high.npy)"
    "$bench" "$scene" "$high" --spp "$chiaro_spp" --threads 2 --seed 7 | tee "$out/chiaro_high.log"
fi
echo "== correctness: chiaro ${chiaro_spp} spp against Mitsuba ${ref_spp} spp"
"$py" "$mod" compare "$ref" "$high.npy"

secs() { grep -o "$2=[0-9.]*" "$1" | tail -1 | cut -d= -f2; }
echo "== speed, 64 spp, $repeats rounds; load before: $(cut -d' ' -f1-3 /proc/loadavg)"
: > "$out/rounds.txt"
for r in $(seq 1 "$repeats"); do
    "$py" "$mod" render llvm_ad_rgb 64 0 "$out/mi_llvm_64.npy" 2 > "$out/mi_llvm_$r.log"
    "$py" "$mod" render scalar_rgb 64 0 "$out/mi_scalar_64.npy" 1 > "$out/mi_scalar_$r.log"
    "$bench" "$scene" "$out/chiaro_64" --spp 64 --threads 2 --repeats 2 > "$out/chiaro_64_$r.log"
    tl=$(secs "$out/mi_llvm_$r.log" 'render\[1\]')
    ts=$(secs "$out/mi_scalar_$r.log" 'render\[0\]')
    tc=$(secs "$out/chiaro_64_$r.log" median)
    echo "$tl $ts $tc" | tee -a "$out/rounds.txt"
done
echo "load after: $(cut -d' ' -f1-3 /proc/loadavg)"
med() { cut -d' ' -f"$1" "$out/rounds.txt" | sort -n | awk '{a[NR]=$1} END {print a[int((NR+1)/2)]}'; }
t_llvm=$(med 1)
t_scalar=$(med 2)
t_chiaro=$(med 3)
spp_eq=$(awk -v a="$t_llvm" -v b="$t_chiaro" 'BEGIN { s = int(64 * a / b + 0.5); print (s < 1 ? 1 : s) }')
"$bench" "$scene" "$out/chiaro_eq" --spp "$spp_eq" --threads 2 --repeats 1 > "$out/chiaro_eq.log"
t_eq=$(secs "$out/chiaro_eq.log" median)

"$py" - "$ref" "$out" "$spp_eq" "$t_scalar" "$t_llvm" "$t_chiaro" "$t_eq" <<'PY'
import sys
import numpy as np
ref_path, out, spp_eq = sys.argv[1], sys.argv[2], int(sys.argv[3])
t = [float(x) for x in sys.argv[4:]]
ref = np.load(ref_path).astype(np.float64)
pixels = ref.shape[0] * ref.shape[1]
rounds = np.loadtxt(f"{out}/rounds.txt", ndmin=2)
ratio = np.median(rounds[:, 0] / rounds[:, 2])
ratio_s = np.median(rounds[:, 1] / rounds[:, 2])
# The brightest pixels (radiance above 3: the glass box's emitter and the
# point light's hotspot, the environment's lamps seen in the metals) dominate
# the plain RMSE: also give it without them.
off_light = ref.max(axis=2) < 3.0
def rmse(p, mask=None):
    d2 = ((np.load(p).astype(np.float64) - ref) ** 2).mean(axis=2)
    return float(np.sqrt(d2[mask].mean() if mask is not None else d2.mean()))
rows = [
    ("Mitsuba scalar_rgb", 64, t[0], f"{out}/mi_scalar_64.npy"),
    ("Mitsuba llvm_ad_rgb", 64, t[1], f"{out}/mi_llvm_64.npy"),
    ("chiaro path", 64, t[2], f"{out}/chiaro_64.npy"),
    ("chiaro path, equal time", spp_eq, t[3], f"{out}/chiaro_eq.npy"),
]
llvm_rate = pixels * 64 / t[1]
print(f"reference: {ref_path}; rounds (llvm s, scalar s, chiaro s):")
for r in rounds:
    print("  " + " ".join(f"{x:.3f}" for x in r) + f"  ratio {r[0] / r[2]:.3f}")
print("| renderer | spp | render s (median) | Msamples/s | vs llvm | RMSE vs ref | RMSE x sqrt(time) | RMSE off the bright spots |")
print("|---|---|---|---|---|---|---|---|")
for name, spp, secs, img in rows:
    rate = pixels * spp / secs
    e = rmse(img)
    print(f"| {name} | {spp} | {secs:.3f} | {rate / 1e6:.3f} | {rate / llvm_rate:.2f}x | {e:.5f} | "
          f"{e * secs ** 0.5:.5f} | {rmse(img, off_light):.5f} |")
print(f"median per-round ratio chiaro / llvm_ad_rgb samples/s: {ratio:.3f}; chiaro / scalar_rgb: {ratio_s:.3f}")
print(f"equal-time RMSE ratio chiaro / llvm_ad_rgb: {rmse(rows[3][3]) / rmse(rows[1][3]):.3f} "
      f"(off the bright spots: {rmse(rows[3][3], off_light) / rmse(rows[1][3], off_light):.3f}); "
      f"{int((~off_light).sum())} bright pixels")
PY
