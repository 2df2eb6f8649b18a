#!/usr/bin/env python3
"""Mitsuba 3 vs chiaro's path tracer on a glass-and-mirror Cornell box
(benches/glass_cbox.toml; Mitsuba's scene is that file through
`chiaro export`, benches/chiaro_export.py).

usage: mitsuba_glass.py scene OUT.toml
       mitsuba_glass.py render VARIANT SPP SEED OUT.npy [REPEATS] [--no-glass] [--no-mirror] [--no-point]
       mitsuba_glass.py compare REF.npy IMG.npy [IMG.npy ...]

The scene is Mitsuba's own Cornell box (mi.cornell_box(): walls, camera and
the ceiling's area emitter, as scenes/mitsuba-cbox.toml) with its two boxes
replaced by a glass sphere (chiaro: `transmit = 1`, `ior = 1.5`,
`fresnel = true`, no diffuse; Mitsuba: `dielectric`, int_ior 1.5,
ext_ior 1) and a mirror sphere (chiaro: `reflect = 1`, no diffuse, no
specular; Mitsuba: `conductor` with `material = "none"`, reflectance 1),
plus a point light under the ceiling. chiaro's point light of intensity Ip
gives the irradiance pi Ip cos / d^2 (ARCHITECTURE.md, radiometric
conventions), Mitsuba's `point` intensity is the radiant intensity itself:
Mitsuba gets pi Ip. Path tracer with max_depth 64 (chiaro's 63 scattering
vertices), Russian roulette from depth 5, box pixel filter, 256x256.

`scene` writes chiaro's scene file: scenes/mitsuba-cbox.toml (the walls,
camera and emitter verbatim) without its boxes, plus the spheres and the
point light below. `render` exports benches/glass_cbox.toml to Mitsuba
XML with `chiaro export` (build chiaro-cli in release first, or set
$CHIARO) and renders it with VARIANT (scalar_rgb |
llvm_ad_rgb), prints `render[i]=SECONDS s  M Msamples/s` per repeat (the
render call only, as mi.render + dr.eval + sync) and writes the last image
as .npy (float32, H x W x 3, linear RGB); the --no-* flags drop one part
(for bisecting a difference). `compare` prints, for each image against
REF, the relative difference of the whole image's mean per channel and of
each region's mean (fixed pixel boxes), and the RMSE.

The point light's caustic under the glass sphere (light -> glass -> glass
-> floor -> eye) needs a delta light seen through delta interfaces: no
unidirectional path tracer samples it, and both miss it alike. The
ceiling emitter's caustic is found by BSDF sampling in both.
"""
import os
import sys
import time
import numpy as np

import chiaro_export

HERE = os.path.dirname(os.path.abspath(__file__))
SCENE = os.path.join(HERE, "glass_cbox.toml")
CBOX = os.path.join(HERE, "..", "scenes", "mitsuba-cbox.toml")
W = H = 256
MITSUBA_DEPTH = 64  # path segments; chiaro's max_depth is one less
RR_DEPTH = 5
IOR = 1.5
GLASS = ([0.45, -0.64, 0.3], 0.35)  # centre, radius
MIRROR = ([-0.4, -0.55, -0.35], 0.44)
POINT = [0.0, 0.75, 0.3]  # position
POINT_IP = 0.5  # chiaro's intensity (colour white)

FLAGS = {f: f in sys.argv for f in ("--no-glass", "--no-mirror", "--no-point")}
sys.argv = [a for a in sys.argv if a not in FLAGS]


def fmt(v):
    return "[" + ", ".join(repr(float(x)) for x in v) + "]"


