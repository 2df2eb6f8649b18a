"""The Mitsuba peer benches' scenes, built by `chiaro export` from the
TOML scene chiaro renders, so that "the same scene" holds by construction
(issue 45, item 5).

`load(mi, toml)` exports TOML to Mitsuba 3 XML (meshes as PLY files and a
lat-long map resampled to Mitsuba's row convention beside it, in a
temporary folder) with the chiaro binary ($CHIARO, else
target/release/chiaro; `cargo build --release -p chiaro-cli`), prints the
exporter's warnings, and loads the XML with mitsuba.load_file. `drop`
names objects (`name = "..."`) or light types to leave out, for bisecting
a difference: the TOML is copied without them next to the original (so
its relative paths still resolve) and removed after the export.
"""
import os
import subprocess
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
CHIARO = os.environ.get("CHIARO", os.path.join(HERE, "..", "target", "release", "chiaro"))


def without(text, drop):
    """The TOML text without the [[object]] blocks named in `drop` and the
    [[light]] blocks whose type is in `drop`."""
    head, *blocks = text.split("\n[[")
    kept = [head]
    for b in blocks:
        body = "[[" + b
        names = [f'name = "{d}"' for d in drop] + [f'type = "{d}"' for d in drop]
        if any(n in body for n in names):
            continue
        kept.append(body)
    return "\n".join(kept)


def export(toml, out_dir, drop=()):
    """Writes OUT_DIR/scene.xml from `toml` (without `drop`); returns its path."""
    src = toml
    tmp = None
    if drop:
        text = without(open(toml).read(), drop)
        fd, tmp = tempfile.mkstemp(suffix=".toml", dir=os.path.dirname(os.path.abspath(toml)))
        with os.fdopen(fd, "w") as f:
            f.write(text)
        src = tmp
    xml = os.path.join(out_dir, "scene.xml")
    try:
        subprocess.run([CHIARO, "export", src, "--to", "mitsuba", "-o", xml], check=True,
                       stdout=subprocess.DEVNULL)
    finally:
        if tmp:
            os.remove(tmp)
    return xml


def load(mi, toml, drop=(), edit=None):
    """The Mitsuba scene of `toml` (see the module doc). `edit`, if given,
    maps the exported XML's text to the text loaded (to swap a peer-only
    setting such as the pixel filter or the sampler)."""
    with tempfile.TemporaryDirectory(prefix="chiaro-export-") as d:
        xml = export(toml, d, drop)
        if edit is not None:
            with open(xml) as f:
                text = edit(f.read())
            with open(xml, "w") as f:
                f.write(text)
        return mi.load_file(xml)
