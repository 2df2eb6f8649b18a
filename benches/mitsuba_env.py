#!/usr/bin/env python3
"""Mitsuba 3 vs chiaro's path tracer on an environment-lit glossy scene
(benches/env_spheres.toml; Mitsuba's scene is that file through
`chiaro export`, benches/chiaro_export.py).

usage: mitsuba_env.py render VARIANT SPP SEED OUT.npy [REPEATS]
       mitsuba_env.py compare REF.npy IMG.npy [IMG.npy ...]

`render` exports benches/env_spheres.toml to Mitsuba XML with `chiaro
export` (build chiaro-cli in release first, or set $CHIARO) and renders it
with VARIANT (scalar_rgb | llvm_ad_rgb), path tracer with max_depth 8
(chiaro's 7 scattering vertices), Russian roulette from depth 5, box pixel
filter, and writes the image as .npy (float32, H x W x 3, linear RGB).
`compare` prints, for each image against REF, the relative difference of
the whole image's mean per channel and of the mean of each region
(background, floor, the three spheres: fixed pixel boxes at 256x192), and
the RMSE.

What the exporter does for this scene: chiaro's lat-long lookup puts -z at
u = 0.5, Mitsuba's `envmap` puts -z at u = 0, so Mitsuba's map is turned
180 degrees about +y. Both place texel column i at u = (i + 0.5) / W, but
Mitsuba places row j at v = j / (H - 1) (rows span the poles) where chiaro
places it at (j + 0.5) / H, so the exporter writes the map resampled to
2H + 1 rows at v = j / 2H, each row chiaro's bilinear lookup there (its
knots are every other row, so Mitsuba's linear interpolation between the
rows is chiaro's lookup exactly). The floor is a PLY mesh of chiaro's quad.
The metals: chiaro's Torrance-Sparrow with F0 = 1 (Schlick's Fresnel is
then 1) and alpha = roughness, Mitsuba's `roughconductor` with eta 0, k 1
(Mitsuba's `none`, Fresnel 1), GGX, separable Smith masking in both.
"""
import os
import sys
import time
import numpy as np

import chiaro_export

HERE = os.path.dirname(os.path.abspath(__file__))
SCENE = os.path.join(HERE, "env_spheres.toml")
W, H = 256, 192


def render(variant, spp, seed, out, repeats):
    import mitsuba as mi
    import drjit as dr

    mi.set_variant(variant)
    # The scene chiaro renders, through `chiaro export` (the sample count
    # is the render call's).
    scene = chiaro_export.load(mi, SCENE)
    img = None
    for i in range(repeats):
        t0 = time.perf_counter()
        img = mi.render(scene, spp=spp, seed=seed + i)
        dr.eval(img)
        dr.sync_thread()
        t = time.perf_counter() - t0
        print(f"render[{i}]={t:.3f}s  {W * H * spp / t / 1e6:.3f} Msamples/s", flush=True)
    np.save(out, np.array(img, dtype=np.float32)[:, :, :3])


# Pixel boxes (x0, y0, x1, y1) at 256x192, inside each region.
REGIONS = {
    "background": (0, 0, 256, 40),
    "floor": (20, 150, 236, 190),
    "matte sphere": (40, 85, 70, 115),
    "rough sphere": (113, 85, 143, 115),
    "glossy sphere": (186, 85, 216, 115),
}


def compare(ref_path, paths):
    ref = np.load(ref_path).astype(np.float64)
    for p in paths:
        img = np.load(p).astype(np.float64)
        rmse = np.sqrt(np.mean((img - ref) ** 2))
        rel = img.mean(axis=(0, 1)) / ref.mean(axis=(0, 1)) - 1
        print(f"{p}: RMSE {rmse:.5f}; image mean {img.mean():.5f} vs {ref.mean():.5f}, "
              f"per channel {' '.join(f'{100 * r:+.2f}%' for r in rel)}")
        for name, (x0, y0, x1, y1) in REGIONS.items():
            a = img[y0:y1, x0:x1].mean()
            b = ref[y0:y1, x0:x1].mean()
            print(f"  {name:14s} {a:.5f} vs {b:.5f}  {100 * (a / b - 1):+.2f}%")


def main():
    if len(sys.argv) >= 6 and sys.argv[1] == "render":
        repeats = int(sys.argv[6]) if len(sys.argv) > 6 else 1
        render(sys.argv[2], int(sys.argv[3]), int(sys.argv[4]), sys.argv[5], repeats)
    elif len(sys.argv) >= 4 and sys.argv[1] == "compare":
        compare(sys.argv[2], sys.argv[3:])
    else:
        print(__doc__)
        sys.exit(2)


if __name__ == "__main__":
    main()
