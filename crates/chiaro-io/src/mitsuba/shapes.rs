//! `<shape>` plugins: `obj` and `ply` files, the analytic `sphere`, the
//! meshed primitives `rectangle`, `cube`, `disk` and `cylinder`, and
//! `shapegroup` / `instance` (the group's shapes placed once per instance
//! over shared meshes: chiaro's two-level BVH instances them).

use super::Builder;
use super::bsdfs::{AttributeUse, Built};
use super::props::Props;
use super::xml::Element;
use crate::{Imported, Result};
use chiaro_core::scene::{Geometry, Material, MaterialId, Mesh, Object, Sidedness, Transform};
use chiaro_core::{Mat4, Vec2, Vec3};
use std::f32::consts::TAU;

/// Segments around a meshed disk or cylinder.
pub const SEGMENTS: u32 = 64;

impl Builder<'_> {
    /// A `<shape>` placed with `world_from_parent` (identity at top level,
    /// the instance's transform inside a shape group).
    pub fn shape(&mut self, el: &Element, world_from_parent: Mat4) -> Result<()> {
        self.shape_at(el, world_from_parent, 0)
    }

    fn shape_at(&mut self, el: &Element, parent: Mat4, depth: usize) -> Result<()> {
        let ty = Self::plugin_type(el)?;
        let p = Props::new(el);
        match ty {
            // Its shapes are drawn only through an `instance`.
            "shapegroup" => {
                if depth == 0 && el.attr("id").is_none() {
                    self.warn(
                        el,
                        "a shapegroup without an id cannot be instanced; ignored",
                    );
                }
                return Ok(());
            }
            "instance" => {
                // Mitsuba does not nest instances; refusing them also keeps a
                // group instancing itself many times from growing exponentially.
                if depth > 0 {
                    return Err(el.loc.error("an instance inside a shapegroup is refused (Mitsuba does not nest instances)"));
                }
                let m = parent * p.transform("to_world")?;
                let refs = p.children("ref");
                let Some(r) = refs.first() else {
                    return Err(el
                        .loc
                        .error("<shape type=\"instance\"> needs a <ref id=...> to a shapegroup"));
                };
                let group = self.lookup(r)?;
                if group.tag != "shape" || group.attr("type") != Some("shapegroup") {
                    return Err(r
                        .loc
                        .error("an instance's <ref> must name a <shape type=\"shapegroup\">"));
                }
                for child in &group.children {
                    if child.tag == "shape" {
                        self.shape_at(child, m, depth + 1)?;
                    }
                }
                self.warn_unused(&p);
                return Ok(());
            }
            _ => {}
        }
        let m = parent * p.transform("to_world")?;
        // A `<ref>` names the BSDF or an area emitter declared at the top.
        let (mut emitter_refs, mut bsdf_refs) = (Vec::new(), Vec::new());
        for r in p.children("ref") {
            if self.lookup(r)?.tag == "emitter" {
                emitter_refs.push(self.lookup(r)?);
            } else {
                bsdf_refs.push(r);
            }
        }
        // The BSDF: nested, referenced, or Mitsuba's default diffuse 0.5.
        let bsdf_el = p.children("bsdf").into_iter().chain(bsdf_refs).next();
        let (mut material, built) = match bsdf_el {
            Some(b) => self.material_of(b)?,
            None => self.default_material(),
        };
        if let Some(e) = p.children("emitter").into_iter().chain(emitter_refs).next() {
            let l = self.area_radiance(e)?;
            let mut em: Material = self.scene.materials[material.index()].clone();
            em.emission = l;
            // Mitsuba's area emitters emit from the front only, whatever
            // the BSDF.
            em.emission_two_sided = false;
            em.name = format!("{} (emitter)", em.name);
            material = self.scene.add_material(em);
        }
        if !p.children("medium").is_empty()
            || p.named("interior").is_some()
            || p.named("exterior").is_some()
        {
            self.warn(el, "ignored: media (chiaro has no participating media)");
        }
        let flip = p.boolean("flip_normals", false)?;
        let face_normals = p.boolean("face_normals", false)?;
        match ty {
            "obj" | "ply" => {
                let name = p.string("filename")?.ok_or_else(|| {
                    el.loc.error(format!(
                        "<shape type=\"{ty}\"> needs a <string name=\"filename\">"
                    ))
                })?;
                if ty == "obj" && !p.boolean("flip_tex_coords", true)? {
                    self.warn(el, "approximate: flip_tex_coords=false is ignored (chiaro flips OBJ texture coordinates as Mitsuba does by default)");
                }
                let _ = p.named("maintain_topology");
                let path = self.resolve(name);
                self.mesh_file(el, ty, &path, m, material, &built, flip, face_normals)?;
            }
            "sphere" => {
                let center = p.vector("center", Vec3::ZERO)?;
                let radius = p.float("radius", 1.0)?;
                let c = m.transform_point3(center);
                let axes = [Vec3::X, Vec3::Y, Vec3::Z].map(|a| m.transform_vector3(a).length());
                let s = axes[0];
                if axes.iter().any(|a| (a - s).abs() > 1e-4 * s.max(1e-6)) {
                    self.warn(el, "approximate: a non-uniformly scaled sphere is drawn round (the mean scale)");
                }
                let s = (axes[0] + axes[1] + axes[2]) / 3.0;
                if radius <= 0.0 || s <= 0.0 {
                    return Err(el.loc.error(format!(
                        "sphere radius must be positive, got {}",
                        radius * s
                    )));
                }
                if built.attribute.is_some() {
                    return Err(el.loc.error(
                        "a mesh_attribute texture needs a mesh (obj or ply), not a sphere",
                    ));
                }
                self.scene.objects.push(Object {
                    name: object_name(el),
                    geometry: Geometry::Sphere { radius: radius * s },
                    material,
                    transform: Transform::from_matrix(Mat4::from_translation(c)),
                    ..Object::default()
                });
            }
            "rectangle" | "cube" | "disk" | "cylinder" => {
                let mesh = match ty {
                    "rectangle" => rectangle(),
                    "cube" => cube(),
                    "disk" => {
                        self.warn(el, &format!("approximate: meshed with {SEGMENTS} segments"));
                        disk()
                    }
                    _ => {
                        let p0 = p.vector("p0", Vec3::ZERO)?;
                        let p1 = p.vector("p1", Vec3::Z)?;
                        let r = p.float("radius", 1.0)?;
                        self.warn(el, &format!("approximate: meshed with {SEGMENTS} segments"));
                        cylinder(p0, p1, r).ok_or_else(|| {
                            el.loc
                                .error("cylinder: p0 and p1 coincide or the radius is not positive")
                        })?
                    }
                };
                if built.attribute.is_some() {
                    return Err(el
                        .loc
                        .error("a mesh_attribute texture needs a mesh file (obj or ply)"));
                }
                // One copy of each primitive's mesh, shared by its placements.
                let key = format!(
                    "{ty}|{flip}|{}",
                    if ty == "cylinder" {
                        el.loc.describe()
                    } else {
                        String::new()
                    }
                );
                let id = match self.primitives.get(&key) {
                    Some(id) => *id,
                    None => {
                        let mut mesh = mesh;
                        mesh.name = ty.to_owned();
                        if flip {
                            flip_mesh(&mut mesh);
                        }
                        let id = self.scene.add_mesh(mesh);
                        self.primitives.insert(key, id);
                        id
                    }
                };
                self.scene.objects.push(Object {
                    name: object_name(el),
                    geometry: Geometry::Mesh(id),
                    material,
                    transform: Transform::from_matrix(m),
                    smooth: !face_normals,
                    crease_angle_degrees: 180.0,
                    ..Object::default()
                });
            }
            other => {
                return Err(el.loc.error(format!(
                    "unknown shape plugin \"{other}\" (chiaro reads obj, ply, sphere, rectangle, cube, disk, cylinder, shapegroup and instance)"
                )));
            }
        }
        self.warn_unused(&p);
        Ok(())
    }

    /// Mitsuba's default BSDF: diffuse of reflectance 0.5.
    fn default_material(&mut self) -> (MaterialId, Built) {
        let key = "bsdf:<default>".to_owned();
        if let Some((id, b)) = self.built.get(&key) {
            return (*id, b.clone());
        }
        let m = Material {
            name: "mitsuba-default".into(),
            ambient: Vec3::ZERO,
            sidedness: Sidedness::OneSided,
            ..Material::diffuse("mitsuba-default", Vec3::splat(0.5))
        };
        let built = Built {
            material: m.clone(),
            attribute: None,
        };
        let id = self.scene.add_material(m);
        self.built.insert(key, (id, built.clone()));
        (id, built)
    }

    /// An `obj` or `ply` file placed with `m`: read once, its meshes shared
    /// by every placement with the same material.
    #[allow(clippy::too_many_arguments)]
    fn mesh_file(
        &mut self,
        el: &Element,
        ty: &str,
        path: &std::path::Path,
        m: Mat4,
        material: MaterialId,
        built: &Built,
        flip: bool,
        face_normals: bool,
    ) -> Result<()> {
        let template = Object {
            name: object_name(el),
            smooth: !face_normals,
            crease_angle_degrees: 180.0,
            ..Object::default()
        };
        if let Some(use_) = &built.attribute {
            // Attributes change the mesh itself: one copy per shape.
            let imported = self.attributed_mesh(el, path, use_)?;
            imported.merge_into(&mut self.scene, m, Some(material), &template);
            return Ok(());
        }
        let key = (path.to_path_buf(), material.0, flip);
        let shared = match self.shared.get(&key) {
            Some(s) => *s,
            None => {
                if !self.files.contains_key(&(path.to_path_buf(), flip)) {
                    let mut imported = self.read_mesh(el, ty, path)?;
                    if flip {
                        imported.meshes.iter_mut().for_each(flip_mesh);
                    }
                    self.files.insert((path.to_path_buf(), flip), imported);
                }
                let imported = &self.files[&(path.to_path_buf(), flip)];
                let s = imported.add_shared(&mut self.scene, Some(material));
                self.shared.insert(key, s);
                s
            }
        };
        let imported = &self.files[&(path.to_path_buf(), flip)];
        imported.place(&mut self.scene, &shared, m, &template);
        Ok(())
    }

    /// Reads a mesh file as Mitsuba does: OBJ texture coordinates flipped
    /// (as chiaro's reader does), PLY's as they are (chiaro's PLY reader
    /// flips them, so they are flipped back). The file's own materials are
    /// replaced by the shape's BSDF.
    fn read_mesh(&mut self, el: &Element, ty: &str, path: &std::path::Path) -> Result<Imported> {
        let read = if ty == "obj" {
            crate::obj::load_obj_meshes(path)
        } else {
            crate::ply::load_ply(path)
        };
        let mut imported = read.map_err(|e| el.loc.error(format!("{ty} shape: {e}")))?;
        if ty == "ply" {
            for mesh in &mut imported.meshes {
                for uv in &mut mesh.uvs {
                    uv.y = 1.0 - uv.y;
                }
            }
        }
        for w in std::mem::take(&mut imported.warnings) {
            self.warnings.push(w);
        }
        Ok(imported)
    }

    /// A PLY mesh whose diffuse colour comes from Mitsuba mesh attributes:
    /// `vertex_NAME` (properties `NAME_0..`) as vertex colours, `face_NAME`
    /// as the colour of each face's corners (the faces unwelded).
    fn attributed_mesh(
        &mut self,
        el: &Element,
        path: &std::path::Path,
        use_: &AttributeUse,
    ) -> Result<Imported> {
        if crate::lowercase_extension(path) != "ply" {
            return Err(el
                .loc
                .error("mesh_attribute textures are read from PLY files only"));
        }
        let (mut imported, extra) = crate::ply::load_ply_with_properties(path)
            .map_err(|e| el.loc.error(format!("ply shape: {e}")))?;
        for mesh in &mut imported.meshes {
            for uv in &mut mesh.uvs {
                uv.y = 1.0 - uv.y;
            }
        }
        type ToColor = Box<dyn Fn(&[f32]) -> Vec3>;
        let (name, map): (&str, ToColor) = match use_ {
            AttributeUse::Color(n) => (
                n.as_str(),
                Box::new(|v: &[f32]| match v {
                    [x] => Vec3::splat(*x),
                    [r, g, b, ..] => Vec3::new(*r, *g, *b),
                    _ => Vec3::ZERO,
                }),
            ),
            AttributeUse::Blend { weight, a, b } => {
                let (a, b) = (*a, *b);
                (
                    weight.as_str(),
                    Box::new(move |v: &[f32]| a.lerp(b, v.first().copied().unwrap_or(0.0))),
                )
            }
        };
        let (scope, base) = if let Some(b) = name.strip_prefix("vertex_") {
            ("vertex", b)
        } else if let Some(b) = name.strip_prefix("face_") {
            ("face", b)
        } else {
            return Err(el.loc.error(format!(
                "mesh attribute \"{name}\" must start with vertex_ or face_"
            )));
        };
        let props = if scope == "vertex" {
            &extra.vertex
        } else {
            &extra.face
        };
        let channels: Vec<&Vec<f32>> = (0..4)
            .map_while(|i| {
                props
                    .iter()
                    .find(|(k, _)| *k == format!("{base}_{i}"))
                    .map(|(_, v)| v)
            })
            .collect();
        if channels.is_empty() {
            return Err(el.loc.error(format!(
                "{}: no {scope} properties {base}_0, {base}_1, ... for mesh attribute \"{name}\"",
                path.display()
            )));
        }
        let value = |i: usize| -> Vec3 {
            let v: Vec<f32> = channels
                .iter()
                .map(|c| c.get(i).copied().unwrap_or(0.0))
                .collect();
            map(&v)
        };
        let Some(mesh) = imported.meshes.first_mut() else {
            return Err(el.loc.error("the PLY file has no mesh"));
        };
        if scope == "vertex" {
            mesh.colors = (0..mesh.positions.len()).map(value).collect();
        } else {
            // Each triangle's corners get their own vertices, coloured by its face.
            let face_of: Vec<usize> = extra
                .triangles_per_face
                .iter()
                .enumerate()
                .flat_map(|(f, &n)| std::iter::repeat_n(f, n as usize))
                .collect();
            let mut out = Mesh {
                name: mesh.name.clone(),
                ..Mesh::default()
            };
            for (t, tri) in mesh.indices.iter().enumerate() {
                let c = value(face_of.get(t).copied().unwrap_or(0));
                let base_index = out.positions.len() as u32;
                for &v in tri {
                    let v = v as usize;
                    out.positions.push(mesh.positions[v]);
                    if !mesh.normals.is_empty() {
                        out.normals.push(mesh.normals[v]);
                    }
                    if !mesh.uvs.is_empty() {
                        out.uvs.push(mesh.uvs[v]);
                    }
                    out.colors.push(c);
                }
                out.indices
                    .push([base_index, base_index + 1, base_index + 2]);
            }
            *mesh = out;
        }
        for w in std::mem::take(&mut imported.warnings) {
            self.warnings.push(w);
        }
        Ok(imported)
    }
}