def chiaro_scene(out):
    """scenes/mitsuba-cbox.toml without its two boxes, with the spheres and
    the point light; render.path.max_depth set to MITSUBA_DEPTH - 1."""
    text = open(CBOX).read()
    head, *objects = text.split("[[object]]")
    objects = [o for o in objects if 'name = "small-box"' not in o and 'name = "large-box"' not in o]
    assert len(objects) == 6, "scenes/mitsuba-cbox.toml: expected 6 objects besides the boxes"
    head = head.replace("max_depth = 7\n", f"max_depth = {MITSUBA_DEPTH - 1}\n")
    head = head.replace("rr_depth = 5\n", f"rr_depth = {RR_DEPTH}\n")
    assert f"max_depth = {MITSUBA_DEPTH - 1}\n" in head
    body = "\n".join(line for line in head.splitlines() if not line.startswith("#")).lstrip("\n")
    lines = [
        "# A glass and a mirror sphere in Mitsuba 3's Cornell box, lit by its ceiling",
        "# emitter and a point light: written by benches/mitsuba_glass.py (`scene`),",
        "# which renders the same scene in Mitsuba. The walls, camera and emitter are",
        "# scenes/mitsuba-cbox.toml's; max_depth 63 = Mitsuba's 64 path segments.",
        "# Glass: Fresnel dielectric, ior 1.5 (Mitsuba `dielectric`); mirror: kr = 1",
        "# (Mitsuba `conductor`, material none). The point light's intensity Ip gives",
        "# the irradiance pi Ip cos / d^2: Mitsuba's radiant intensity is pi Ip.",
        "",
        body.rstrip("\n"),
        "",
        "[material.glass]",
        "diffuse = 0",
        "transmit = 1",
        f"ior = {IOR}",
        "fresnel = true",
        "",
        "[material.mirror]",
        "diffuse = 0",
        "reflect = 1",
        "",
        "[[light]]",
        'type = "point"',
        f"position = {fmt(POINT)}",
        f"intensity = {POINT_IP}",
        'attenuation = "inverse_square"',
        "",
    ]
    text = "\n".join(lines) + "\n" + "".join("[[object]]" + o for o in objects).rstrip("\n") + "\n"
    for name, (c, r), m in (("glass-sphere", GLASS, "glass"), ("mirror-sphere", MIRROR, "mirror")):
        text += (
            f'\n[[object]]\nname = "{name}"\nprimitive = "sphere"\nradius = {r}\n'
            f'material = "{m}"\ntransform = {{ translate = {fmt(c)} }}\n'
        )
    with open(out, "w") as f:
        f.write(text)


def render(variant, spp, seed, out, repeats):
    import mitsuba as mi
    import drjit as dr

    mi.set_variant(variant)
    # The scene chiaro renders, through `chiaro export` (the sample count
    # is the render call's).
    drop = [name for flag, name in (("--no-glass", "glass-sphere"), ("--no-mirror", "mirror-sphere"),
                                     ("--no-point", "point")) if FLAGS[flag]]
    scene = chiaro_export.load(mi, SCENE, drop)
    img = None
    for i in range(repeats):
        t0 = time.perf_counter()
        img = mi.render(scene, spp=spp, seed=seed + i)
        dr.eval(img)
        dr.sync_thread()
        t = time.perf_counter() - t0
        print(f"render[{i}]={t:.3f}s  {W * H * spp / t / 1e6:.3f} Msamples/s", flush=True)
    np.save(out, np.array(img, dtype=np.float32)[:, :, :3])


# Pixel boxes (x0, y0, x1, y1) at 256x256, inside each region.
REGIONS = {
    "ceiling emitter": (116, 32, 140, 37),
    "ceiling": (60, 12, 100, 24),
    "red wall": (14, 80, 30, 140),
    "green wall": (226, 80, 242, 140),
    "back wall": (110, 60, 150, 100),
    "floor (front)": (40, 240, 120, 252),
    "glass sphere": (160, 178, 186, 204),
    "mirror sphere": (80, 160, 108, 188),
    "under the glass": (150, 222, 200, 234),
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
            a = img[y0:y1, x0:x1].mean(axis=(0, 1))
            b = ref[y0:y1, x0:x1].mean(axis=(0, 1))
            print(f"  {name:16s} {a.mean():.5f} vs {b.mean():.5f}  {100 * (a.mean() / b.mean() - 1):+.2f}%"
                  f"  (r g b {' '.join(f'{100 * (x / y - 1):+.2f}%' for x, y in zip(a, b))})")


def main():
    if len(sys.argv) == 3 and sys.argv[1] == "scene":
        chiaro_scene(sys.argv[2])
    elif len(sys.argv) >= 6 and sys.argv[1] == "render":
        repeats = int(sys.argv[6]) if len(sys.argv) > 6 else 1
        render(sys.argv[2], int(sys.argv[3]), int(sys.argv[4]), sys.argv[5], repeats)
    elif len(sys.argv) >= 4 and sys.argv[1] == "compare":
        compare(sys.argv[2], sys.argv[3:])
    else:
        print(__doc__)
        sys.exit(2)


if __name__ == "__main__":
    main()
