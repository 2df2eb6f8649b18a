//! The pbrt-v4 writer of `chiaro export`: one `.pbrt` file, meshes inline
//! as `trianglemesh` shapes, materials as `MakeNamedMaterial`.
//!
//! pbrt's camera space is left-handed (its `LookAt` puts +x to the left of
//! chiaro's), so the camera is mirrored back by `Scale -1 1 1`, as
//! pbrt-v4's own exporters do. pbrt flips image `t` (`1 - v`), which the
//! written uvs undo. pbrt's `maxdepth` counts bounces as chiaro's
//! `max_depth` does (1 = direct light).

use super::{
    Bsdf, Colour, Files, LightWords, OutLight, Surface, bitmap_of, bsdf_of, light_of, material_at,
    meshes_of, num, nums, object_at, refuse, sphere_of,
};
use crate::Result;
use chiaro_core::scene::{
    Distribution, Geometry, PixelFilter, Projection, Scene, Texture, WrapMode,
};
use chiaro_core::{Mat4, Vec3};
use std::fmt::Write as _;
use std::path::Path;

/// `"rgb name" [r g b]`.
fn rgb(name: &str, v: Vec3) -> String {
    format!("\"rgb {name}\" [ {} ]", nums(v, " "))
}

/// `"float name" [v]`.
fn float(name: &str, v: f32) -> String {
    format!("\"float {name}\" [ {} ]", num(v))
}

/// A string for pbrt's quoted syntax (quotes and backslashes escaped).
fn quoted(s: &str) -> String {
    format!("\"{}\"", s.replace('\\', "\\\\").replace('"', "\\\""))
}

