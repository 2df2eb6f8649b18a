//! `Scene::validate`: every problem in a scene, not only the first.

use super::{
    AreaShape, FormFactorMethod, Geometry, Light, MAX_IMAGE_PIXELS, MAX_IMAGE_SIDE, MAX_SAMPLES,
    RadiositySolver, RenderSettings, SHADOW_MAP_RESOLUTIONS, Scene, Texture,
};
use glam::Vec3;
use std::fmt;

/// The largest world-space coordinate a scene may use: squared distances
/// and edge cross products of points this far out stay finite in `f32`
/// (1e15 squared is 1e30, under `f32::MAX` = 3.4e38), so no technique meets
/// an infinity or a NaN in its geometry.
pub const MAX_COORDINATE: f32 = 1e15;

/// How bad an [`Issue`] is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Severity {
    /// The scene renders, but probably not as meant.
    Warning,
    /// The scene cannot be rendered.
    Error,
}

/// One problem found in a scene. `path` names the item (`objects[3].material`).
#[derive(Debug, Clone, PartialEq)]
pub struct Issue {
    /// Warning or error.
    pub severity: Severity,
    /// Where in the scene, as a path of fields and indices.
    pub path: String,
    /// What is wrong and what was expected.
    pub message: String,
}

impl fmt::Display for Issue {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let sev = match self.severity {
            Severity::Warning => "warning",
            Severity::Error => "error",
        };
        write!(f, "{sev}: {}: {}", self.path, self.message)
    }
}

struct Checker {
    issues: Vec<Issue>,
}

impl Checker {
    fn error(&mut self, path: impl Into<String>, message: impl Into<String>) {
        self.issues.push(Issue {
            severity: Severity::Error,
            path: path.into(),
            message: message.into(),
        });
    }
    fn warn(&mut self, path: impl Into<String>, message: impl Into<String>) {
        self.issues.push(Issue {
            severity: Severity::Warning,
            path: path.into(),
            message: message.into(),
        });
    }
    fn finite(&mut self, path: &str, v: Vec3) {
        if !v.is_finite() {
            self.error(path, format!("expected finite numbers, got {v}"));
        }
    }
    /// A position: finite and within [`MAX_COORDINATE`].
    fn coordinate(&mut self, path: &str, v: Vec3) {
        if !within_range(v) {
            self.error(
                path,
                format!("expected finite coordinates within ±{MAX_COORDINATE:e}, got {v}"),
            );
        }
    }
    fn non_negative(&mut self, path: &str, v: Vec3) {
        self.finite(path, v);
        if v.min_element() < 0.0 {
            self.error(path, format!("expected values >= 0, got {v}"));
        }
    }
    fn positive_scalar(&mut self, path: &str, x: f32) {
        if !(x.is_finite() && x > 0.0) {
            self.error(path, format!("expected a finite number > 0, got {x}"));
        }
    }
}

