#!/usr/bin/env python3
"""Mitsuba 3 vs chiaro's path tracer on Mitsuba's own Cornell box.

usage: mitsuba_cbox.py render VARIANT SPP FILTER SEED OUT.npy [REPEATS]
       mitsuba_cbox.py compare REF.npy IMG.npy [IMG.npy ...]
       mitsuba_cbox.py regions IMG.npy [IMG.npy ...]

`render` renders Mitsuba's own Cornell box as chiaro renders it:
scenes/mitsuba-cbox.toml (written from mi.cornell_box() by
mitsuba_cbox_scene.py, which mitsuba_cbox.sh checks) exported by
`chiaro export --to mitsuba` (benches/chiaro_export.py; 256x256, path,
max_depth 8 in Mitsuba's count; sampler from $MITSUBA_SAMPLER, default the
export's `independent`) with VARIANT
(scalar_rgb | llvm_ad_rgb) and pixel FILTER (box | gaussian, Mitsuba's
default), prints `render[i]=SECONDS s  M Msamples/s` per repeat (the render
call only, as mi.render + dr.eval + sync) and writes the last image as .npy
(float32, H x W x 3, linear RGB).
MITSUBA_LLVM_AVX2=1 makes llvm_ad_rgb's JIT compile 8-wide AVX2 kernels
(CPU `haswell`) instead of the host's own choice (16-wide on an AVX-512
host), through Dr.Jit's `jit_llvm_set_target`, which its Python module does
not expose; Embree, inside Mitsuba, still picks its own kernels.
`compare` prints the RMSE (over all pixels and channels) of each image
against REF, and its mean. `regions` prints the mean colour of a few
regions (walls, floor, boxes, light) for checking that two scenes match.
"""
import os
import sys
import time
import numpy as np

import chiaro_export

CBOX = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "scenes", "mitsuba-cbox.toml")


def llvm_avx2(dr):
    """Dr.Jit's LLVM backend set to 8-wide AVX2 kernels (see the docstring)."""
    import ctypes

    core = ctypes.CDLL(os.path.join(os.path.dirname(dr.__file__), "libdrjit-core.so"))
    # jit_llvm_set_target(const char *cpu, const char *features, uint32_t vector_width)
    core._Z19jit_llvm_set_targetPKcS0_j(
        b"haswell", b"+avx,+avx2,+fma,+f16c,+sse4.2,+popcnt,+bmi,+bmi2,+lzcnt,+movbe,-avx512f", 8
    )
    core._Z19jit_llvm_target_cpuv.restype = ctypes.c_char_p
    core._Z21jit_llvm_vector_widthv.restype = ctypes.c_uint32
    cpu, width = core._Z19jit_llvm_target_cpuv(), core._Z21jit_llvm_vector_widthv()
    print(f"llvm target {cpu.decode()} width {width}", flush=True)


def render(variant, spp, filt, seed, out, repeats):
    import mitsuba as mi
    import drjit as dr

    mi.set_variant(variant)
    if os.environ.get("MITSUBA_LLVM_AVX2") == "1" and variant.startswith("llvm"):
        llvm_avx2(dr)
    sampler = os.environ.get("MITSUBA_SAMPLER")

    def edit(xml):
        # MITSUBA_SAMPLER=multijitter|ldsampler|stratified|orthogonal replaces
        # the export's `independent` sampler (for comparing like with like);
        # FILTER replaces its box filter (chiaro's).
        if sampler:
            xml = xml.replace('<sampler type="independent">', f'<sampler type="{sampler}">')
        return xml.replace('<rfilter type="box"/>', f'<rfilter type="{filt}"/>')

    scene = chiaro_export.load(mi, CBOX, edit=edit)
    w, h = scene.sensors()[0].film().size()
    img = None
    for i in range(repeats):
        t0 = time.perf_counter()
        img = mi.render(scene, spp=spp, seed=seed + i)
        dr.eval(img)
        dr.sync_thread()
        t = time.perf_counter() - t0
        print(f"render[{i}]={t:.3f}s  {w * h * spp / t / 1e6:.3f} Msamples/s", flush=True)
    np.save(out, np.array(img, dtype=np.float32))


REGIONS = {  # (y0, y1, x0, x1) in the 256x256 image
    "light": (32, 38, 112, 144),
    "ceiling": (12, 24, 60, 100),
    "red wall": (80, 160, 14, 30),
    "green wall": (80, 160, 226, 242),
    "back wall": (60, 100, 110, 150),
    "floor": (232, 250, 100, 160),
    "tall box front": (100, 160, 60, 90),
    "short box top": (170, 180, 160, 190),
}


def main():
    cmd = sys.argv[1]
    if cmd == "render":
        variant, spp, filt, seed, out = sys.argv[2], int(sys.argv[3]), sys.argv[4], int(sys.argv[5]), sys.argv[6]
        repeats = int(sys.argv[7]) if len(sys.argv) > 7 else 1
        render(variant, spp, filt, seed, out, repeats)
    elif cmd == "compare":
        ref = np.load(sys.argv[2]).astype(np.float64)
        for p in sys.argv[3:]:
            img = np.load(p).astype(np.float64)
            rmse = np.sqrt(np.mean((img - ref) ** 2))
            print(f"{p}: rmse={rmse:.5f} mean={img.mean():.5f} ref_mean={ref.mean():.5f}")
    elif cmd == "regions":
        imgs = [np.load(p).astype(np.float64) for p in sys.argv[2:]]
        for name, (y0, y1, x0, x1) in REGIONS.items():
            row = "  ".join(
                "[" + " ".join(f"{v:.4f}" for v in im[y0:y1, x0:x1].reshape(-1, 3).mean(0)) + "]" for im in imgs
            )
            print(f"{name:15s} {row}")
    else:
        raise SystemExit(__doc__)


if __name__ == "__main__":
    main()