/// The whole `.pbrt` file.
pub(crate) fn write(scene: &Scene, out: &Path) -> Result<Files> {
    let mut files = Files::default();
    let w = &mut files.warnings;
    let r = &scene.render;
    let c = &scene.camera;
    let mut x = String::from("# written by chiaro export\n");
    // pbrt's fov spans the shorter image side.
    let aspect = r.width as f32 / r.height.max(1) as f32;
    let fov = if aspect >= 1.0 {
        c.fov_y_degrees
    } else {
        (2.0 * ((0.5 * c.fov_y_degrees.to_radians()).tan() * aspect).atan()).to_degrees()
    };
    // An orthographic camera's film is its screen window, in camera space
    // (world) units.
    let camera = match c.projection {
        Projection::Perspective => format!("\"perspective\" {}", float("fov", fov)),
        Projection::Orthographic { half_height: hh } => format!(
            "\"orthographic\" \"float screenwindow\" [ {} {} {} {} ]",
            num(-hh * aspect),
            num(hh * aspect),
            num(-hh),
            num(hh)
        ),
    };
    let _ = writeln!(
        x,
        "Scale -1 1 1\nLookAt {}  {}  {}\nCamera {camera}",
        nums(c.eye, " "),
        nums(c.look_at, " "),
        nums(c.up, " "),
    );
    let stem = out
        .file_stem()
        .map_or_else(|| "scene".to_owned(), |s| s.to_string_lossy().into_owned());
    let _ = writeln!(
        x,
        "Sampler \"independent\" \"integer pixelsamples\" [ {} ]\nIntegrator \"path\" \"integer maxdepth\" [ {} ]\nFilm \"rgb\" \"integer xresolution\" [ {} ] \"integer yresolution\" [ {} ] \"string filename\" [ {} ]\nPixelFilter {}\n\nWorldBegin\n",
        r.samples,
        r.path.max_depth,
        r.width,
        r.height,
        quoted(&format!("{stem}.exr")),
        match r.filter {
            PixelFilter::Box => "\"box\" \"float xradius\" [ 0.5 ] \"float yradius\" [ 0.5 ]",
            PixelFilter::Tent => "\"triangle\" \"float xradius\" [ 1 ] \"float yradius\" [ 1 ]",
            PixelFilter::Gaussian =>
                "\"gaussian\" \"float sigma\" [ 0.5 ] \"float xradius\" [ 2 ] \"float yradius\" [ 2 ]",
        }
    );
    if r.filter != PixelFilter::Box {
        w.push(
            "[render] filter: approximate: pbrt's filter samples may fall outside the film (chiaro's do not): pixels near the border differ"
                .to_owned(),
        );
    }
    // Lights.
    let words = LightWords {
        soft_edge: "pbrt's conedelta",
        surfaces: "pbrt's",
    };
    for i in 0..scene.lights.len() {
        match light_of(scene, i, out, &words, w)? {
            None => {}
            Some(OutLight::Point {
                position,
                intensity,
            }) => {
                let _ = writeln!(
                    x,
                    "LightSource \"point\" \"point3 from\" [ {} ] {}",
                    nums(position, " "),
                    rgb("I", intensity)
                );
            }
            Some(OutLight::Directional {
                direction,
                irradiance,
            }) => {
                // pbrt's light arrives from `from` towards `to`.
                let _ = writeln!(
                    x,
                    "LightSource \"distant\" \"point3 from\" [ {} ] \"point3 to\" [ 0 0 0 ] {}",
                    nums(-direction, " "),
                    rgb("L", irradiance)
                );
            }
            Some(OutLight::Spot {
                position,
                direction,
                cone_degrees,
                softness_degrees,
                intensity,
            }) => {
                let _ = writeln!(
                    x,
                    "LightSource \"spot\" \"point3 from\" [ {} ] \"point3 to\" [ {} ] {} {} {}",
                    nums(position, " "),
                    nums(position + direction, " "),
                    float("coneangle", cone_degrees),
                    float("conedelta", softness_degrees),
                    rgb("I", intensity)
                );
            }
        }
    }
    match &scene.environment {
        Some(env) => {
            let Some(Texture::Image(img)) = scene.textures.get(env.texture.index()) else {
                return Err(refuse(out, "environment".into(), "its map is not an image"));
            };
            if !env.as_background {
                return Err(refuse(
                    out,
                    "environment".into(),
                    "a map that camera rays do not see (background = false) has no exact counterpart",
                ));
            }
            if img.width == 1 && img.height == 1 && !img.texels.is_empty() {
                let t = img.texels[0];
                let _ = writeln!(
                    x,
                    "LightSource \"infinite\" {}",
                    rgb("L", Vec3::new(t[0], t[1], t[2]) * env.intensity)
                );
            } else {
                return Err(refuse(
                    out,
                    "environment".into(),
                    "pbrt-v4's infinite light reads square equal-area maps, not lat-long ones (convert it with pbrt's `imgtool makeequiarea`)",
                ));
            }
        }
        None if scene.background != Vec3::ZERO => {
            return Err(refuse(
                out,
                "background".into(),
                "a background colour that lights nothing has no exact counterpart (use an environment)",
            ));
        }
        None => {}
    }
    // Materials used by the objects, and their textures.
    let mut parts = Vec::new();
    let mut used = vec![false; scene.materials.len()];
    for (i, o) in scene.objects.iter().enumerate() {
        if !o.casts_shadows {
            return Err(refuse(
                out,
                object_at(scene, i),
                "an object that casts no shadows has no exact counterpart",
            ));
        }
        let p = meshes_of(scene, i, out)?;
        if matches!(o.geometry, Geometry::Sphere { .. }) {
            if o.material.index() >= scene.materials.len() {
                return Err(refuse(out, object_at(scene, i), "material out of range"));
            }
            used[o.material.index()] = true;
        }
        for (m, _) in &p {
            used[*m] = true;
        }
        parts.push(p);
    }
    let mut bsdfs: Vec<Option<Bsdf>> = vec![None; scene.materials.len()];
    for (i, &u) in used.iter().enumerate() {
        if !u {
            continue;
        }
        let b = bsdf_of(scene, i, out, w)?;
        if !b.two_sided && !matches!(b.surface, Surface::Dielectric { .. }) {
            w.push(format!("{}: approximate: pbrt's materials reflect on both faces; chiaro draws this one's back black", material_at(scene, i)));
        }
        let _ = writeln!(x, "{}", material_pbrt(scene, i, &b.surface, out, w)?);
        bsdfs[i] = Some(b);
    }
    // Shapes.
    for ((i, o), p) in scene.objects.iter().enumerate().zip(parts) {
        let world = o.transform.world_from_object();
        let head = |m: usize| -> String {
            let mut h = format!("AttributeBegin\n  NamedMaterial \"material-{m}\"\n");
            if let Some(e) = bsdfs[m].as_ref().and_then(|b| b.emission) {
                h += &format!("  AreaLightSource \"diffuse\" {}\n", rgb("L", e));
            }
            h
        };
        match o.geometry {
            Geometry::Sphere { radius } => {
                let (center, radius) = sphere_of(scene, i, radius, world, out)?;
                let _ = writeln!(
                    x,
                    "{}  Translate {}\n  Shape \"sphere\" {}\nAttributeEnd",
                    head(o.material.index()),
                    nums(center, " "),
                    float("radius", radius)
                );
            }
            Geometry::Mesh(_) => {
                for (m, mesh) in p {
                    let list =
                        |v: &mut dyn Iterator<Item = f32>| v.map(num).collect::<Vec<_>>().join(" ");
                    let mut s = format!(
                        "{}  Transform [ {} ]\n  Shape \"trianglemesh\"\n    \"point3 P\" [ {} ]\n    \"integer indices\" [ {} ]",
                        head(m),
                        transform(world),
                        list(&mut mesh.positions.iter().flat_map(|p| [p.x, p.y, p.z])),
                        mesh.indices
                            .iter()
                            .flat_map(|t| t.iter().map(u32::to_string))
                            .collect::<Vec<_>>()
                            .join(" ")
                    );
                    if !mesh.normals.is_empty() {
                        s += &format!(
                            "\n    \"normal N\" [ {} ]",
                            list(&mut mesh.normals.iter().flat_map(|n| [n.x, n.y, n.z]))
                        );
                    }
                    if !mesh.uvs.is_empty() {
                        // pbrt looks images up at t = 1 - v.
                        s += &format!(
                            "\n    \"point2 uv\" [ {} ]",
                            list(&mut mesh.uvs.iter().flat_map(|uv| [uv.x, 1.0 - uv.y]))
                        );
                    }
                    let _ = writeln!(x, "{s}\nAttributeEnd");
                }
            }
        }
    }
    files.main = (out.to_path_buf(), x.into_bytes());
    Ok(files)
}