impl RenderSettings {
    /// Checks the render settings alone and returns every problem found,
    /// each naming its setting (`render.path.max_depth`). This is the one
    /// place settings are validated: [`Scene::validate`] includes it, and
    /// the techniques take its result as given.
    pub fn validate(&self) -> Vec<Issue> {
        let mut c = Checker { issues: Vec::new() };
        let r = self;
        for (path, side) in [("render.width", r.width), ("render.height", r.height)] {
            if !(1..=MAX_IMAGE_SIDE).contains(&side) {
                c.error(path, format!("expected 1..={MAX_IMAGE_SIDE}, got {side}"));
            }
        }
        if u64::from(r.width) * u64::from(r.height) > MAX_IMAGE_PIXELS
            && r.width <= MAX_IMAGE_SIDE
            && r.height <= MAX_IMAGE_SIDE
        {
            c.error(
                "render.height",
                format!(
                    "image {}x{} has more than {MAX_IMAGE_PIXELS} pixels",
                    r.width, r.height
                ),
            );
        }
        if r.samples == 0 || r.samples > MAX_SAMPLES {
            c.error(
                "render.samples",
                format!("expected 1..={MAX_SAMPLES}, got {}", r.samples),
            );
        }
        if !r.exposure.is_finite() {
            c.error("render.exposure", "expected a finite number");
        }
        if !SHADOW_MAP_RESOLUTIONS.contains(&r.shadow_map.resolution) {
            c.error(
                "render.shadow_map.resolution",
                format!(
                    "expected {}..={} texels per side, got {}",
                    SHADOW_MAP_RESOLUTIONS.start(),
                    SHADOW_MAP_RESOLUTIONS.end(),
                    r.shadow_map.resolution
                ),
            );
        }

        if r.light_samples == 0 || r.light_samples > MAX_SAMPLES {
            c.error(
                "render.light_samples",
                format!(
                    "expected 1..={MAX_SAMPLES} samples per area light, got {}",
                    r.light_samples
                ),
            );
        }
        if let Some(cue) = &r.depth_cue {
            check_depth_cue(&mut c, cue);
        }
        if r.path.max_depth == 0 {
            c.error(
                "render.path.max_depth",
                "expected at least 1 (1 = direct light only)",
            );
        }
        let rad = &r.radiosity;
        if rad.solver == RadiositySolver::Hierarchical
            && rad.formfactor == FormFactorMethod::Hemicube
        {
            c.error(
                "render.radiosity.formfactor",
                "the hierarchical solver needs area-to-area link form factors: use `raycast` or `analytic`",
            );
        }
        if !(rad.patch_size.is_finite() && rad.patch_size >= 0.0) {
            c.error(
                "render.radiosity.patch_size",
                format!(
                    "expected a finite number >= 0 (0 = automatic), got {}",
                    rad.patch_size
                ),
            );
        }
        if !(2..=4096).contains(&rad.hemicube_resolution) {
            c.error(
                "render.radiosity.hemicube_resolution",
                format!("expected 2..=4096, got {}", rad.hemicube_resolution),
            );
        }
        if !(rad.tolerance.is_finite() && rad.tolerance > 0.0 && rad.tolerance < 1.0) {
            c.error(
                "render.radiosity.tolerance",
                format!("expected a number in (0, 1), got {}", rad.tolerance),
            );
        }
        if rad.max_iterations == 0 {
            c.error("render.radiosity.max_iterations", "expected at least 1");
        }
        c.issues
    }
}

impl Scene {
    /// Whether anything lights the scene: a light of any kind, an object
    /// with an emissive material, or an environment map.
    pub fn has_light_source(&self) -> bool {
        let emits = |m: super::MaterialId| {
            self.materials
                .get(m.index())
                .is_some_and(|m| m.is_emissive())
        };
        !self.lights.is_empty()
            || self.environment.is_some()
            || self.objects.iter().any(|o| {
                emits(o.material)
                    || matches!(o.geometry, Geometry::Mesh(id) if self
                        .meshes
                        .get(id.index())
                        .is_some_and(|mesh| mesh.face_materials.iter().any(|&f| emits(f))))
            })
    }

    /// Checks the whole scene and returns every problem found (empty when
    /// the scene is fine). Errors make a scene unrenderable; warnings do not.
    pub fn validate(&self) -> Vec<Issue> {
        self.validate_with(&self.render)
    }

