#!/usr/bin/env python3
"""CLI-level mutation fuzzing of chiaro, for machines without nightly Rust.

Mutates seed files (the shipped scenes, the fuzz corpora's OBJ, PLY and
glTF inputs, the `techniques` corpus and the Mitsuba XML scenes) as a
hostile user would: flipped bytes, deleted or repeated lines, numbers
replaced by extreme values (1e30, NaN, 2^64, 0, -1), and runs `chiaro
info` and `chiaro render` on each mutant with a random technique at
64x48, a radiosity budget of 500 iterations, under an address-space cap
(`prlimit --as`, 4 GB by default) and a timeout. A finding is:

- a hang: the command ran past `--timeout` seconds;
- a crash: the process died by a signal (an abort on allocation failure
  included);
- a panic: `panicked` on stderr;
- a message in Rust's Debug form (`Name { field:`, `Some(`, `Ok(`, `Err(`,
  `Valid(`, `as i128`).

Each finding's input is kept under `fuzz/artifacts/cli/` with a `.txt`
saying what happened; the exit status is 1 when there was any. The random
choices come from `--seed`, so a run explores the same mutants each time
on the same seeds (times aside).

    python3 fuzz/mutate.py --chiaro target/release/chiaro --seconds 60
"""

import argparse
import os
import random
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DEBUG = re.compile(r"\b[A-Z][A-Za-z0-9_]* \{ [a-z_]+:|\bSome\(|\bOk\(|\bErr\(|\bValid\(|as i128")
EXTREMES = [b"1e30", b"-1e30", b"nan", b"inf", b"18446744073709551616", b"0", b"-1",
            b"1e-30", b"65536", b"4294967295", b"3.4e38"]
NUMBER = re.compile(rb"-?\d+(\.\d+)?(e-?\d+)?")
TECHNIQUES = ["preview", "flat", "gouraud", "phong", "whitted", "radiosity", "hybrid", "path"]
# A work budget for radiosity (shots or sweeps, a count, not a time): a
# large but finite solve ends within the timeout, so a hang means a solve,
# or anything else, that does not end.
RADIOSITY_BUDGET = 500


def seeds():
    """(suffix, bytes) of every seed file."""
    out = []
    for p in sorted((ROOT / "scenes").glob("*.toml")):
        out.append((".toml", p.read_bytes()))
    corpus = ROOT / "fuzz" / "corpus"
    for target, suffix in [("obj_mtl", ".obj"), ("ply", ".ply"), ("gltf", None),
                           ("techniques", None), ("mitsuba_xml", ".xml"),
                           ("pbrt", ".pbrt")]:
        for p in sorted((corpus / target).glob("*")):
            data = p.read_bytes()
            if len(data) > 64 << 10:
                continue
            s = suffix
            if s is None:
                if data.startswith(b"glTF"):
                    s = ".glb"
                elif data.lstrip().startswith(b"{"):
                    s = ".gltf"
                elif b"[[object]]" in data or b"[render]" in data:
                    s = ".toml"
                else:
                    s = ".obj"
            out.append((s, data.split(b"\0")[0] if s == ".obj" else data))
    return out


def mutate(rng, data, structured=False):
    """One to four mutations of `data`; for a `structured` (JSON, TOML)
    text mostly numbers replaced and lines repeated, which keep it
    parseable more often than flipped bytes do."""
    for _ in range(rng.randint(1, 4)):
        lines = data.split(b"\n")
        kind = rng.choice([2, 3, 3, 3, 0]) if structured else rng.randrange(6)
        if kind == 0 and data:
            i = rng.randrange(len(data))
            data = data[:i] + bytes([data[i] ^ (1 << rng.randrange(8))]) + data[i + 1:]
        elif kind == 1 and len(lines) > 1:
            del lines[rng.randrange(len(lines))]
            data = b"\n".join(lines)
        elif kind == 2 and lines:
            i = rng.randrange(len(lines))
            lines[i:i] = [lines[i]] * rng.choice([1, 2, 100])
            data = b"\n".join(lines)
        elif kind == 3:
            spans = [m.span() for m in NUMBER.finditer(data)]
            if spans:
                a, b = rng.choice(spans)
                data = data[:a] + rng.choice(EXTREMES) + data[b:]
        elif kind == 4 and len(lines) > 2:
            i, j = rng.randrange(len(lines)), rng.randrange(len(lines))
            lines[i], lines[j] = lines[j], lines[i]
            data = b"\n".join(lines)
        elif data:
            i = rng.randrange(len(data))
            data = data[:i] + data[i:i + rng.randint(1, 64)] * 2 + data[i:]
    return data


