"""Python and Ray benchmark: the Python call against the CLI on the Cornell
box, and a tiled Ray render against a local render (same machine).

    target/pyvenv/bin/python benches/python_bench.py [--size 256] [--repeat 5]

Needs the module built with `maturin develop --release` and the CLI built
with `cargo build --release -p chiaro-cli`. Prints Markdown rows.
"""

from __future__ import annotations

import argparse
import os
import pathlib
import statistics
import subprocess
import tempfile
import time

import chiaro
import chiaro.distributed as dist

ROOT = pathlib.Path(__file__).resolve().parents[1]
BOX = ROOT / "scenes" / "cornell-box.toml"


def best(f, repeat):
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        f()
        times.append(time.perf_counter() - t)
    return min(times), statistics.median(times)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--techniques", default="phong,whitted,path")
    ap.add_argument("--tiles", default="1,2,4,16")
    a = ap.parse_args()
    n = a.size
    cli = ROOT / "target" / "release" / "chiaro"
    out = pathlib.Path(tempfile.mkdtemp()) / "x.exr"
    scene = chiaro.load(BOX)
    print(f"cores: {os.cpu_count()}, image {n}x{n}, best (median) of {a.repeat}")
    print("| technique | CLI process (load+render+EXR) | CLI render only | chiaro.load+render | chiaro.render | render stats |")
    print("|---|---|---|---|---|---|")
    for t in a.techniques.split(","):
        spp = ["--samples", "16"] if t == "path" else []
        cmd = [str(cli), "render", str(BOX), "--technique", t, "--width", str(n), "--height", str(n), *spp, "-o", str(out)]
        cli_times = []
        cli_render = []
        for _ in range(a.repeat):
            s = time.perf_counter()
            r = subprocess.run(cmd, capture_output=True, text=True, check=True)
            cli_times.append(time.perf_counter() - s)
            # "...: phong 256x256 4 spp in 0.123 s"
            cli_render.append(float(r.stdout.split(" in ")[1].split(" s")[0]))
        kw = dict(width=n, height=n, samples=16 if t == "path" else None)
        stats = []
        py = best(lambda: stats.append(chiaro.render(scene, t, **kw).stats["seconds"]), a.repeat)
        py_load = best(lambda: chiaro.render(chiaro.load(BOX), t, **kw), a.repeat)
        print(f"| {t} | {min(cli_times):.3f} ({statistics.median(cli_times):.3f}) s | {min(cli_render):.3f} s "
              f"| {py_load[0]:.3f} ({py_load[1]:.3f}) s | {py[0]:.3f} ({py[1]:.3f}) s | {min(stats):.3f} s |")

    import ray
    ray.init(num_cpus=os.cpu_count(), include_dashboard=False, log_to_driver=False,
             _temp_dir=tempfile.mkdtemp(prefix="rb", dir="/tmp"))
    print()
    print("| technique | local chiaro.render | Ray tiles | Ray render (best, median) | cpus_per_task |")
    print("|---|---|---|---|---|")
    for t in ("whitted", "path"):
        kw = dict(width=n, height=n, samples=16 if t == "path" else None)
        local = best(lambda: chiaro.render(scene, t, **kw), a.repeat)
        for tiles in [int(x) for x in a.tiles.split(",")]:
            dist.render(scene, t, tiles=tiles, **kw)  # warm the workers
            r = best(lambda: dist.render(scene, t, tiles=tiles, **kw), a.repeat)
            print(f"| {t} | {local[0]:.3f} s | {tiles} | {r[0]:.3f} ({r[1]:.3f}) s | 1 |")
    ray.shutdown()


if __name__ == "__main__":
    main()