/// pbrt's `Transform`: the matrix's 16 numbers column by column.
fn transform(m: Mat4) -> String {
    m.to_cols_array().map(num).join(" ")
}

/// `MakeNamedMaterial "material-i"` (after the `Texture` it needs).
fn material_pbrt(
    scene: &Scene,
    i: usize,
    s: &Surface,
    out: &Path,
    w: &mut Vec<String>,
) -> Result<String> {
    let at = || material_at(scene, i);
    let mut pre = String::new();
    let mut colour = |name: &str, c: &Colour, w: &mut Vec<String>| -> Result<String> {
        match c {
            Colour::Const(v) => Ok(rgb(name, *v)),
            Colour::Texture(t) => {
                let b = bitmap_of(scene, i, *t, out, w)?;
                let wrap = match b.wrap {
                    WrapMode::Repeat => "repeat",
                    WrapMode::Clamp => "clamp",
                    WrapMode::Mirror => {
                        return Err(refuse(out, at(), "pbrt has no mirrored texture wrap"));
                    }
                };
                let _ = writeln!(
                    pre,
                    "Texture \"texture-{i}\" \"spectrum\" \"imagemap\" \"string filename\" [ {} ] \"string wrap\" [ \"{wrap}\" ] \"string filter\" [ \"{}\" ]",
                    quoted(&b.path.to_string_lossy()),
                    if b.nearest { "point" } else { "bilinear" }
                );
                Ok(format!("\"texture {name}\" \"texture-{i}\""))
            }
        }
    };
    let rough = |r: &Option<(f32, Distribution)>| -> Result<String> {
        match r {
            None => Ok(String::new()),
            Some((_, Distribution::Beckmann)) => Err(refuse(
                out,
                at(),
                "pbrt-v4 has no Beckmann distribution (Trowbridge-Reitz/GGX only)",
            )),
            Some((a, Distribution::Ggx)) => Ok(format!(
                " {} \"bool remaproughness\" [ false ]",
                float("roughness", *a)
            )),
        }
    };
    let body = match s {
        Surface::Diffuse(c) => format!(
            "\"string type\" [ \"diffuse\" ] {}",
            colour("reflectance", c, w)?
        ),
        Surface::Conductor {
            tint,
            eta,
            k,
            rough: r,
        } => {
            if *tint != Vec3::ONE {
                return Err(refuse(
                    out,
                    at(),
                    "a tinted conductor (pbrt's conductor has no specular_reflectance)",
                ));
            }
            format!(
                "\"string type\" [ \"conductor\" ] {} {}{}",
                rgb("eta", *eta),
                rgb("k", *k),
                match r {
                    None => " \"float roughness\" [ 0 ]".to_owned(),
                    Some(_) => rough(r)?,
                }
            )
        }
        Surface::Dielectric { ior, transmittance } => {
            if *transmittance != Vec3::ONE {
                return Err(refuse(
                    out,
                    at(),
                    "a tinted dielectric (pbrt's dielectric has no transmittance)",
                ));
            }
            format!("\"string type\" [ \"dielectric\" ] {}", float("eta", *ior))
        }
        Surface::Plastic {
            diffuse,
            ior,
            rough: r,
        } => format!(
            "\"string type\" [ \"coateddiffuse\" ] {} {}{}",
            colour("reflectance", diffuse, w)?,
            float("eta", *ior),
            match r {
                None => " \"float roughness\" [ 0 ]".to_owned(),
                Some(_) => rough(r)?,
            }
        ),
    };
    Ok(format!("{pre}MakeNamedMaterial \"material-{i}\" {body}"))
}
