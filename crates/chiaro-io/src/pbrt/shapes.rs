//! `Shape` directives: `trianglemesh`, `bilinearmesh`, `plymesh` (chiaro's
//! PLY reader), `sphere` (chiaro's analytic sphere), `disk` and `cylinder`
//! (meshed as the Mitsuba reader meshes them).
//!
//! A triangle's front in pbrt is its counter-clockwise side, as in chiaro,
//! except where the mesh has normals `N` (pbrt turns the geometric normal
//! to their side) or `ReverseOrientation` is in effect (meshes without
//! `N`): the winding is turned to match, so one-sided emitters shine the
//! way they do in pbrt.

use super::Builder;
use super::lexer::{Lexer, Loc};
use super::params::Params;
use crate::Result;
use crate::mitsuba::shapes::{SEGMENTS, cylinder, disk};
use chiaro_core::scene::{Geometry, Mesh, Object, Transform};
use chiaro_core::{Mat4, Vec2, Vec3};

/// The shapes this module reads.
pub const SHAPES: &[&str] = &[
    "trianglemesh",
    "bilinearmesh",
    "plymesh",
    "sphere",
    "disk",
    "cylinder",
];

/// The uniform scale and centre of a sphere placed by `m` (the mean of
/// the axes' scales).
pub fn sphere_placement(m: Mat4) -> (f32, Vec3) {
    let axes = [Vec3::X, Vec3::Y, Vec3::Z].map(|a| m.transform_vector3(a).length());
    (
        (axes[0] + axes[1] + axes[2]) / 3.0,
        m.transform_point3(Vec3::ZERO),
    )
}

