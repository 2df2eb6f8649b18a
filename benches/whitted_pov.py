#!/usr/bin/env python3
"""Writes a POV-Ray 3.7 scene that is exactly a chiaro Whitted scene.

    benches/whitted_pov.py [SCENE.toml] [-o OUT.pov] [--size WxH] [--max-depth N]

Defaults: scenes/whitted.toml -> benches/whitted.pov at the scene's size.
Only what the mapping below expresses exactly is accepted (point and ambient
lights, Phong materials, the checker texture, spheres and planes moved by
`translate`); anything else is an error naming the key, so a changed scene
cannot silently render differently in POV-Ray.

How chiaro's terms map to POV-Ray's (chiaro: ARCHITECTURE.md "Radiometric
conventions", shading/{brdf,lights,bsdf}.rs, ray/whitted/mod.rs):
- camera: chiaro's `fov` is vertical and its frame right-handed (image right
  = forward x up); POV-Ray's `direction` of length 1/(2 tan(fov/2)), `up` of
  length 1 and `right` of length width/height pointing along -x before
  `look_at` give the same rays (a negative right keeps the frame
  right-handed through `look_at`). Both shoot through pixel centres.
- a point light under `inverse_square` gives `Ip c cos / d^2` of diffuse
  light for `kd` (the pi of the BRDF cancels); POV-Ray's `fade_power 2`
  multiplies by `2 / (1 + (d/D)^2)`, so the colour `Ip c / (2 D^2)` with a
  tiny D gives `Ip c / (d^2 + D^2)`: inverse square to D^2/d^2.
- ambient `Ia ka kd` = POV-Ray's `ambient_light Ia`, `ambient ka`, pigment kd.
- chiaro's Phong lobe is `ks (R.L)^n Ip / d^2`, without the cosine and not
  tinted by kd, where N.L > 0: POV-Ray's `phong ks phong_size n`, which is
  the same expression under the same condition.
- mirror `reflect` kr = `reflection { kr }`; a Fresnel dielectric
  (`fresnel = true`, `transmit` kt) reflects F and transmits (1 - F) kt at
  both surfaces, 1 under total internal reflection (chiaro ignores `reflect`
  there): `reflection { 0, 1 fresnel on } conserve_energy`, pigment transmit
  kt and `interior { ior }`. Shadow rays through it are tinted by kt at each
  crossing in both renderers.
- `max_depth` M counts bounces after the camera ray; POV-Ray's
  `max_trace_level` counts the camera ray too: M + 1. `min_weight` =
  `adc_bailout` (both stop a ray whose weight, the largest channel, is below).
- the checker is `floor(x) + floor(y) + floor(z)` parity in object space
  (`color_a` on even cells); POV-Ray adds 0.001 to each coordinate before the
  floor, so the pigment is moved by that much, and by half a cell in y so
  that the plane y = 0 sits inside a cell in both.
"""

import argparse
import math
import os
import sys
import tomllib

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

# POV-Ray's fade_distance: inverse square to (D / d)^2 relative.
FADE_DISTANCE = 1e-3
# POV-Ray's checker adds SMALL_TOLERANCE to each coordinate before the floor.
POV_CHECKER_TOLERANCE = 1e-3

MATERIAL_DEFAULTS = {
    "ambient": 0.1,
    "diffuse": 0.8,
    "specular": 0.0,
    "shininess": 20.0,
    "reflect": 0.0,
    "transmit": 0.0,
    "ior": 1.5,
    "fresnel": False,
    "model": "phong",
}
WHITTED_DEFAULTS = {"max_depth": 6, "min_weight": 1e-3}


class Unsupported(Exception):
    pass


def vec3(v, what):
    if isinstance(v, (int, float)):
        return [float(v)] * 3
    if isinstance(v, list) and len(v) == 3 and all(isinstance(x, (int, float)) for x in v):
        return [float(x) for x in v]
    raise Unsupported(f"{what}: expected a number or [x, y, z], got {v!r}")


def pov(v):
    return "<" + ", ".join(f"{x:.9g}" for x in v) + ">"


def only(table, allowed, what):
    extra = sorted(set(table) - set(allowed))
    if extra:
        raise Unsupported(f"{what}: {', '.join(extra)} cannot be mapped to POV-Ray exactly")


def camera(cam, width, height):
    only(cam, {"eye", "look_at", "up", "fov"}, "[camera]")
    eye = vec3(cam.get("eye", [0, 0, 5]), "camera.eye")
    look = vec3(cam.get("look_at", [0, 0, 0]), "camera.look_at")
    up = vec3(cam.get("up", [0, 1, 0]), "camera.up")
    fov = float(cam.get("fov", 45))
    if not 0 < fov < 180:
        raise Unsupported(f"camera.fov = {fov}: expected 0 < fov < 180")
    direction = 1.0 / (2.0 * math.tan(math.radians(fov) / 2.0))
    aspect = width / height
    return "\n".join(
        [
            "camera {",
            "  perspective",
            f"  location {pov(eye)}",
            f"  direction <0, 0, {direction:.12g}>  // vertical fov {fov:g} degrees",
            "  up <0, 1, 0>",
            f"  right <{-aspect:.12g}, 0, 0>  // right-handed, as chiaro",
            f"  sky {pov(up)}",
            f"  look_at {pov(look)}",
            "}",
        ]
    )