/// A name for the object: its id, else the plugin and line.
fn object_name(el: &Element) -> String {
    el.attr("id").map_or_else(
        || format!("{}@{}", el.attr("type").unwrap_or("shape"), el.loc.line),
        str::to_owned,
    )
}

/// Reverses the winding and the normals (Mitsuba's `flip_normals`).
fn flip_mesh(mesh: &mut Mesh) {
    for t in &mut mesh.indices {
        t.swap(1, 2);
    }
    for n in &mut mesh.normals {
        *n = -*n;
    }
}

/// Mitsuba's `rectangle`: `[-1, 1]^2` in the z = 0 plane, facing +z, uv
/// `((x + 1) / 2, (y + 1) / 2)`.
pub fn rectangle() -> Mesh {
    let p = [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)];
    Mesh {
        positions: p.iter().map(|&(x, y)| Vec3::new(x, y, 0.0)).collect(),
        normals: vec![Vec3::Z; 4],
        uvs: p
            .iter()
            .map(|&(x, y)| Vec2::new(0.5 * (x + 1.0), 0.5 * (y + 1.0)))
            .collect(),
        indices: vec![[0, 1, 2], [0, 2, 3]],
        ..Mesh::default()
    }
}

/// Mitsuba's `cube`: `[-1, 1]^3`, each face its own four vertices with an
/// outward normal and uv `[0, 1]^2`.
pub fn cube() -> Mesh {
    let mut mesh = Mesh::default();
    for axis in 0..3 {
        for sign in [-1.0f32, 1.0] {
            let mut n = Vec3::ZERO;
            n[axis] = sign;
            // Two in-face directions whose cross product is the normal.
            let mut u = Vec3::ZERO;
            u[(axis + 1) % 3] = 1.0;
            let v = n.cross(u);
            let base = mesh.positions.len() as u32;
            for (s, t) in [(-1.0f32, -1.0f32), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
                mesh.positions.push(n + s * u + t * v);
                mesh.normals.push(n);
                mesh.uvs.push(Vec2::new(0.5 * (s + 1.0), 0.5 * (t + 1.0)));
            }
            mesh.indices.push([base, base + 1, base + 2]);
            mesh.indices.push([base, base + 2, base + 3]);
        }
    }
    mesh
}

