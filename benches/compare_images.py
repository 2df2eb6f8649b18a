#!/usr/bin/env python3
"""Compares two linear OpenEXR renders of a scene made of spheres and planes.

    benches/compare_images.py A.exr B.exr [--scene scenes/whitted.toml] [--out DIR]

Prints the mean absolute difference (over pixels and RGB channels), the
share of pixels whose largest channel difference is within 1/255 and 5/255,
and the mean colour of each renderer per region (each `[[object]]` by its
material name, and `sky`), where a pixel's region is what the ray through its
centre hits first (ray-cast here from the scene's camera). With --out, writes
A.png, B.png (clamped, sRGB) and diff.png (|A - B| x 10) there.

Standard library only: reads scan-line EXR files with NONE, ZIPS or ZIP
compression and HALF or FLOAT channels (what chiaro and POV-Ray write).
"""

import argparse
import math
import os
import struct
import sys
import tomllib
import zlib

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def read_exr(path):
    """(width, height, [(r, g, b)] row-major from the top) of an EXR file."""
    data = open(path, "rb").read()
    if data[:4] != b"\x76\x2f\x31\x01":
        raise ValueError(f"{path}: not an OpenEXR file")
    if data[5] & 0x02:
        raise ValueError(f"{path}: tiled EXR files are not supported")
    pos, attrs = 8, {}
    while data[pos] != 0:
        end = data.index(b"\0", pos)
        name = data[pos:end].decode()
        end2 = data.index(b"\0", end + 1)
        kind = data[end + 1 : end2].decode()
        (size,) = struct.unpack_from("<i", data, end2 + 1)
        attrs[name] = (kind, data[end2 + 5 : end2 + 5 + size])
        pos = end2 + 5 + size
    pos += 1
    channels, raw = [], attrs["channels"][1]
    p = 0
    while raw[p] != 0:
        end = raw.index(b"\0", p)
        name = raw[p:end].decode()
        ptype, _, xs, ys = struct.unpack_from("<iiii", raw, end + 1)
        if (xs, ys) != (1, 1):
            raise ValueError(f"{path}: subsampled channel {name}")
        channels.append((name, ptype))
        p = end + 17
    compression = attrs["compression"][1][0]
    lines_per_block = {0: 1, 2: 1, 3: 16}.get(compression)
    if lines_per_block is None:
        raise ValueError(f"{path}: compression {compression} is not supported (NONE, ZIPS, ZIP are)")
    x0, y0, x1, y1 = struct.unpack("<iiii", attrs["dataWindow"][1])
    w, h = x1 - x0 + 1, y1 - y0 + 1
    sizes = {0: 4, 1: 2, 2: 4}
    fmts = {0: "I", 1: "e", 2: "f"}
    nblocks = (h + lines_per_block - 1) // lines_per_block
    offsets = struct.unpack_from(f"<{nblocks}Q", data, pos)
    want = {"R": 0, "G": 1, "B": 2}
    pixels = [[0.0, 0.0, 0.0] for _ in range(w * h)]
    for off in offsets:
        y, n = struct.unpack_from("<ii", data, off)
        block = data[off + 8 : off + 8 + n]
        lines = min(lines_per_block, y1 - y + 1)
        full = lines * w * sum(sizes[t] for _, t in channels)
        if compression != 0 and n < full:
            block = unzip(block)
        q = 0
        for line in range(lines):
            row = (y - y0 + line) * w
            for name, ptype in channels:
                size = sizes[ptype]
                vals = struct.unpack_from(f"<{w}{fmts[ptype]}", block, q)
                q += w * size
                c = want.get(name)
                if c is not None:
                    for x, v in enumerate(vals):
                        pixels[row + x][c] = float(v)
    return w, h, pixels


def unzip(block):
    """EXR's ZIP: zlib, then undo the byte delta predictor and interleave."""
    t = bytearray(zlib.decompress(block))
    for i in range(1, len(t)):
        t[i] = (t[i - 1] + t[i] - 128) & 0xFF
    half = (len(t) + 1) // 2
    out = bytearray(len(t))
    out[0::2] = t[:half]
    out[1::2] = t[half:]
    return bytes(out)


def write_png(path, w, h, rgb):
    """8-bit sRGB PNG of linear (r, g, b) values, clamped to [0, 1]."""

    def enc(v):
        v = min(max(v, 0.0), 1.0)
        s = 12.92 * v if v <= 0.0031308 else 1.055 * v ** (1 / 2.4) - 0.055
        return int(round(s * 255))

    raw = bytearray()
    for y in range(h):
        raw.append(0)
        for r, g, b in rgb[y * w : (y + 1) * w]:
            raw += bytes((enc(r), enc(g), enc(b)))

    def chunk(kind, body):
        c = struct.pack(">I", len(body)) + kind + body
        return c + struct.pack(">I", zlib.crc32(kind + body) & 0xFFFFFFFF)

    png = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
    png += chunk(b"IDAT", zlib.compress(bytes(raw), 6)) + chunk(b"IEND", b"")
    open(path, "wb").write(png)


def sub(a, b):
    return [a[0] - b[0], a[1] - b[1], a[2] - b[2]]


def dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def norm(a):
    n = math.sqrt(dot(a, a))
    return [a[0] / n, a[1] / n, a[2] / n]


