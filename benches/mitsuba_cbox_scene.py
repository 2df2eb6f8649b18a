#!/usr/bin/env python3
"""Writes scenes/mitsuba-cbox.toml from Mitsuba 3's own mi.cornell_box() dict.

usage: mitsuba_cbox_scene.py OUT.toml

Every shape keeps Mitsuba's to_world matrix verbatim (as chiaro's column-major
`transform.matrix`) on Mitsuba's canonical shape: `rectangle` is the quad
[-1, 1]^2 at z = 0 facing +z, `cube` is the box [-1, 1]^3. The sensor's
to_world (camera at its origin looking down its +z, +y up) becomes eye /
look_at / up; fov_axis = smaller on a square film is the vertical fov.
Mitsuba's max_depth counts path segments (1 = visible emitters only, 2 =
direct light), chiaro's counts scattering vertices (1 = direct light), so
chiaro's max_depth is Mitsuba's minus one.
"""
import sys
import numpy as np
import mitsuba as mi

mi.set_variant("scalar_rgb")
d = mi.cornell_box()


def mat(t):
    m = np.array(t.matrix, dtype=np.float64)
    return m.T.reshape(-1)  # column-major


def fmt(v):
    return "[" + ", ".join(str(np.float32(x)) for x in v) + "]"


sensor = d["sensor"]
cm = np.array(sensor["to_world"].matrix, dtype=np.float64)
eye = cm[:3, 3]
look = eye + cm[:3, 2]
up = cm[:3, 1]
mitsuba_depth = d["integrator"]["max_depth"]
out = [
    "# Mitsuba 3's own Cornell box (mitsuba.cornell_box(), Mitsuba 3.9), rebuilt",
    "# for chiaro by benches/mitsuba_cbox_scene.py: the same shapes with Mitsuba's",
    "# to_world matrices verbatim, the same camera, RGB albedos and emitter.",
    "# Mitsuba's `rectangle` is the quad [-1,1]^2 at z = 0 facing +z and its `cube`",
    "# is [-1,1]^3; its diffuse BSDFs are Lambertian with these albedos, the area",
    "# emitter is one-sided (it faces down). Mitsuba's film uses a Gaussian pixel",
    "# filter, chiaro a box: compare against a box-filtered Mitsuba reference.",
    "# max_depth: Mitsuba's 8 path segments = chiaro's 7 scattering vertices.",
    "",
    "[render]",
    'technique = "path"',
    f"width = {sensor['film']['width']}",
    f"height = {sensor['film']['height']}",
    f"samples = {sensor['sampler']['sample_count']}",
    "",
    "[render.path]",
    f"max_depth = {mitsuba_depth - 1}",
    "rr_depth = 5",
    "",
    "[camera]",
    f"eye = {fmt(eye)}",
    f"look_at = {fmt(look)}",
    f"up = {fmt(up)}",
    f"fov = {sensor['fov']}",
    "",
]
for name in ("white", "red", "green"):
    out += [f"[material.{name}]", f"diffuse = {fmt(d[name]['reflectance']['value'])}", ""]
light = d["light"]
out += [
    "[material.light]",
    f"diffuse = {fmt(d[light['bsdf']['id']]['reflectance']['value'])}",
    f"emission = {fmt(light['emitter']['radiance']['value'])}",
    "sidedness = \"one-sided\"",
    "",
]
for key in ("floor", "ceiling", "back", "green-wall", "red-wall", "small-box", "large-box", "light"):
    s = d[key]
    material = "light" if key == "light" else s["bsdf"]["id"]
    out.append("[[object]]")
    out.append(f'name = "{key}"')
    if s["type"] == "rectangle":
        out += ['primitive = "quad"', "corner = [-1, -1, 0]", "edge_u = [2, 0, 0]", "edge_v = [0, 2, 0]"]
    elif s["type"] == "cube":
        out += ['primitive = "box"', "size = 2"]
    else:
        raise SystemExit(f"unexpected shape type {s['type']}")
    out.append(f'material = "{material}"')
    out.append("smooth = false")
    out.append(f"transform = {{ matrix = {fmt(mat(s['to_world']))} }}")
    out.append("")
open(sys.argv[1], "w").write("\n".join(out))