impl Builder {
    /// A `Shape` directive.
    pub fn shape(&mut self, loc: &Loc, lx: &mut Lexer) -> Result<()> {
        let ty = lx.string("a shape type")?;
        let p = Params::read(lx)?;
        let what = format!("Shape \"{}\"", ty.text);
        let ctm = self.ctm();
        for k in ["alpha", "emissionfilename"] {
            if p.has(k) {
                self.warn(loc, &what, &format!("approximate: \"{k}\" is ignored"));
            }
        }
        let reverse = self.reverse_orientation();
        match ty.text.as_str() {
            "trianglemesh" | "bilinearmesh" | "loopsubdiv" => {
                if ty.text == "loopsubdiv" {
                    return Err(ty.loc.error("Shape \"loopsubdiv\" is refused: chiaro does not subdivide (convert it to a trianglemesh)"));
                }
                let mesh = mesh_of(&p, loc, &ty.text)?;
                let bilinear = ty.text == "bilinearmesh";
                let mut mesh = if bilinear {
                    let (mesh, planar) = bilinear_to_triangles(mesh);
                    if !planar {
                        self.warn(
                            loc,
                            &what,
                            "approximate: a non-planar patch is drawn as two flat triangles",
                        );
                    }
                    mesh
                } else {
                    mesh
                };
                for k in ["S", "faceIndices", "tangents"] {
                    p.skip(k);
                }
                orient(&mut mesh, reverse);
                mesh.name = format!("{} at {}", ty.text, loc.describe());
                let smooth = !mesh.normals.is_empty();
                let material = self.current_material()?;
                let id = self.scene.add_mesh(mesh);
                self.place(
                    loc,
                    Object {
                        name: mesh_name(loc, &ty.text),
                        geometry: Geometry::Mesh(id),
                        material,
                        transform: Transform::from_matrix(ctm),
                        smooth,
                        crease_angle_degrees: 180.0,
                        ..Object::default()
                    },
                )?;
            }
            "plymesh" => {
                let name = p
                    .string("filename")?
                    .ok_or_else(|| loc.error("Shape \"plymesh\" needs a \"string filename\""))?;
                if p.has("displacement") {
                    p.skip("edgelength");
                    self.warn(loc, &what, "approximate: the displacement is ignored");
                }
                let path = self.resolve(&name);
                let material = self.current_material()?;
                let key = (path.clone(), material.0, reverse);
                let shared = match self.shared.get(&key) {
                    Some(s) => *s,
                    None => {
                        if !self.files.contains_key(&path) {
                            let mut imported = crate::ply::load_ply(&path)
                                .map_err(|e| loc.error(format!("plymesh: {e}")))?;
                            for w in std::mem::take(&mut imported.warnings) {
                                self.warnings.push(w);
                            }
                            self.files.insert(path.clone(), imported);
                        }
                        let mut imported = self.files[&path].clone();
                        for mesh in &mut imported.meshes {
                            orient(mesh, reverse);
                        }
                        let s = imported.add_shared(&mut self.scene, Some(material));
                        self.shared.insert(key.clone(), s);
                        s
                    }
                };
                let template = Object {
                    name: mesh_name(loc, "plymesh"),
                    crease_angle_degrees: 180.0,
                    ..Object::default()
                };
                let imported = &self.files[&path];
                let smooth: Vec<bool> = imported
                    .objects
                    .iter()
                    .map(|o| {
                        imported
                            .meshes
                            .get(o.mesh)
                            .is_some_and(|m| !m.normals.is_empty())
                    })
                    .collect();
                let placed = imported.place(&mut self.scene, &shared, ctm, &template);
                // Taken back out so an object definition can hold them.
                let first = placed.first().copied().unwrap_or(self.scene.objects.len());
                let objects: Vec<Object> = self.scene.objects.drain(first..).collect();
                for (mut o, s) in objects
                    .into_iter()
                    .zip(smooth.iter().chain(std::iter::repeat(&false)))
                {
                    o.smooth = *s;
                    self.place(loc, o)?;
                }
            }
            "sphere" => {
                let radius = p.float("radius", 1.0)?;
                let zmin = p.float("zmin", -radius)?;
                let zmax = p.float("zmax", radius)?;
                let phimax = p.float("phimax", 360.0)?;
                if zmin > -radius || zmax < radius || phimax < 360.0 {
                    self.warn(
                        loc,
                        &what,
                        "approximate: a partial sphere (zmin, zmax, phimax) is drawn whole",
                    );
                }
                let (s, c) = sphere_placement(ctm);
                let axes = [Vec3::X, Vec3::Y, Vec3::Z].map(|a| ctm.transform_vector3(a).length());
                if axes.iter().any(|a| (a - s).abs() > 1e-4 * s.max(1e-6)) {
                    self.warn(loc, &what, "approximate: a non-uniformly scaled sphere is drawn round (the mean scale)");
                }
                if reverse {
                    self.warn(
                        loc,
                        &what,
                        "approximate: ReverseOrientation is ignored (chiaro's sphere faces out)",
                    );
                }
                if !(radius * s > 0.0 && (radius * s).is_finite()) {
                    return Err(p.loc_of("radius").error(format!(
                        "sphere radius must be positive, got {}",
                        radius * s
                    )));
                }
                let material = self.current_material()?;
                self.place(
                    loc,
                    Object {
                        name: mesh_name(loc, "sphere"),
                        geometry: Geometry::Sphere { radius: radius * s },
                        material,
                        transform: Transform::from_matrix(Mat4::from_translation(c)),
                        ..Object::default()
                    },
                )?;
            }
            "disk" | "cylinder" => {
                let radius = p.float("radius", 1.0)?;
                if radius.is_nan() || radius <= 0.0 {
                    return Err(p
                        .loc_of("radius")
                        .error(format!("radius must be positive, got {radius}")));
                }
                if p.float("phimax", 360.0)? < 360.0 || p.float("innerradius", 0.0)? > 0.0 {
                    self.warn(
                        loc,
                        &what,
                        "approximate: phimax and innerradius are ignored (drawn whole)",
                    );
                }
                self.warn(
                    loc,
                    &what,
                    &format!("approximate: meshed with {SEGMENTS} segments"),
                );
                let (mut mesh, m) = if ty.text == "disk" {
                    let h = p.float("height", 0.0)?;
                    (
                        disk(),
                        Mat4::from_translation(Vec3::new(0.0, 0.0, h))
                            * Mat4::from_scale(Vec3::new(radius, radius, 1.0)),
                    )
                } else {
                    let zmin = p.float("zmin", -1.0)?;
                    let zmax = p.float("zmax", 1.0)?;
                    let mesh =
                        cylinder(Vec3::new(0.0, 0.0, zmin), Vec3::new(0.0, 0.0, zmax), radius)
                            .ok_or_else(|| loc.error("cylinder: zmin and zmax coincide"))?;
                    (mesh, Mat4::IDENTITY)
                };
                if reverse {
                    flip_winding(&mut mesh);
                }
                mesh.name = format!("{} at {}", ty.text, loc.describe());
                let material = self.current_material()?;
                let id = self.scene.add_mesh(mesh);
                self.place(
                    loc,
                    Object {
                        name: mesh_name(loc, &ty.text),
                        geometry: Geometry::Mesh(id),
                        material,
                        transform: Transform::from_matrix(ctm * m),
                        crease_angle_degrees: 180.0,
                        ..Object::default()
                    },
                )?;
            }
            "curve" | "cone" | "paraboloid" | "hyperboloid" | "heightfield" | "nurbs" => {
                return Err(ty.loc.error(format!(
                    "Shape \"{}\" is refused: chiaro reads {}",
                    ty.text,
                    SHAPES.join(", ")
                )));
            }
            other => {
                return Err(ty.loc.error(format!(
                    "unknown shape \"{other}\" (chiaro reads {})",
                    SHAPES.join(", ")
                )));
            }
        }
        self.warn_unused(loc, &what, &p);
        Ok(())
    }
}

fn mesh_name(loc: &Loc, ty: &str) -> String {
    format!("{ty} {}:{}", loc.line, loc.column)
}

