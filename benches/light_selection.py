#!/usr/bin/env python3
"""Summarises benches/light_selection.sh's renders in DIR.

    benches/light_selection.py DIR

Per scene and sample count: the mean relMSE of luminance, (x - r)^2 /
(r^2 + 1e-6) averaged over pixels and seeds, of each mode against the mean
of the two 1024-spp references; the median CPU seconds of each; and the
equal-time efficiency relMSE(power) t(power) / (relMSE(tree) t(tree))
(above 1 the tree wins). Standard library only (compare_images.read_exr).
"""

import os
import statistics
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from compare_images import read_exr  # noqa: E402


def lum(path):
    _, _, px = read_exr(path)
    return [0.2126 * r + 0.7152 * g + 0.0722 * b for r, g, b in px]


def rel_mse(x, ref):
    return sum((a - r) ** 2 / (r * r + 1e-6) for a, r in zip(x, ref)) / len(ref)


def main():
    out = sys.argv[1]
    rows = [line.split("\t") for line in open(os.path.join(out, "times.tsv")).read().split("\n") if line]
    for s in ["helmet", "helmetemit", "emissive"]:
        rp = lum(os.path.join(out, f"ref-{s}-power.exr"))
        rt = lum(os.path.join(out, f"ref-{s}-tree.exr"))
        ref = [(a + b) / 2 for a, b in zip(rp, rt)]
        for spp in ["16", "64"]:
            res = {}
            for m in ["power", "tree"]:
                rs = [r for r in rows if r[0] == s and r[1] == spp and r[3] == m]
                mse = [rel_mse(lum(os.path.join(out, f"r-{s}-{spp}-{r[2]}-{m}.exr")), ref) for r in rs]
                res[m] = (statistics.mean(mse), statistics.median(float(r[4]) for r in rs), len(rs))
            (mp, tp, n), (mt, tt, _) = res["power"], res["tree"]
            print(
                f"{s} {spp} spp, {n} seeds: relMSE power {mp:.3e} tree {mt:.3e} ({mt / mp - 1:+.1%}); "
                f"CPU s power {tp:.2f} tree {tt:.2f}; equal-time tree/power {mp * tp / (mt * tt):.2f}x; "
                f"references apart by relMSE {rel_mse(rp, rt):.1e}"
            )


if __name__ == "__main__":
    main()