    /// [`Self::validate`] with `settings` in place of the scene's own
    /// `render` table (a render whose settings were overridden), without
    /// copying the scene.
    pub fn validate_with(&self, settings: &RenderSettings) -> Vec<Issue> {
        let mut c = Checker { issues: Vec::new() };
        c.issues.extend(settings.validate());

        check_camera(&mut c, "camera", &self.camera);
        for (i, nc) in self.cameras.iter().enumerate() {
            check_camera(&mut c, &format!("cameras[{i}]"), &nc.camera);
        }

        let ntex = self.textures.len();
        let check_tex = |c: &mut Checker, path: String, t: Option<super::TextureId>| {
            if let Some(t) = t
                && t.index() >= ntex
            {
                c.error(
                    path,
                    format!("texture index {} out of range ({} textures)", t.0, ntex),
                );
            }
        };

        for (i, m) in self.materials.iter().enumerate() {
            let p = format!("materials[{i}] ({})", m.name);
            c.non_negative(&format!("{p}.ambient"), m.ambient);
            c.non_negative(&format!("{p}.diffuse"), m.diffuse);
            c.non_negative(&format!("{p}.specular"), m.specular);
            c.non_negative(&format!("{p}.reflect"), m.reflect);
            c.non_negative(&format!("{p}.transmit"), m.transmit);
            c.non_negative(&format!("{p}.emission"), m.emission);
            c.non_negative(&format!("{p}.absorption"), m.absorption);
            if let Some(ior) = m.conductor {
                c.non_negative(&format!("{p}.conductor.eta"), ior.eta);
                c.non_negative(&format!("{p}.conductor.k"), ior.k);
            }
            if !(m.shininess.is_finite() && m.shininess >= 0.0) {
                c.error(
                    format!("{p}.shininess"),
                    format!("expected a finite number >= 0, got {}", m.shininess),
                );
            }
            c.positive_scalar(&format!("{p}.ior"), m.ior);
            if !(m.roughness.is_finite() && m.roughness > 0.0 && m.roughness <= 1.0) {
                c.error(
                    format!("{p}.roughness"),
                    format!("expected 0 < roughness <= 1, got {}", m.roughness),
                );
            }
            if m.diffuse.max_element() > 1.0 {
                c.warn(format!("{p}.diffuse"), "an albedo above 1 creates energy");
            }
            if (m.diffuse + m.reflect + m.transmit).max_element() > 1.0 + 1e-4 {
                c.warn(p.clone(), "diffuse + reflect + transmit exceeds 1: the surface creates energy in the ray tracers");
            }
            check_tex(&mut c, format!("{p}.texture"), m.texture);
            check_tex(&mut c, format!("{p}.normal_map"), m.normal_map);
            check_tex(&mut c, format!("{p}.emission_texture"), m.emission_texture);
            if let Some(b) = m.bump {
                check_tex(&mut c, format!("{p}.bump"), Some(b.texture));
                if !b.height.is_finite() {
                    c.error(format!("{p}.bump.height"), "expected a finite number");
                }
            }
        }

        if !self.objects.is_empty() && !self.has_light_source() {
            c.warn(
                "lights",
                "the scene has no lights, no emissive material and no environment map: \
                 every technique but preview (which brings its own eye light) renders it black",
            );
        }

        for (i, t) in self.textures.iter().enumerate() {
            if let Texture::Image(img) = t
                && (img.width == 0
                    || img.height == 0
                    || (img.texels8.is_some() && !img.texels.is_empty())
                    || img.texel_count() != (img.width as usize * img.height as usize))
            {
                c.error(
                    format!("textures[{i}] ({})", img.source),
                    "image has no texels, a wrong texel count, or both f32 and 8-bit texels",
                );
            }
        }

        for (i, mesh) in self.meshes.iter().enumerate() {
            let p = format!("meshes[{i}] ({})", mesh.name);
            let n = mesh.positions.len();
            if mesh.positions.iter().any(|v| !v.is_finite()) {
                c.error(
                    format!("{p}.positions"),
                    "a vertex position is NaN or infinite",
                );
            } else if let Some(v) = mesh.positions.iter().find(|v| !within_range(**v)) {
                c.error(
                    format!("{p}.positions"),
                    format!("a vertex position is beyond ±{MAX_COORDINATE:e}: {v}"),
                );
            }
            for (name, len) in [
                ("normals", mesh.normals.len()),
                ("uvs", mesh.uvs.len()),
                ("uvs1", mesh.uvs1.len()),
                ("tangents", mesh.tangents.len()),
                ("colors", mesh.colors.len()),
            ] {
                if len != 0 && len != n {
                    c.error(
                        format!("{p}.{name}"),
                        format!("expected 0 or {n} entries, got {len}"),
                    );
                }
            }
            if mesh.normals.iter().any(|v| !v.is_finite())
                || mesh.uvs.iter().chain(&mesh.uvs1).any(|v| !v.is_finite())
            {
                c.error(p.clone(), "a normal or uv is NaN or infinite");
            }
            if let Some((t, tri)) = mesh
                .indices
                .iter()
                .enumerate()
                .find(|(_, t)| t.iter().any(|&k| k as usize >= n))
            {
                c.error(
                    format!("{p}.indices[{t}]"),
                    format!("vertex index out of range in {tri:?} ({n} vertices)"),
                );
            }
            let degenerate = mesh
                .indices
                .iter()
                .filter(|t| {
                    t.iter().all(|&k| (k as usize) < n) && {
                        let [a, b, cc] = t.map(|k| mesh.positions[k as usize]);
                        (b - a).cross(cc - a).length_squared() == 0.0
                    }
                })
                .count();
            if degenerate > 0 {
                c.warn(
                    p.clone(),
                    format!("{degenerate} zero-area triangle(s) will not be drawn"),
                );
            }
            if !mesh.face_materials.is_empty() && mesh.face_materials.len() != mesh.indices.len() {
                c.error(
                    format!("{p}.face_materials"),
                    format!(
                        "expected 0 or {} entries, got {}",
                        mesh.indices.len(),
                        mesh.face_materials.len()
                    ),
                );
            }
            if let Some(m) = mesh
                .face_materials
                .iter()
                .find(|m| m.index() >= self.materials.len())
            {
                c.error(
                    format!("{p}.face_materials"),
                    format!(
                        "material index {} out of range ({} materials)",
                        m.0,
                        self.materials.len()
                    ),
                );
            }
        }

        for (i, o) in self.objects.iter().enumerate() {
            let p = format!("objects[{i}] ({})", o.name);
            if o.material.index() >= self.materials.len() {
                c.error(
                    format!("{p}.material"),
                    format!(
                        "material index {} out of range ({} materials)",
                        o.material.0,
                        self.materials.len()
                    ),
                );
            }
            match o.geometry {
                Geometry::Mesh(m) if m.index() >= self.meshes.len() => {
                    c.error(
                        format!("{p}.mesh"),
                        format!(
                            "mesh index {} out of range ({} meshes)",
                            m.0,
                            self.meshes.len()
                        ),
                    );
                }
                Geometry::Sphere { radius } => c.positive_scalar(&format!("{p}.radius"), radius),
                Geometry::Mesh(_) => {}
            }
            let m = o.transform.world_from_object();
            if !m.is_finite() {
                c.error(
                    format!("{p}.transform"),
                    "transform has NaN or infinite entries",
                );
            } else if m.determinant().abs() < 1e-20 {
                c.error(
                    format!("{p}.transform"),
                    "transform is singular (a scale of 0?)",
                );
            }
            // Where the object lands: the corners of its local box moved
            // into the world.
            let local = match o.geometry {
                Geometry::Sphere { radius } if radius.is_finite() => {
                    Some((Vec3::splat(-radius), Vec3::splat(radius)))
                }
                Geometry::Mesh(id) => self.meshes.get(id.index()).and_then(|mesh| {
                    let ps = mesh.positions.iter().filter(|v| within_range(**v));
                    let lo = ps.clone().copied().reduce(Vec3::min)?;
                    Some((lo, ps.copied().fold(lo, Vec3::max)))
                }),
                Geometry::Sphere { .. } => None,
            };
            if let Some((lo, hi)) = local
                && m.is_finite()
            {
                let far = (0..8)
                    .map(|k| {
                        let corner = Vec3::select(
                            glam::BVec3::new(k & 1 != 0, k & 2 != 0, k & 4 != 0),
                            hi,
                            lo,
                        );
                        m.transform_point3(corner)
                    })
                    .find(|w| !within_range(*w));
                if let Some(w) = far {
                    c.error(
                        format!("{p}.transform"),
                        format!("the object reaches {w} in the world, beyond ±{MAX_COORDINATE:e}"),
                    );
                }
            }
        }

        for (i, l) in self.lights.iter().enumerate() {
            let p = format!("lights[{i}] ({})", l.kind());
            c.non_negative(&format!("{p}.color"), l.power_rgb());
            match l {
                Light::Point { position, .. } => {
                    c.coordinate(&format!("{p}.position"), *position);
                }
                Light::Directional { direction, .. } => {
                    c.finite(&format!("{p}.direction"), *direction);
                    if direction.length_squared() == 0.0 {
                        c.error(format!("{p}.direction"), "direction is the zero vector");
                    }
                }
                Light::Spot(s) => {
                    c.coordinate(&format!("{p}.position"), s.position);
                    c.finite(&format!("{p}.direction"), s.direction);
                    if s.direction.length_squared() == 0.0 {
                        c.error(format!("{p}.direction"), "direction is the zero vector");
                    }
                    if !(s.cone_degrees > 0.0 && s.cone_degrees <= 180.0) {
                        c.error(
                            format!("{p}.cone"),
                            format!("expected 0 < cone <= 180 degrees, got {}", s.cone_degrees),
                        );
                    }
                    if !(s.exponent.is_finite() && s.exponent >= 0.0) {
                        c.error(format!("{p}.exponent"), "expected a finite number >= 0");
                    }
                }
                Light::Area { shape, .. } => {
                    if !(shape.area().is_finite() && shape.area() > 0.0) {
                        c.error(
                            format!("{p}.shape"),
                            "area light has zero or non-finite area",
                        );
                    }
                    let (at, reach) = match shape {
                        AreaShape::Quad {
                            corner,
                            edge_u,
                            edge_v,
                        } => (*corner, edge_u.abs() + edge_v.abs()),
                        AreaShape::Disk { center, radius, .. }
                        | AreaShape::Sphere { center, radius } => (*center, Vec3::splat(*radius)),
                        AreaShape::Triangle { a, b, c } => (*a, (*b - *a).abs() + (*c - *a).abs()),
                    };
                    c.coordinate(&format!("{p}.shape"), at.abs() + reach.abs());
                    if let AreaShape::Disk { normal, .. } = shape
                        && normal.length_squared() == 0.0
                    {
                        c.error(format!("{p}.normal"), "normal is the zero vector");
                    }
                }
                Light::Ambient { .. } => {}
            }
        }
        if let Some(env) = &self.environment {
            check_tex(&mut c, "environment".into(), Some(env.texture));
        }
        c.issues
    }
}