def lights(scene):
    ambient = [0.0, 0.0, 0.0]
    out = []
    for i, light in enumerate(scene.get("light", [])):
        what = f"light[{i}]"
        kind = light.get("type")
        color = vec3(light.get("color", [1, 1, 1]), f"{what}.color")
        ip = float(light.get("intensity", 1.0))
        if kind == "ambient":
            only(light, {"type", "color", "intensity"}, what)
            ambient = [a + c * ip for a, c in zip(ambient, color)]
        elif kind == "point":
            only(light, {"type", "position", "color", "intensity", "attenuation"}, what)
            pos = vec3(light["position"], f"{what}.position")
            att = light.get("attenuation", "none")
            if att == "inverse_square":
                k = ip / (2.0 * FADE_DISTANCE**2)
                fade = f" fade_distance {FADE_DISTANCE:g} fade_power 2"
            elif att == "none":
                k, fade = ip, ""
            else:
                raise Unsupported(f"{what}.attenuation = {att!r}")
            out.append(
                f"light_source {{ {pov(pos)} color rgb {pov([c * k for c in color])}{fade} }}"
            )
        else:
            raise Unsupported(f"{what}.type = {kind!r}")
    return ambient, out


def checker_pigment(tex, kd, what):
    only(tex, {"procedural", "scale", "color_a", "color_b"}, what)
    if tex.get("procedural") != "checker":
        raise Unsupported(f"{what}: only the checker procedural maps exactly")
    s = float(tex.get("scale", 1.0))
    if s <= 0:
        raise Unsupported(f"{what}.scale = {s}")
    a = [k * c for k, c in zip(kd, vec3(tex.get("color_a", [0, 0, 0]), f"{what}.color_a"))]
    b = [k * c for k, c in zip(kd, vec3(tex.get("color_b", [1, 1, 1]), f"{what}.color_b"))]
    tol = POV_CHECKER_TOLERANCE
    shift = [tol / s, (tol - 0.5) / s, tol / s]
    return f"pigment {{ checker rgb {pov(a)}, rgb {pov(b)} scale {1.0 / s:.12g} translate {pov(shift)} }}"


def material(name, m):
    what = f"material.{name}"
    only(m, set(MATERIAL_DEFAULTS) | {"texture"}, what)
    g = lambda k: m.get(k, MATERIAL_DEFAULTS[k])  # noqa: E731
    if g("model") != "phong":
        raise Unsupported(f"{what}.model = {g('model')!r}")
    ka = vec3(g("ambient"), f"{what}.ambient")
    kd = vec3(g("diffuse"), f"{what}.diffuse")
    ks = vec3(g("specular"), f"{what}.specular")
    kr = vec3(g("reflect"), f"{what}.reflect")
    kt = vec3(g("transmit"), f"{what}.transmit")
    n = float(g("shininess"))
    fresnel = bool(g("fresnel"))
    if len(set(ka)) != 1 or len(set(ks)) != 1:
        raise Unsupported(f"{what}: coloured ambient or specular")
    transmissive = max(kt) > 0
    finish = [f"ambient {ka[0]:.9g}", "diffuse 1", "brilliance 1"]
    if ks[0] > 0:
        finish.append(f"phong {ks[0]:.9g} phong_size {n:.9g}")
    interior = ""
    if transmissive:
        if len(set(kt)) != 1:
            raise Unsupported(f"{what}.transmit: coloured transmission")
        t = kt[0]
        if t >= 1:
            raise Unsupported(f"{what}.transmit = {t}: POV-Ray's opacity 1 - t must be > 0")
        # POV-Ray scales ambient and diffuse by the opacity 1 - t.
        finish = [f"ambient {ka[0] / (1 - t):.9g}", f"diffuse {1 / (1 - t):.9g}", "brilliance 1"] + finish[3:]
        pigment = f"pigment {{ rgbt <{kd[0]:.9g}, {kd[1]:.9g}, {kd[2]:.9g}, {t:.9g}> }}"
        interior = f"interior {{ ior {float(g('ior')):.9g} }}"
        if fresnel:
            finish.append("reflection { 0, 1 fresnel on } conserve_energy")
        else:
            raise Unsupported(
                f"{what}: transmit without fresnel (POV-Ray's total internal reflection "
                "weighs 1 where chiaro weighs kr + kt)"
            )
    else:
        if "texture" in m:
            pigment = checker_pigment(m["texture"], kd, f"{what}.texture")
        else:
            pigment = f"pigment {{ rgb {pov(kd)} }}"
        if max(kr) > 0:
            finish.append(f"reflection {{ rgb {pov(kr)} }}")
    if transmissive and "texture" in m:
        raise Unsupported(f"{what}: a textured transparent material")
    return "\n".join(
        [
            f"#declare M_{name} = texture {{",
            f"  {pigment}",
            f"  finish {{ {' '.join(finish)} }}",
            "}",
        ]
    ), interior