def regions(scene_path, w, h):
    """Per pixel, the name of what the pixel-centre ray hits first."""
    scene = tomllib.load(open(scene_path, "rb"))
    cam = scene.get("camera", {})
    eye = [float(x) for x in cam.get("eye", [0, 0, 5])]
    fwd = norm(sub([float(x) for x in cam.get("look_at", [0, 0, 0])], eye))
    right = norm(cross(fwd, [float(x) for x in cam.get("up", [0, 1, 0])]))
    up = cross(right, fwd)
    th = math.tan(math.radians(float(cam.get("fov", 45))) / 2)
    shapes = []
    for obj in scene.get("object", []):
        t = [float(x) for x in obj.get("transform", {}).get("translate", [0, 0, 0])]
        name = obj.get("material", "?")
        if obj["primitive"] == "sphere":
            shapes.append(("sphere", name, t, float(obj.get("radius", 1.0))))
        elif obj["primitive"] == "plane":
            shapes.append(("plane", name, t, 0.5 * float(obj.get("size", 2.0))))
    out = []
    for y in range(h):
        ny = (1 - 2 * (y + 0.5) / h) * th
        for x in range(w):
            nx = (2 * (x + 0.5) / w - 1) * th * w / h
            d = norm([fwd[i] + nx * right[i] + ny * up[i] for i in range(3)])
            best, hit = math.inf, "sky"
            for kind, name, c, r in shapes:
                if kind == "sphere":
                    oc = sub(eye, c)
                    b = dot(oc, d)
                    disc = b * b - (dot(oc, oc) - r * r)
                    if disc >= 0:
                        t = -b - math.sqrt(disc)
                        if 1e-6 < t < best:
                            best, hit = t, name
                elif abs(d[1]) > 1e-12:
                    t = (c[1] - eye[1]) / d[1]
                    px, pz = eye[0] + t * d[0] - c[0], eye[2] + t * d[2] - c[2]
                    if 1e-6 < t < best and abs(px) <= r and abs(pz) <= r:
                        best, hit = t, name
            out.append(hit)
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("a")
    ap.add_argument("b")
    ap.add_argument("--scene", default=os.path.join(ROOT, "scenes", "whitted.toml"))
    ap.add_argument("--out", help="folder for A.png, B.png and diff.png")
    args = ap.parse_args()
    wa, ha, a = read_exr(args.a)
    wb, hb, b = read_exr(args.b)
    if (wa, ha) != (wb, hb):
        sys.exit(f"sizes differ: {wa}x{ha} and {wb}x{hb}")
    w, h = wa, ha
    n = w * h
    diffs = [max(abs(p - q) for p, q in zip(pa, pb)) for pa, pb in zip(a, b)]
    mad = sum(sum(abs(p - q) for p, q in zip(pa, pb)) for pa, pb in zip(a, b)) / (3 * n)
    within1 = sum(d <= 1 / 255 for d in diffs) / n
    within5 = sum(d <= 5 / 255 for d in diffs) / n
    print(f"{w}x{h}: mean |A - B| {mad:.5f}; pixels within 1/255 {100 * within1:.2f} %, "
          f"within 5/255 {100 * within5:.2f} %; largest {max(diffs):.4f}")
    # A pixel over 1/255 whose colour one of the other image's 3x3 neighbours
    # has (within 1/255, both ways) differs by where an edge falls in it.
    def near(img, other, i):
        x, y = i % w, i // w
        for dy in (-1, 0, 1):
            for dx in (-1, 0, 1):
                if 0 <= x + dx < w and 0 <= y + dy < h:
                    q = other[(y + dy) * w + x + dx]
                    if max(abs(p - r) for p, r in zip(img[i], q)) <= 1 / 255:
                        return True
        return False

    over = [i for i, d in enumerate(diffs) if d > 1 / 255]
    edge = sum(near(a, b, i) and near(b, a, i) for i in over)
    print(f"pixels over 1/255: {len(over)}, of which {edge} match a neighbour of the other "
          f"image (an edge a fraction of a pixel apart), {len(over) - edge} do not")
    reg = regions(args.scene, w, h)
    print("| region | pixels | mean A (r, g, b) | mean B (r, g, b) | mean abs diff | within 1/255 |")
    print("|---|---|---|---|---|---|")
    for name in sorted(set(reg)):
        idx = [i for i, r in enumerate(reg) if r == name]
        ma = [sum(a[i][c] for i in idx) / len(idx) for c in range(3)]
        mb = [sum(b[i][c] for i in idx) / len(idx) for c in range(3)]
        md = sum(sum(abs(p - q) for p, q in zip(a[i], b[i])) for i in idx) / (3 * len(idx))
        ok = sum(diffs[i] <= 1 / 255 for i in idx) / len(idx)
        fa = ", ".join(f"{v:.4f}" for v in ma)
        fb = ", ".join(f"{v:.4f}" for v in mb)
        print(f"| {name} | {len(idx)} | {fa} | {fb} | {md:.5f} | {100 * ok:.2f} % |")
    if args.out:
        os.makedirs(args.out, exist_ok=True)
        write_png(os.path.join(args.out, "A.png"), w, h, a)
        write_png(os.path.join(args.out, "B.png"), w, h, b)
        d = [[10 * abs(p - q) for p, q in zip(pa, pb)] for pa, pb in zip(a, b)]
        write_png(os.path.join(args.out, "diff.png"), w, h, d)


if __name__ == "__main__":
    main()