/// Depth cueing needs finite distances with `far > near`, and finite
/// colours and scales.
fn check_depth_cue(c: &mut Checker, cue: &super::DepthCue) {
    c.finite("render.depth_cue.color", cue.color);
    for (path, x) in [
        ("render.depth_cue.max_scale", cue.max_scale),
        ("render.depth_cue.min_scale", cue.min_scale),
    ] {
        if !x.is_finite() {
            c.error(path, format!("expected a finite number, got {x}"));
        }
    }
    if !(cue.near.is_finite() && cue.far.is_finite() && cue.far > cue.near) {
        c.error(
            "render.depth_cue.far",
            format!("expected far > near, got near {} far {}", cue.near, cue.far),
        );
    }
}

/// The checks of one camera, reported under `path` (`camera`, `cameras[2]`).
fn check_camera(c: &mut Checker, path: &str, cam: &super::Camera) {
    c.coordinate(&format!("{path}.eye"), cam.eye);
    c.coordinate(&format!("{path}.look_at"), cam.look_at);
    c.finite(&format!("{path}.up"), cam.up);
    match cam.projection {
        super::Projection::Perspective => {
            if !(cam.fov_y_degrees > 0.0 && cam.fov_y_degrees < 180.0) {
                c.error(
                    format!("{path}.fov"),
                    format!("expected 0 < fov < 180 degrees, got {}", cam.fov_y_degrees),
                );
            }
        }
        super::Projection::Orthographic { half_height } => {
            if !(half_height > 0.0 && half_height.is_finite()) {
                c.error(
                    format!("{path}.half_height"),
                    format!("expected a finite half-height > 0, got {half_height}"),
                );
            }
        }
    }
    if (cam.look_at - cam.eye).length_squared() == 0.0 {
        c.error(
            format!("{path}.look_at"),
            "eye and look_at are the same point",
        );
    }
    // Named by the distance that is wrong: `near` when it is not > 0.
    let which = if cam.near > 0.0 { "far" } else { "near" };
    if !(cam.near > 0.0 && cam.far > cam.near && cam.far.is_finite()) {
        c.error(
            format!("{path}.{which}"),
            format!(
                "expected 0 < near < far, got near {} far {}",
                cam.near, cam.far
            ),
        );
    }
}

