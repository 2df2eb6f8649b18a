#!/usr/bin/env python3
"""Reference images for chiaro's Mitsuba agreement test (issue 45, item 6).

usage: mitsuba_agreement_refs.py [--spp N] [--variant V] [--only STEM] [--textures]

Renders every `*_path.xml` in crates/chiaro/tests/data/mitsuba-agreement/
with Mitsuba 3 (the scenes wrap `path` in the `moment` integrator) and
writes, as Mitsuba's own render tests do (src/render/tests/test_renders.py),
`refs/STEM_ref_rgb.exr`, the mean, and `refs/STEM_ref_rgb_var.exr`, the
per-sample variance (second moment minus the squared mean), both computed in
XYZ by the moment integrator and stored converted to linear RGB. STEM is the
file name without `_path.xml`. The test (crates/chiaro/tests/
mitsuba_agreement.rs) renders the same files with chiaro's path tracer and
applies Mitsuba's z-test against them.

--spp defaults to 131072 (Mitsuba's own references use 32000; more keeps
the reference's own noise near 1.5 % of the z statistic at the test's 1953
spp); --variant to llvm_ad_rgb (scalar_rgb where LLVM is absent); the seed
is 0. --only renders the scene STEM alone. --textures also (re)writes the
two textures the scenes read: sky.exr, a lat-long sky with a sun and a
darker ground, smooth in v, and tiles.png, an 8x8 sRGB tile pattern; both
are generated here, deterministically.
"""
import argparse
import glob
import os

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
DATA = os.path.join(HERE, "..", "crates", "chiaro", "tests", "data", "mitsuba-agreement")


def write_textures(mi):
    """sky.exr (128x64, linear RGB, half floats) and tiles.png (8x8, sRGB)
    beside the scenes."""
    w, h = 128, 64
    v = (np.arange(h) + 0.5) / h
    u = (np.arange(w) + 0.5) / w
    theta = v[:, None] * np.pi
    phi = u[None, :] * 2.0 * np.pi
    up = np.cos(theta)  # the map's +y
    # Smooth in v (a few texels per feature), so that the test sees the
    # row placement rather than how a discontinuity between rows is
    # interpolated: a blue-to-white sky, a brown ground blended in over the
    # horizon, orange bands around it varying in u, and a Gaussian sun.
    s = 0.5 + 0.5 * np.tanh(up / 0.2)
    t = np.clip(up, 0.0, 1.0)
    sky = np.zeros((h, w, 3), np.float32)
    for c, (top, hor, ground, band) in enumerate(
        [(0.25, 0.9, 0.35, 0.9), (0.45, 0.9, 0.25, 0.4), (1.0, 0.95, 0.15, 0.2)]
    ):
        base = s * (hor + (top - hor) * t) + (1.0 - s) * ground
        k = np.exp(-((up / 0.3) ** 2)) * (0.5 + 0.5 * np.sin(3.0 * phi))
        sky[..., c] = (1.0 - k) * base + k * band
    # The sun: a Gaussian of about three texels around (u, v) = (0.33, 0.22).
    du = (u[None, :] - 0.33) * w
    dv = (v[:, None] - 0.22) * h
    sun = np.exp(-(du**2 + dv**2) / (2.0 * 3.0**2))
    for c, e in enumerate([40.0, 36.0, 30.0]):
        sky[..., c] += e * sun
    bmp = mi.Bitmap(sky, mi.Bitmap.PixelFormat.RGB)
    bmp.convert(mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.Float16, False).write(
        os.path.join(DATA, "sky.exr")
    )
    tiles = np.zeros((8, 8, 3), np.uint8)
    for j in range(8):
        for i in range(8):
            tiles[j, i] = [(200, 190, 170), (60, 90, 140), (170, 60, 50)][(i + 2 * j) % 3]
    mi.Bitmap(tiles, mi.Bitmap.PixelFormat.RGB).write(os.path.join(DATA, "tiles.png"))


def mean_and_variance(bmp):
    """The moment integrator's mean and per-sample variance (XYZ, H x W x 3)."""
    # Its layers: the film's own, then the nested integrator's mean and
    # second moment (named after the nested integrator).
    layers = bmp.split()
    mean = np.array(layers[1][1], copy=True)
    m2 = np.array(layers[2][1], copy=True)
    return mean, m2 - mean * mean


def xyz_to_rgb(mi, img):
    xyz = mi.Bitmap(img.astype(np.float32), mi.Bitmap.PixelFormat.XYZ)
    return xyz.convert(mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.Float32, False)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--spp", type=int, default=131072)
    ap.add_argument("--variant", default=None)
    ap.add_argument("--only", default=None, metavar="STEM")
    ap.add_argument("--textures", action="store_true")
    args = ap.parse_args()
    import mitsuba as mi

    variant = args.variant
    if variant is None:
        variant = "llvm_ad_rgb" if "llvm_ad_rgb" in mi.variants() else "scalar_rgb"
    mi.set_variant(variant)
    if args.textures:
        write_textures(mi)
    os.makedirs(os.path.join(DATA, "refs"), exist_ok=True)
    for path in sorted(glob.glob(os.path.join(DATA, "*_path.xml"))):
        stem = os.path.basename(path)[: -len("_path.xml")]
        if args.only and args.only != stem:
            continue
        scene = mi.load_file(path, spp=args.spp)
        scene.integrator().render(scene, seed=0, spp=args.spp, develop=False)
        bmp = scene.sensors()[0].film().bitmap(raw=False)
        mean, var = mean_and_variance(bmp)
        xyz_to_rgb(mi, mean).write(os.path.join(DATA, "refs", f"{stem}_ref_rgb.exr"))
        xyz_to_rgb(mi, var).write(os.path.join(DATA, "refs", f"{stem}_ref_rgb_var.exr"))
        print(f"{stem}: {variant}, {args.spp} spp, mean {mean.mean(axis=(0, 1))}", flush=True)


if __name__ == "__main__":
    main()
