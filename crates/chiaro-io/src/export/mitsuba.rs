//! The Mitsuba 3 XML writer of `chiaro export`: the inverse of the reader
//! in `crate::mitsuba` (docs/import-mitsuba.md), so that a scene exported
//! and read back is the scene written. Meshes go to binary PLY files
//! beside the XML (`STEM-mesh-N.ply`).

use super::{
    Bitmap, Colour, Files, LightWords, OutLight, Surface, bitmap_of, bsdf_of, companion, light_of,
    meshes_of, num, nums, object_at, ply_bytes, refuse, sphere_of,
};
use crate::Result;
use chiaro_core::scene::{
    Distribution, Geometry, PixelFilter, Projection, Scene, Texture, WrapMode,
};
use chiaro_core::{Mat4, Vec3};
use std::fmt::Write as _;
use std::path::Path;

/// `s` with XML's five special characters escaped, for an attribute.
fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
        .replace('\'', "&apos;")
}

/// `<rgb name value>`.
fn rgb(name: &str, v: Vec3) -> String {
    format!("<rgb name=\"{name}\" value=\"{}\"/>", nums(v, ", "))
}

/// `<float name value>`.
fn float(name: &str, v: f32) -> String {
    format!("<float name=\"{name}\" value=\"{}\"/>", num(v))
}

/// A 4x4 matrix as Mitsuba's row-major `<matrix value>`.
fn matrix(m: Mat4) -> String {
    let rows = m.transpose().to_cols_array().map(num).join(" ");
    format!("<transform name=\"to_world\"><matrix value=\"{rows}\"/></transform>")
}