/// Finite and within [`MAX_COORDINATE`] on every axis.
fn within_range(v: Vec3) -> bool {
    v.is_finite() && v.abs().max_element() <= MAX_COORDINATE
}

#[cfg(test)]
mod tests {
    use super::super::*;

    #[test]
    fn reports_every_problem() {
        let mut s = Scene::default();
        s.render.width = 0;
        s.camera.fov_y_degrees = 200.0;
        s.objects.push(Object {
            material: MaterialId(3),
            geometry: Geometry::Mesh(MeshId(9)),
            ..Default::default()
        });
        let issues = s.validate();
        let errors = issues
            .iter()
            .filter(|i| i.severity == Severity::Error)
            .count();
        assert!(errors >= 4, "{issues:#?}");
    }

    /// Geometry near `f32::MAX` (a fuzzed quad corner of 3.4e38, a cube
    /// moved by 1e30) overflowed the BVH's slab test into infinities and
    /// NaNs; such a scene is refused, naming what is too far out.
    #[test]
    fn coordinates_beyond_the_range_are_refused() {
        use crate::geometry::primitives;
        use crate::scene::{Light, Material, Transform};
        let with = |corner_z: f32, shift: f32| {
            let mut s = Scene::default();
            let m = s.add_material(Material::default());
            let q = primitives::quad(Vec3::new(0.0, 0.0, corner_z), Vec3::X, Vec3::Y);
            let mesh = s.add_mesh(q);
            s.objects.push(Object {
                material: m,
                geometry: Geometry::Mesh(mesh),
                transform: Transform {
                    translate: Vec3::new(shift, 0.0, 0.0),
                    ..Default::default()
                },
                ..Default::default()
            });
            s.lights.push(Light::Point {
                position: Vec3::new(0.0, 2.0, 0.0),
                color: Vec3::ONE,
                intensity: 1.0,
                attenuation: Default::default(),
            });
            s.validate()
                .into_iter()
                .filter(|i| i.severity == Severity::Error)
                .map(|i| i.path)
                .collect::<Vec<_>>()
        };
        assert!(with(1.0, 1e3).is_empty());
        assert_eq!(with(3.4e38, 0.0), ["meshes[0] (quad).positions"]);
        assert_eq!(with(1.0, 1e30), ["objects[0] ().transform"]);
    }