def transform(obj, what):
    t = obj.get("transform", {})
    only(t, {"translate"}, f"{what}.transform")
    return vec3(t.get("translate", [0, 0, 0]), f"{what}.transform.translate")


def objects(scene, interiors):
    out = []
    for i, obj in enumerate(scene.get("object", [])):
        what = f"object[{i}]"
        prim = obj.get("primitive")
        mat = obj.get("material")
        if mat not in interiors:
            raise Unsupported(f"{what}.material = {mat!r}: not a [material.NAME] of the scene")
        inner = f"texture {{ M_{mat} }} {interiors[mat]}".rstrip()
        move = transform(obj, what)
        if prim == "sphere":
            only(obj, {"primitive", "radius", "material", "transform"}, what)
            r = float(obj.get("radius", 1.0))
            out.append(f"sphere {{ <0, 0, 0>, {r:.9g} {inner} translate {pov(move)} }}")
        elif prim == "plane":
            # A square of side `size` in y = 0, centred on the origin.
            only(obj, {"primitive", "size", "material", "transform", "smooth"}, what)
            h = 0.5 * float(obj.get("size", 2.0))
            c = [(-h, -h), (h, -h), (h, h), (-h, h), (-h, -h)]
            pts = ", ".join(pov([x, 0, z]) for x, z in c)
            out.append(f"polygon {{ 5, {pts} {inner} translate {pov(move)} }}")
        else:
            raise Unsupported(f"{what}.primitive = {prim!r}")
    return out


def generate(scene, width, height, max_depth=None, source="scenes/whitted.toml"):
    only(scene, {"background", "render", "camera", "light", "material", "object"}, "scene")
    render = scene.get("render", {})
    # Settings that change only sampling or the 8-bit output; any other
    # (shadows, light samples, depth cueing, ...) changes the picture.
    only(render, {"technique", "width", "height", "samples", "seed", "aa", "tonemap",
                  "exposure", "whitted"}, "[render]")
    if render.get("technique", "whitted") != "whitted":
        raise Unsupported(f"render.technique = {render['technique']!r}: expected \"whitted\"")
    wt = dict(WHITTED_DEFAULTS)
    only(render.get("whitted", {}), {"max_depth", "min_weight", "adaptive_threshold",
                                     "adaptive_max_depth"}, "[render.whitted]")
    wt.update(render.get("whitted", {}))
    depth = int(wt["max_depth"] if max_depth is None else max_depth)
    ambient, light_lines = lights(scene)
    mats, interiors = [], {}
    for name, m in scene.get("material", {}).items():
        text, interiors[name] = material(name, m)
        mats.append(text)
    bg = vec3(scene.get("background", [0, 0, 0]), "background")
    lines = [
        f"// Generated by benches/whitted_pov.py from {source} ({width}x{height}):",
        "// the same scene term for term; regenerate instead of editing.",
        "#version 3.7;",
        "global_settings {",
        "  assumed_gamma 1.0",
        f"  max_trace_level {depth + 1}  // chiaro max_depth {depth} + the camera ray",
        f"  adc_bailout {float(wt['min_weight']):.9g}",
        f"  ambient_light rgb {pov(ambient)}",
        "}",
        f"background {{ rgb {pov(bg)} }}",
        camera(scene.get("camera", {}), width, height),
        *light_lines,
        *mats,
        *objects(scene, interiors),
    ]
    return "\n".join(lines) + "\n"


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("scene", nargs="?", default=os.path.join(ROOT, "scenes", "whitted.toml"))
    ap.add_argument("-o", "--output", default=os.path.join(ROOT, "benches", "whitted.pov"))
    ap.add_argument("--size", help="WxH (default: the scene's [render] width and height)")
    ap.add_argument("--max-depth", type=int, help="override [render.whitted] max_depth")
    args = ap.parse_args()
    with open(args.scene, "rb") as f:
        scene = tomllib.load(f)
    render = scene.get("render", {})
    width, height = int(render.get("width", 640)), int(render.get("height", 480))
    if args.size:
        w, _, h = args.size.partition("x")
        width, height = int(w), int(h)
    try:
        text = generate(scene, width, height, args.max_depth, os.path.relpath(args.scene, ROOT))
    except Unsupported as e:
        sys.exit(f"{args.scene}: {e}")
    with open(args.output, "w") as f:
        f.write(text)


if __name__ == "__main__":
    main()