/// Mitsuba's `disk`: radius 1 in the z = 0 plane facing +z, as a fan of
/// `SEGMENTS` (64) triangles; uv `(r, phi / 2 pi)`.
pub fn disk() -> Mesh {
    let mut mesh = Mesh {
        positions: vec![Vec3::ZERO],
        normals: vec![Vec3::Z],
        uvs: vec![Vec2::ZERO],
        ..Mesh::default()
    };
    for i in 0..=SEGMENTS {
        let phi = TAU * i as f32 / SEGMENTS as f32;
        mesh.positions.push(Vec3::new(phi.cos(), phi.sin(), 0.0));
        mesh.normals.push(Vec3::Z);
        mesh.uvs.push(Vec2::new(1.0, i as f32 / SEGMENTS as f32));
    }
    for i in 0..SEGMENTS {
        mesh.indices.push([0, i + 1, i + 2]);
    }
    mesh
}

/// Mitsuba's `cylinder` from `p0` to `p1` of radius `r`, open at both ends,
/// normals outward; `None` when degenerate.
pub fn cylinder(p0: Vec3, p1: Vec3, r: f32) -> Option<Mesh> {
    let axis = p1 - p0;
    let dir = axis.try_normalize()?;
    if !(r > 0.0 && r.is_finite()) {
        return None;
    }
    let (a, b) = dir.any_orthonormal_pair();
    let mut mesh = Mesh::default();
    for i in 0..=SEGMENTS {
        let phi = TAU * i as f32 / SEGMENTS as f32;
        let n = a * phi.cos() + b * phi.sin();
        for (k, end) in [p0, p1].into_iter().enumerate() {
            mesh.positions.push(end + r * n);
            mesh.normals.push(n);
            mesh.uvs
                .push(Vec2::new(i as f32 / SEGMENTS as f32, k as f32));
        }
    }
    for i in 0..SEGMENTS {
        let (s0, e0, s1, e1) = (2 * i, 2 * i + 1, 2 * i + 2, 2 * i + 3);
        mesh.indices.push([s0, s1, e1]);
        mesh.indices.push([s0, e1, e0]);
    }
    Some(mesh)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every triangle's winding normal agrees with its vertex normals.
    fn outward(mesh: &Mesh) {
        for t in &mesh.indices {
            let [a, b, c] = t.map(|i| mesh.positions[i as usize]);
            let n = (b - a).cross(c - a);
            assert!(n.dot(mesh.normals[t[0] as usize]) > 0.0, "{t:?}");
        }
    }

    #[test]
    fn primitives_face_their_normals() {
        outward(&rectangle());
        outward(&cube());
        outward(&disk());
        outward(&cylinder(Vec3::ZERO, Vec3::Z, 0.5).expect("test input"));
        // Cube normals point away from the centre.
        let c = cube();
        for (p, n) in c.positions.iter().zip(&c.normals) {
            assert!(p.dot(*n) > 0.9);
        }
        assert_eq!(cube().indices.len(), 12);
        assert!(cylinder(Vec3::ONE, Vec3::ONE, 1.0).is_none());
    }
}