    #[test]
    fn shadow_map_resolution_is_bounded() {
        for (res, ok) in [(16, true), (8192, true), (0, false), (16384, false)] {
            let mut s = Scene::default();
            s.render.shadow_map.resolution = res;
            let bad: Vec<_> = s
                .validate()
                .into_iter()
                .filter(|i| i.path == "render.shadow_map.resolution")
                .collect();
            assert_eq!(bad.is_empty(), ok, "{res}: {bad:?}");
        }
    }

    #[test]
    fn every_settings_error_names_its_setting() {
        use crate::scene::Technique;
        let mut r = RenderSettings {
            technique: Technique::Phong,
            samples: 100,
            light_samples: 0,
            ..RenderSettings::default()
        };
        r.path.max_depth = 0;
        r.radiosity.solver = RadiositySolver::Hierarchical;
        r.radiosity.formfactor = FormFactorMethod::Hemicube;
        r.radiosity.tolerance = f32::NAN;
        r.radiosity.max_iterations = 0;
        let issues = r.validate();
        let paths = |sev: Severity| -> Vec<&str> {
            issues
                .iter()
                .filter(|i| i.severity == sev)
                .map(|i| i.path.as_str())
                .collect()
        };
        assert_eq!(
            paths(Severity::Error),
            [
                "render.light_samples",
                "render.path.max_depth",
                "render.radiosity.formfactor",
                "render.radiosity.tolerance",
                "render.radiosity.max_iterations",
            ],
            "{issues:#?}"
        );
        // The scan converter's sample cap is its own check (chiaro-raster).
        assert_eq!(paths(Severity::Warning), Vec::<&str>::new(), "{issues:#?}");
        assert!(RenderSettings::default().validate().is_empty());
    }

    /// The checks the scene file used to make alone: each image side, the
    /// light samples' upper bound and the depth cue's distances.
    #[test]
    fn size_light_samples_and_depth_cue_name_their_setting() {
        let errors = |r: &RenderSettings| -> Vec<(String, String)> {
            r.validate()
                .into_iter()
                .filter(|i| i.severity == Severity::Error)
                .map(|i| (i.path, i.message))
                .collect()
        };
        let pair = |p: &str, m: &str| (p.to_string(), m.to_string());
        let mut r = RenderSettings {
            width: 0,
            height: MAX_IMAGE_SIDE + 1,
            light_samples: MAX_SAMPLES + 1,
            depth_cue: Some(DepthCue {
                near: 5.0,
                far: 5.0,
                ..DepthCue::default()
            }),
            ..RenderSettings::default()
        };
        assert_eq!(
            errors(&r),
            [
                pair("render.width", "expected 1..=16384, got 0"),
                pair("render.height", "expected 1..=16384, got 16385"),
                pair(
                    "render.light_samples",
                    "expected 1..=65536 samples per area light, got 65537"
                ),
                pair(
                    "render.depth_cue.far",
                    "expected far > near, got near 5 far 5"
                ),
            ]
        );
        r.width = 16_000;
        r.height = 16_000;
        r.light_samples = MAX_SAMPLES;
        r.depth_cue = Some(DepthCue {
            far: f32::INFINITY,
            ..DepthCue::default()
        });
        assert_eq!(
            errors(&r),
            [
                pair(
                    "render.height",
                    "image 16000x16000 has more than 67108864 pixels"
                ),
                pair(
                    "render.depth_cue.far",
                    "expected far > near, got near 0 far inf"
                ),
            ]
        );
        r.width = 8192;
        r.height = 8192;
        r.depth_cue = Some(DepthCue::default());
        assert!(errors(&r).is_empty(), "{:?}", errors(&r));
    }

    #[test]
    fn default_scene_is_valid() {
        assert!(Scene::default().validate().is_empty());
    }
}