/// The indexed mesh of a `trianglemesh` or `bilinearmesh` (`P`,
/// `indices`, `N`, `uv`); indices are checked against `P`. uv are flipped
/// to chiaro's top-row `v = 0` (pbrt's image lookups flip `t`).
fn mesh_of(p: &Params, loc: &Loc, ty: &str) -> Result<Mesh> {
    let per = if ty == "bilinearmesh" { 4 } else { 3 };
    let positions = p
        .vec3s("P")?
        .ok_or_else(|| loc.error(format!("Shape \"{ty}\" needs \"point3 P\"")))?;
    let indices = match p.indices("indices")? {
        Some(i) => i,
        None if positions.len() == per => (0..per as u32).collect(),
        None => {
            return Err(loc.error(format!(
                "Shape \"{ty}\" needs \"integer indices\" (only a single {} may leave them out)",
                if per == 3 { "triangle" } else { "patch" }
            )));
        }
    };
    if indices.is_empty() || indices.len() % per != 0 {
        return Err(p.loc_of("indices").error(format!(
            "\"indices\" needs a positive multiple of {per} values, found {}",
            indices.len()
        )));
    }
    if let Some(&bad) = indices.iter().find(|&&i| i as usize >= positions.len()) {
        return Err(p.loc_of("indices").error(format!(
            "index {bad} is out of range ({} vertices in \"P\")",
            positions.len()
        )));
    }
    let normals = p.vec3s("N")?.unwrap_or_default();
    if !normals.is_empty() && normals.len() != positions.len() {
        return Err(p.loc_of("N").error(format!(
            "\"N\" has {} normals for {} vertices",
            normals.len(),
            positions.len()
        )));
    }
    let uvs = match p.vec2s("uv")? {
        Some(uv) => Some(uv),
        None => p.vec2s("st")?,
    }
    .unwrap_or_default();
    if !uvs.is_empty() && uvs.len() != positions.len() {
        return Err(loc.error(format!(
            "\"uv\" has {} pairs for {} vertices",
            uvs.len(),
            positions.len()
        )));
    }
    let normals = normals
        .into_iter()
        .map(|n| n.try_normalize().unwrap_or(Vec3::Z))
        .collect();
    let uvs = uvs.into_iter().map(|t| Vec2::new(t.x, 1.0 - t.y)).collect();
    let indices = if per == 3 {
        indices
            .chunks_exact(3)
            .map(|c| [c[0], c[1], c[2]])
            .collect()
    } else {
        // Patches are held four to a row until they are split.
        indices
            .chunks_exact(4)
            .flat_map(|c| [[c[0], c[1], c[2]], [c[3], c[3], c[3]]])
            .collect()
    };
    Ok(Mesh {
        positions,
        normals,
        uvs,
        indices,
        ..Mesh::default()
    })
}

/// Splits bilinear patches `p00 p10 p01 p11` (held as two rows by
/// [`mesh_of`]) into the triangles `p00 p10 p11` and `p00 p11 p01`, which
/// face the patch's `dp/du x dp/dv`. Returns whether every patch is planar.
fn bilinear_to_triangles(mut mesh: Mesh) -> (Mesh, bool) {
    let rows = std::mem::take(&mut mesh.indices);
    let mut planar = true;
    for pair in rows.chunks_exact(2) {
        let [a, b, c] = pair[0];
        let d = pair[1][0];
        let p = |i: u32| mesh.positions[i as usize];
        let n = (p(b) - p(a)).cross(p(c) - p(a));
        let off = n.normalize_or_zero().dot(p(d) - p(a)).abs();
        let size = (p(d) - p(a)).length().max(1e-12);
        if off > 1e-4 * size {
            planar = false;
        }
        mesh.indices.push([a, b, d]);
        mesh.indices.push([a, d, c]);
    }
    (mesh, planar)
}

/// Turns each triangle to pbrt's front: towards the mean of its vertex
/// normals where the mesh has them, else flipped under `ReverseOrientation`.
fn orient(mesh: &mut Mesh, reverse: bool) {
    if mesh.normals.len() == mesh.positions.len() && !mesh.normals.is_empty() {
        for t in &mut mesh.indices {
            let [a, b, c] = t.map(|i| i as usize);
            let (Some(pa), Some(pb), Some(pc)) = (
                mesh.positions.get(a),
                mesh.positions.get(b),
                mesh.positions.get(c),
            ) else {
                continue;
            };
            let ng = (*pb - *pa).cross(*pc - *pa);
            let ns = mesh.normals[a] + mesh.normals[b] + mesh.normals[c];
            if ng.dot(ns) < 0.0 {
                t.swap(1, 2);
            }
        }
    } else if reverse {
        flip_winding(mesh);
    }
}

/// Reverses every triangle and normal.
fn flip_winding(mesh: &mut Mesh) {
    for t in &mut mesh.indices {
        t.swap(1, 2);
    }
    for n in &mut mesh.normals {
        *n = -*n;
    }
}