/// The XML of the whole scene and its PLY files.
pub(crate) fn write(scene: &Scene, out: &Path) -> Result<Files> {
    let mut files = Files::default();
    let mut x = String::from(
        "<?xml version=\"1.0\" encoding=\"utf-8\"?>\n<!-- written by chiaro export -->\n<scene version=\"3.0.0\">\n",
    );
    let w = &mut files.warnings;
    let r = &scene.render;
    let _ = writeln!(
        x,
        "    <integrator type=\"path\">\n        <integer name=\"max_depth\" value=\"{}\"/>\n        <integer name=\"rr_depth\" value=\"{}\"/>\n    </integrator>",
        // Mitsuba counts the camera segment, chiaro the scattering vertices.
        r.path.max_depth.saturating_add(1),
        r.path.rr_depth.saturating_add(1)
    );
    // The camera. Mitsuba's orthographic film is [-1, 1] wide and
    // [-1/aspect, 1/aspect] high before `to_world`'s scale.
    let c = &scene.camera;
    let (sensor, lens, scale) = match c.projection {
        Projection::Perspective => (
            "perspective",
            format!(
                "<string name=\"fov_axis\" value=\"y\"/>\n        {}\n        ",
                float("fov", c.fov_y_degrees)
            ),
            String::new(),
        ),
        Projection::Orthographic { half_height } => {
            let s = num(half_height * r.width as f32 / r.height.max(1) as f32);
            (
                "orthographic",
                String::new(),
                format!("<scale x=\"{s}\" y=\"{s}\"/>"),
            )
        }
    };
    let _ = writeln!(
        x,
        "    <sensor type=\"{sensor}\">\n        {lens}{}\n        {}\n        <transform name=\"to_world\">{scale}<lookat origin=\"{}\" target=\"{}\" up=\"{}\"/></transform>\n        <sampler type=\"independent\"><integer name=\"sample_count\" value=\"{}\"/></sampler>\n        <film type=\"hdrfilm\">\n            <integer name=\"width\" value=\"{}\"/>\n            <integer name=\"height\" value=\"{}\"/>\n            <rfilter type=\"{}\"/>\n        </film>\n    </sensor>",
        float("near_clip", c.near),
        float("far_clip", c.far),
        nums(c.eye, ", "),
        nums(c.look_at, ", "),
        nums(c.up, ", "),
        r.samples,
        r.width,
        r.height,
        // Mitsuba's tent (radius 1) and Gaussian (stddev 0.5) are chiaro's.
        match r.filter {
            PixelFilter::Box => "box",
            PixelFilter::Tent => "tent",
            PixelFilter::Gaussian => "gaussian",
        }
    );
    // The materials the objects use, once each.
    let mut used = vec![false; scene.materials.len()];
    let mut meshes = Vec::new();
    for (i, o) in scene.objects.iter().enumerate() {
        if !o.casts_shadows {
            return Err(refuse(
                out,
                object_at(scene, i),
                "an object that casts no shadows has no exact counterpart",
            ));
        }
        match o.geometry {
            Geometry::Mesh(_) => {
                let parts = meshes_of(scene, i, out)?;
                for (m, _) in &parts {
                    used[*m] = true;
                }
                meshes.push(parts);
            }
            Geometry::Sphere { .. } => {
                let m = o.material.index();
                if m >= scene.materials.len() {
                    return Err(refuse(out, object_at(scene, i), "material out of range"));
                }
                used[m] = true;
                meshes.push(Vec::new());
            }
        }
    }
    let mut bsdfs = Vec::with_capacity(scene.materials.len());
    for (i, &u) in used.iter().enumerate() {
        if !u {
            bsdfs.push(None);
            continue;
        }
        let b = bsdf_of(scene, i, out, w)?;
        let body = surface_xml(scene, i, &b.surface, out, w)?;
        let id = format!("material-{i}");
        let xml = if b.two_sided && !matches!(b.surface, Surface::Dielectric { .. }) {
            format!("    <bsdf type=\"twosided\" id=\"{id}\">\n        {body}\n    </bsdf>\n")
        } else {
            // The first element of `body` takes the id.
            format!(
                "    {}\n",
                body.replacen("<bsdf ", &format!("<bsdf id=\"{id}\" "), 1)
            )
        };
        x += &xml;
        bsdfs.push(Some((id, b.emission)));
    }
    // Lights.
    let words = LightWords {
        soft_edge: "Mitsuba's beam_width",
        surfaces: "the peers'",
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
                    "    <emitter type=\"point\"><point name=\"position\" value=\"{}\"/>{}</emitter>",
                    nums(position, ", "),
                    rgb("intensity", intensity)
                );
            }
            Some(OutLight::Directional {
                direction,
                irradiance,
            }) => {
                let _ = writeln!(
                    x,
                    "    <emitter type=\"directional\"><vector name=\"direction\" value=\"{}\"/>{}</emitter>",
                    nums(direction, ", "),
                    rgb("irradiance", irradiance)
                );
            }
            Some(OutLight::Spot {
                position,
                direction,
                cone_degrees,
                softness_degrees,
                intensity,
            }) => {
                let d = direction.normalize_or(Vec3::NEG_Z);
                let up = if d.y.abs() < 0.9 { Vec3::Y } else { Vec3::X };
                let _ = writeln!(
                    x,
                    "    <emitter type=\"spot\"><transform name=\"to_world\"><lookat origin=\"{}\" target=\"{}\" up=\"{}\"/></transform>{}{}{}</emitter>",
                    nums(position, ", "),
                    nums(position + d, ", "),
                    nums(up, ", "),
                    float("cutoff_angle", cone_degrees),
                    float("beam_width", (cone_degrees - softness_degrees).max(0.0)),
                    rgb("intensity", intensity)
                );
            }
        }
    }
    // The environment.
    match &scene.environment {
        Some(env) => {
            if !env.as_background {
                return Err(refuse(
                    out,
                    "environment".into(),
                    "a map that camera rays do not see (background = false) has no exact counterpart",
                ));
            }
            let Some(Texture::Image(img)) = scene.textures.get(env.texture.index()) else {
                return Err(refuse(out, "environment".into(), "its map is not an image"));
            };
            if img.width > 1 || img.height > 1 {
                let path = companion(out, "-env.exr");
                let name = path
                    .file_name()
                    .map(|n| n.to_string_lossy().into_owned())
                    .unwrap_or_default();
                let bytes = mitsuba_rows(img).map_err(|m| {
                    refuse(
                        out,
                        "environment".into(),
                        format!("its map cannot be written: {m}"),
                    )
                })?;
                files.companions.push((path, bytes));
                // Mitsuba puts -z at u = 0, chiaro at u = 0.5: half a turn more.
                let _ = writeln!(
                    x,
                    "    <emitter type=\"envmap\"><string name=\"filename\" value=\"{}\"/>{}<transform name=\"to_world\"><rotate y=\"1\" angle=\"{}\"/></transform></emitter>",
                    esc(&name),
                    float("scale", env.intensity),
                    num(env.rotate_y_degrees - 180.0)
                );
            } else if !img.texels.is_empty() || img.texels8.is_some() {
                let t = img.texel_at(0);
                let _ = writeln!(
                    x,
                    "    <emitter type=\"constant\">{}</emitter>",
                    rgb("radiance", Vec3::new(t[0], t[1], t[2]) * env.intensity)
                );
            } else {
                return Err(refuse(
                    out,
                    "environment".into(),
                    format!(
                        "its map \"{}\" is not a file the peer could read",
                        img.source
                    ),
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
    // Shapes: one PLY file per mesh, smoothing and material, shared by
    // every object that places it.
    let mut n_mesh = 0usize;
    let mut written: std::collections::HashMap<(usize, bool, u32, usize, usize), String> =
        std::collections::HashMap::new();
    for ((i, o), parts) in scene.objects.iter().enumerate().zip(meshes) {
        let world = o.transform.world_from_object();
        let shape_tail = |m: usize| -> String {
            let (id, emission) = bsdfs[m]
                .as_ref()
                .map_or((String::new(), None), |b| (b.0.clone(), b.1));
            let mut t = format!("<ref id=\"{id}\"/>");
            if let Some(e) = emission {
                t += &format!("<emitter type=\"area\">{}</emitter>", rgb("radiance", e));
            }
            t
        };
        match o.geometry {
            Geometry::Sphere { radius } => {
                let (center, radius) = sphere_of(scene, i, radius, world, out)?;
                let _ = writeln!(
                    x,
                    "    <shape type=\"sphere\"><point name=\"center\" value=\"{}\"/>{}{}</shape>",
                    nums(center, ", "),
                    float("radius", radius),
                    shape_tail(o.material.index())
                );
            }
            Geometry::Mesh(id) => {
                for (part, (m, mesh)) in parts.into_iter().enumerate() {
                    let key = (
                        id.index(),
                        o.smooth,
                        o.crease_angle_degrees.to_bits(),
                        o.material.index(),
                        part,
                    );
                    let name = match written.get(&key) {
                        Some(name) => name.clone(),
                        None => {
                            let path = companion(out, &format!("-mesh-{n_mesh}.ply"));
                            n_mesh += 1;
                            let name = path
                                .file_name()
                                .map(|n| n.to_string_lossy().into_owned())
                                .unwrap_or_default();
                            files.companions.push((path, ply_bytes(&mesh)));
                            written.insert(key, name.clone());
                            name
                        }
                    };
                    let face_normals = if mesh.normals.is_empty() {
                        "<boolean name=\"face_normals\" value=\"true\"/>"
                    } else {
                        ""
                    };
                    let _ = writeln!(
                        x,
                        "    <shape type=\"ply\"><string name=\"filename\" value=\"{}\"/>{face_normals}{}{}</shape>",
                        esc(&name),
                        matrix(world),
                        shape_tail(m)
                    );
                }
            }
        }
    }
    x += "</scene>\n";
    files.main = (out.to_path_buf(), x.into_bytes());
    Ok(files)
}

/// The `<bsdf>` of one surface (without an id).
fn surface_xml(
    scene: &Scene,
    i: usize,
    s: &Surface,
    out: &Path,
    w: &mut Vec<String>,
) -> Result<String> {
    let colour = |name: &str, c: &Colour, w: &mut Vec<String>| -> Result<String> {
        match c {
            Colour::Const(v) => Ok(rgb(name, *v)),
            Colour::Texture(t) => {
                let b = bitmap_of(scene, i, *t, out, w)?;
                Ok(bitmap_xml(name, &b))
            }
        }
    };
    let rough = |r: &Option<(f32, Distribution)>| -> String {
        match r {
            None => String::new(),
            Some((alpha, d)) => format!(
                "{}<string name=\"distribution\" value=\"{}\"/>",
                float("alpha", *alpha),
                match d {
                    Distribution::Ggx => "ggx",
                    Distribution::Beckmann => "beckmann",
                }
            ),
        }
    };
    Ok(match s {
        Surface::Diffuse(c) => format!(
            "<bsdf type=\"diffuse\">{}</bsdf>",
            colour("reflectance", c, w)?
        ),
        Surface::Conductor {
            tint,
            eta,
            k,
            rough: r,
        } => format!(
            "<bsdf type=\"{}\">{}{}{}{}</bsdf>",
            if r.is_some() {
                "roughconductor"
            } else {
                "conductor"
            },
            rgb("eta", *eta),
            rgb("k", *k),
            rgb("specular_reflectance", *tint),
            rough(r)
        ),
        Surface::Dielectric { ior, transmittance } => format!(
            "<bsdf type=\"dielectric\">{}{}{}</bsdf>",
            float("int_ior", *ior),
            float("ext_ior", 1.0),
            rgb("specular_transmittance", *transmittance)
        ),
        Surface::Plastic {
            diffuse,
            ior,
            rough: r,
        } => format!(
            "<bsdf type=\"{}\">{}{}{}{}</bsdf>",
            if r.is_some() {
                "roughplastic"
            } else {
                "plastic"
            },
            colour("diffuse_reflectance", diffuse, w)?,
            float("int_ior", *ior),
            float("ext_ior", 1.0),
            rough(r)
        ),
    })
}

/// A `<texture type="bitmap">` parameter.
fn bitmap_xml(name: &str, b: &Bitmap) -> String {
    format!(
        "<texture type=\"bitmap\" name=\"{name}\"><string name=\"filename\" value=\"{}\"/><string name=\"filter_type\" value=\"{}\"/><string name=\"wrap_mode\" value=\"{}\"/></texture>",
        esc(&b.path.to_string_lossy()),
        if b.nearest { "nearest" } else { "bilinear" },
        match b.wrap {
            WrapMode::Repeat => "repeat",
            WrapMode::Mirror => "mirror",
            WrapMode::Clamp => "clamp",
        }
    )
}

/// The lat-long map `img` as an RGB OpenEXR for Mitsuba's `envmap`, which
/// places row j at v = j / (H - 1) (its rows span the poles) where chiaro
/// places it at (j + 0.5) / H: 2H + 1 rows at v = j / 2H, each chiaro's
/// bilinear lookup in v there (rows wrapped, columns kept; both place
/// column i at u = (i + 0.5) / W). Mitsuba's linear interpolation between
/// these rows is then chiaro's lookup exactly, as its knots are every
/// other row.
fn mitsuba_rows(img: &chiaro_core::scene::ImageTexture) -> std::result::Result<Vec<u8>, String> {
    use exr::prelude::*;
    let (w, h) = (img.width as usize, img.height as usize);
    if w == 0 || h == 0 || img.texel_count() < w * h {
        return Err("the image is empty".into());
    }
    let rows = 2 * h + 1;
    let mut rgb = [Vec::new(), Vec::new(), Vec::new()];
    for j in 0..rows {
        let y = j as f64 / (2 * h) as f64 * h as f64 - 0.5;
        let y0 = y.floor();
        let f = (y - y0) as f32;
        let r0 = (y0 as i64).rem_euclid(h as i64) as usize;
        let r1 = (y0 as i64 + 1).rem_euclid(h as i64) as usize;
        for i in 0..w {
            let a = img.texel_at(r0 * w + i);
            let b = img.texel_at(r1 * w + i);
            for c in 0..3 {
                rgb[c].push((1.0 - f) * a[c] + f * b[c]);
            }
        }
    }
    let [r, g, b] = rgb;
    let ch = |name: &str, v: Vec<f32>| AnyChannel::new(name, FlatSamples::F32(v));
    let channels: SmallVec<[AnyChannel<FlatSamples>; 4]> =
        vec![ch("R", r), ch("G", g), ch("B", b)].into();
    let layer = Layer::new(
        (w, rows),
        LayerAttributes::default(),
        Encoding::SMALL_LOSSLESS,
        AnyChannels::sort(channels),
    );
    let mut bytes = std::io::Cursor::new(Vec::new());
    Image::from_layer(layer)
        .write()
        .to_buffered(&mut bytes)
        .map_err(|e| format!("cannot encode the OpenEXR image: {e}"))?;
    Ok(bytes.into_inner())
}
