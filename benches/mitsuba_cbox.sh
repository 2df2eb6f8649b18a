#!/bin/bash
# chiaro's path tracer vs Mitsuba 3 (scalar_rgb and llvm_ad_rgb) on Mitsuba's
# own Cornell box (mi.cornell_box(), 256x256, max depth 8 in Mitsuba's count =
# 7 scattering vertices in chiaro's), in one run:
#   1. the high-spp reference (llvm_ad_rgb, box pixel filter, cached under target/),
#   2. Mitsuba scalar_rgb and llvm_ad_rgb at 64 spp, with its default Gaussian
#      pixel filter (the issue's figures) and with a box filter (chiaro's),
#   3. chiaro at 64 spp and at equal time with llvm_ad_rgb (box filter),
#   4. the RMSE of every box-filtered image against the reference.
# usage: benches/mitsuba_cbox.sh [REPEATS=3] [REF_SPP=4096]
# CHIARO_PROFILE=dist builds chiaro with the workspace's thin-LTO profile
# (default: release).
# needs: a venv with mitsuba, numpy ($MITSUBA_VENV, default /tmp/mvenv) and
# Debian's libllvm19 for the llvm variant (apt-get install libllvm19).
set -euo pipefail
cd "$(dirname "$0")/.."
repeats=${1:-3}
ref_spp=${2:-4096}
venv=${MITSUBA_VENV:-/tmp/mvenv}
py="$venv/bin/python"
out=target/mitsuba-bench
mkdir -p "$out"
export DRJIT_LIBLLVM_PATH=${DRJIT_LIBLLVM_PATH:-/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1}
quiet=${WAIT_QUIET:-benches/wait_quiet.sh}

profile=${CHIARO_PROFILE:-release}
cargo build --profile "$profile" -q -p chiaro-ray --example path_bench
bench=target/$profile/examples/path_bench
# mitsuba_cbox.py builds Mitsuba's scene with `chiaro export` (benches/chiaro_export.py).
cargo build --release -q -p chiaro-cli
# The shipped scene must still be what Mitsuba's dict says.
"$py" benches/mitsuba_cbox_scene.py "$out/scene-check.toml"
cmp -s "$out/scene-check.toml" scenes/mitsuba-cbox.toml || {
    echo "scenes/mitsuba-cbox.toml differs from mi.cornell_box(): rerun benches/mitsuba_cbox_scene.py" >&2
    exit 1
}
ref="$out/ref_llvm_box_${ref_spp}spp.npy"
if [ ! -f "$ref" ]; then
    echo "rendering the ${ref_spp}-spp reference (cached in $ref)"
    "$py" benches/mitsuba_cbox.py render llvm_ad_rgb "$ref_spp" box 1000 "$ref" 1
fi

median() { grep -o 'render\[[0-9]*\]=[0-9.]*' "$1" | cut -d= -f2 | sort -n | awk '{a[NR]=$1} END {print a[int((NR+1)/2)]}'; }

[ -x "$quiet" ] && "$quiet" 180 || true
echo "chiaro profile: $profile; load before: $(cut -d' ' -f1-3 /proc/loadavg)"
for v in scalar_rgb llvm_ad_rgb; do
    for f in gaussian box; do
        "$py" benches/mitsuba_cbox.py render $v 64 $f 0 "$out/mi_${v}_${f}_64.npy" "$repeats" > "$out/mi_${v}_${f}.log"
    done
done
"$bench" scenes/mitsuba-cbox.toml "$out/chiaro_64" --spp 64 --repeats "$repeats" > "$out/chiaro_64.log"
t_llvm=$(median "$out/mi_llvm_ad_rgb_box.log")
t_chiaro=$(median "$out/chiaro_64.log")
spp_eq=$(awk -v a="$t_llvm" -v b="$t_chiaro" 'BEGIN { s = int(64 * a / b + 0.5); print (s < 1 ? 1 : s) }')
"$bench" scenes/mitsuba-cbox.toml "$out/chiaro_eq" --spp "$spp_eq" --repeats "$repeats" > "$out/chiaro_eq.log"
echo "load after: $(cut -d' ' -f1-3 /proc/loadavg)"

"$py" - "$ref" "$out" "$spp_eq" \
    "$(median "$out/mi_scalar_rgb_gaussian.log")" "$(median "$out/mi_scalar_rgb_box.log")" \
    "$(median "$out/mi_llvm_ad_rgb_gaussian.log")" "$t_llvm" "$t_chiaro" "$(median "$out/chiaro_eq.log")" <<'PY'
import sys
import numpy as np
ref_path, out, spp_eq = sys.argv[1], sys.argv[2], int(sys.argv[3])
t = [float(x) for x in sys.argv[4:]]
ref = np.load(ref_path).astype(np.float64)
pixels = ref.shape[0] * ref.shape[1]
# The emitter's pixels (radiance ~18 against ~0.2 elsewhere) and its edges,
# where pixel coverage is noisy, dominate the plain RMSE: also give it without them.
off_light = ref.max(axis=2) < 1.0
def rmse(p, mask=None):
    d2 = ((np.load(p).astype(np.float64) - ref) ** 2).mean(axis=2)
    return float(np.sqrt(d2[mask].mean() if mask is not None else d2.mean()))
rows = [
    ("Mitsuba scalar_rgb, gaussian filter", 64, t[0], None),
    ("Mitsuba scalar_rgb, box filter", 64, t[1], f"{out}/mi_scalar_rgb_box_64.npy"),
    ("Mitsuba llvm_ad_rgb, gaussian filter", 64, t[2], None),
    ("Mitsuba llvm_ad_rgb, box filter", 64, t[3], f"{out}/mi_llvm_ad_rgb_box_64.npy"),
    ("chiaro path", 64, t[4], f"{out}/chiaro_64.npy"),
    ("chiaro path, equal time", spp_eq, t[5], f"{out}/chiaro_eq.npy"),
]
llvm_rate = pixels * 64 / t[3]
llvm_rmse = rmse(rows[3][3])
print(f"reference: {ref_path}")
print("| renderer | spp | render s (median) | Msamples/s | vs llvm box | RMSE vs ref | RMSE x sqrt(time) | RMSE off the emitter |")
print("|---|---|---|---|---|---|---|---|")
for name, spp, secs, img in rows:
    rate = pixels * spp / secs
    e = rmse(img) if img else None
    es = f"{e:.5f}" if e is not None else "-"
    eff = f"{e * secs ** 0.5:.5f}" if e is not None else "-"
    off = f"{rmse(img, off_light):.5f}" if img else "-"
    print(f"| {name} | {spp} | {secs:.3f} | {rate / 1e6:.3f} | {rate / llvm_rate:.2f}x | {es} | {eff} | {off} |")
print(f"equal-time RMSE ratio chiaro / llvm_ad_rgb: {rmse(rows[5][3]) / llvm_rmse:.3f} "
      f"(off the emitter: {rmse(rows[5][3], off_light) / rmse(rows[3][3], off_light):.3f}); "
      f"{int((~off_light).sum())} emitter pixels")
PY