def run(cmd, timeout, cap):
    """(outcome, stderr) of `cmd` under the address-space cap."""
    if cap and shutil.which("prlimit"):
        cmd = ["prlimit", f"--as={cap}", "--"] + cmd
    try:
        p = subprocess.run(cmd, capture_output=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return "hang", ""
    err = p.stderr.decode("utf-8", "replace")
    if p.returncode < 0 or p.returncode >= 128:
        return f"crash (status {p.returncode})", err
    if "panicked" in err:
        return "panic", err
    m = DEBUG.search(err)
    if m:
        return f"Debug form `{m.group(0)}`", err
    return None, err


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--chiaro", default=str(ROOT / "target" / "release" / "chiaro"))
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--timeout", type=float, default=30.0,
                    help="seconds after which a command counts as a hang")
    ap.add_argument("--cap", default="4000000000", help="address-space cap (bytes; '' for none)")
    ap.add_argument("--artifacts", default=str(ROOT / "fuzz" / "artifacts" / "cli"))
    args = ap.parse_args()
    rng = random.Random(args.seed)
    pool = seeds()
    if not pool:
        sys.exit("no seeds found")
    work = Path(tempfile.mkdtemp(prefix="chiaro-mutate-"))
    # Relative mesh and texture paths of the shipped scenes resolve here.
    for d in ["meshes", "gltf"]:
        if (ROOT / "scenes" / d).exists():
            os.symlink(ROOT / "scenes" / d, work / d)
    start, runs, findings = time.time(), 0, 0
    try:
        # Each format is as likely as the others, whatever its seed count
        # (the glTF corpus alone has hundreds).
        kinds = sorted({s for s, _ in pool})
        by_kind = {k: [d for s, d in pool if s == k] for k in kinds}
        while time.time() - start < args.seconds:
            suffix = rng.choice(kinds)
            data = rng.choice(by_kind[suffix])
            mutant = mutate(rng, data, structured=suffix in (".gltf", ".toml"))
            path = work / f"mutant{suffix}"
            path.write_bytes(mutant)
            technique = rng.choice(TECHNIQUES)
            for cmd in (
                [args.chiaro, "info", str(path)],
                [args.chiaro, "render", str(path), "-t", technique, "--width", "64",
                 "--height", "48", "--samples", "1", "--set",
                 f"radiosity.max_iterations={RADIOSITY_BUDGET}", "-o", str(work / "out.png")],
            ):
                runs += 1
                outcome, err = run(cmd, args.timeout, args.cap)
                if outcome:
                    findings += 1
                    out = Path(args.artifacts)
                    out.mkdir(parents=True, exist_ok=True)
                    name = f"finding-{findings}{suffix}"
                    (out / name).write_bytes(mutant)
                    (out / f"finding-{findings}.txt").write_text(
                        f"{outcome}\ncommand: {' '.join(cmd[1:2] + ['<input>'] + cmd[3:])}\n\n{err[-4000:]}\n")
                    print(f"FINDING {outcome}: {out / name} ({cmd[1]}, technique {technique})")
                    break
    finally:
        shutil.rmtree(work, ignore_errors=True)
    print(f"mutate: {runs} runs in {time.time() - start:.0f} s, {findings} findings")
    sys.exit(1 if findings else 0)


if __name__ == "__main__":
    main()
