//! `[[object]]`: transforms, primitives and mesh files.

use super::raw::{Opt, RawObject, RawTransform, Sp, Splat3};
use super::{Ctx, Present, span_of};
use crate::Result;
use chiaro_core::Vec3;
use chiaro_core::geometry::primitives;
use chiaro_core::geometry::primitives::MeshSize;
use chiaro_core::glam::Mat4;
use chiaro_core::scene::{Geometry, Material, MaterialId, Mesh, Object, Scene, Transform};
use std::collections::HashMap;
use std::ops::Range;
use std::path::Path;

/// Largest accepted tessellation parameter (`segments`, `stacks`).
const MAX_SEGMENTS: u32 = 1 << 16;
/// Largest accepted `subdivisions` of a plane (a 4096^2-quad grid).
const MAX_PLANE_SUBDIVISIONS: u32 = 4096;
/// Largest accepted `subdivisions` of the teapot (per patch side).
const MAX_TEAPOT_SUBDIVISIONS: u32 = 128;

impl Ctx<'_> {
    pub(super) fn transform(&self, t: &Opt<RawTransform>) -> Result<Transform> {
        let mut out = Transform::default();
        let Some(t) = t else { return Ok(out) };
        let raw = t.get_ref();
        if let Some(v) = raw.translate {
            out.translate = Vec3::from(v);
        }
        let axes = [&raw.rotate_x, &raw.rotate_y, &raw.rotate_z];
        if let Some(r) = &raw.rotate {
            if let Some(a) = axes.iter().find_map(|a| a.as_ref()) {
                return Err(self.at(
                    a.span(),
                    "give either `rotate = [x, y, z]` or `rotate_x/y/z`, not both",
                ));
            }
            out.rotate_degrees = Vec3::from(*r.get_ref());
        } else {
            let g = |a: &Opt<f32>| a.as_ref().map_or(0.0, |a| *a.get_ref());
            out.rotate_degrees = Vec3::new(g(&raw.rotate_x), g(&raw.rotate_y), g(&raw.rotate_z));
        }
        if let Some(s) = &raw.scale {
            let v = s.get_ref().vec3();
            if v.x == 0.0 || v.y == 0.0 || v.z == 0.0 {
                return Err(self.at(s.span(), format!("scale must not be zero, got {v}")));
            }
            out.scale = v;
        }
        if let Some(m) = &raw.matrix {
            let mat = Mat4::from_cols_array(m.get_ref());
            if mat.determinant().abs() < 1e-20 {
                return Err(self.at(m.span(), "matrix is singular"));
            }
            out.matrix = mat;
        }
        Ok(out)
    }

    pub(super) fn object(
        &mut self,
        scene: &mut Scene,
        o: &Sp<RawObject>,
        names: &HashMap<String, MaterialId>,
        known: &[String],
        default_material: &mut Option<MaterialId>,
    ) -> Result<()> {
        let span = o.span();
        let r = o.get_ref();
        let material = match &r.material {
            None => None,
            Some(m) => match names.get(m.get_ref()) {
                Some(id) => Some(*id),
                None => {
                    let list = if known.is_empty() {
                        "no materials are defined".to_string()
                    } else {
                        format!("known: {}", known.join(", "))
                    };
                    return Err(self.at(
                        m.span(),
                        format!("unknown material {:?} ({list})", m.get_ref()),
                    ));
                }
            },
        };
        let crease = match &r.crease_angle {
            Some(c) => {
                let x = *c.get_ref();
                if !(0.0..=180.0).contains(&x) {
                    return Err(self.at(
                        c.span(),
                        format!("crease_angle: expected 0..=180 degrees, got {x}"),
                    ));
                }
                x
            }
            None => Object::default().crease_angle_degrees,
        };
        let template = Object {
            name: r.name.clone().unwrap_or_default(),
            transform: self.transform(&r.transform)?,
            smooth: r.smooth.unwrap_or(true),
            crease_angle_degrees: crease,
            shade_mode: r.shade,
            casts_shadows: r.casts_shadows.unwrap_or(true),
            ..Object::default()
        };
        let present: Present = vec![
            ("radius", span_of(&r.radius)),
            ("size", span_of(&r.size)),
            ("height", span_of(&r.height)),
            ("segments", span_of(&r.segments)),
            ("stacks", span_of(&r.stacks)),
            ("subdivisions", span_of(&r.subdivisions)),
            ("corner", span_of(&r.corner)),
            ("edge_u", span_of(&r.edge_u)),
            ("edge_v", span_of(&r.edge_v)),
        ];
        match (&r.mesh, &r.primitive) {
            (Some(_), Some(p)) => Err(self.at(
                p.span(),
                "an object takes either `mesh` or `primitive`, not both",
            )),
            (None, None) => Err(self.at(
                span,
                "an object needs `mesh = \"file\"` or `primitive = \"sphere\"` (or plane, quad, disk, box, cylinder, teapot)",
            )),
            (Some(file), None) => {
                self.only("a mesh file object", &present, &[])?;
                self.mesh_file(scene, file, material, &template, span)
            }
            (None, Some(prim)) => {
                let material = match material {
                    Some(m) => m,
                    None => match *default_material {
                        Some(m) => m,
                        None => {
                            let m = scene.add_material(Material::default());
                            self.spans.materials.push(span.clone());
                            *default_material = Some(m);
                            m
                        }
                    },
                };
                // Same primitive, same parameters: the same mesh.
                let key = format!(
                    "{}|{:?}|{:?}|{:?}|{:?}|{:?}|{:?}|{:?}|{:?}|{:?}",
                    prim.get_ref(),
                    r.stacks.as_ref().map(|v| *v.get_ref()),
                    r.radius.as_ref().map(|v| v.get_ref().to_bits()),
                    r.size.as_ref().map(|v| *v.get_ref()),
                    r.height.as_ref().map(|v| v.get_ref().to_bits()),
                    r.segments.as_ref().map(|v| *v.get_ref()),
                    r.subdivisions.as_ref().map(|v| *v.get_ref()),
                    r.corner.as_ref().map(|v| v.get_ref().map(f32::to_bits)),
                    r.edge_u.as_ref().map(|v| v.get_ref().map(f32::to_bits)),
                    r.edge_v.as_ref().map(|v| v.get_ref().map(f32::to_bits)),
                );
                let geometry = match self.primitive_meshes.get(&key) {
                    Some(&mesh) => {
                        let size = MeshSize::of(&scene.meshes[mesh.index()]);
                        self.account(None, size, prim, prim.span())?;
                        Geometry::Mesh(mesh)
                    }
                    None => {
                        let geometry = self.primitive(scene, r, prim, &present)?;
                        if let Geometry::Mesh(mesh) = geometry {
                            self.spans.meshes.push(span.clone());
                            self.primitive_meshes.insert(key, mesh);
                        }
                        geometry
                    }
                };
                scene.objects.push(Object {
                    name: if template.name.is_empty() {
                        prim.get_ref().clone()
                    } else {
                        template.name.clone()
                    },
                    geometry,
                    material,
                    ..template
                });
                self.spans.objects.push(span);
                Ok(())
            }
        }
    }

    pub(super) fn primitive(
        &self,
        scene: &mut Scene,
        r: &RawObject,
        prim: &Sp<String>,
        present: &Present,
    ) -> Result<Geometry> {
        let f = |v: &Opt<f32>, what: &str, def: f32| -> Result<f32> {
            match v {
                Some(v) => self.finite_positive(v, what),
                None => Ok(def),
            }
        };
        let count = |v: &Opt<u32>, what: &str, lo: u32, hi: u32, def: u32| -> Result<u32> {
            match v {
                Some(v) => self.in_range_u32(v, what, lo, hi),
                None => Ok(def),
            }
        };
        let v3 =
            |v: &Opt<[f32; 3]>, def: Vec3| v.as_ref().map_or(def, |v| Vec3::from(*v.get_ref()));
        let name = prim.get_ref().as_str();
        let what = format!("primitive {name:?}");
        let mesh: Mesh = match name {
            "sphere" => {
                self.only(&what, present, &["radius"])?;
                return Ok(Geometry::Sphere {
                    radius: f(&r.radius, "radius", 1.0)?,
                });
            }
            "plane" => {
                self.only(&what, present, &["size", "subdivisions"])?;
                let span = span_of(&r.subdivisions).unwrap_or(prim.span());
                let size = match &r.size {
                    None => 2.0,
                    Some(s) => match *s.get_ref() {
                        Splat3::Scalar(x) if x > 0.0 => x,
                        _ => {
                            return Err(self.at(
                                s.span(),
                                "plane size: expected one number > 0 (the side length)",
                            ));
                        }
                    },
                };
                let n = count(
                    &r.subdivisions,
                    "subdivisions",
                    1,
                    MAX_PLANE_SUBDIVISIONS,
                    1,
                )?;
                let m = MeshSize::plane(n);
                self.account(Some(m), m, prim, span)?;
                primitives::plane(0.5 * size, n)
            }
            "quad" => {
                self.only(&what, present, &["corner", "edge_u", "edge_v"])?;
                let corner = v3(&r.corner, Vec3::new(-1.0, 0.0, 1.0));
                let edge_u = v3(&r.edge_u, Vec3::new(2.0, 0.0, 0.0));
                let edge_v = v3(&r.edge_v, Vec3::new(0.0, 0.0, -2.0));
                if edge_u.cross(edge_v).length_squared() == 0.0 {
                    return Err(self.at(
                        span_of(&r.edge_v)
                            .or(span_of(&r.edge_u))
                            .unwrap_or(prim.span()),
                        "edge_u and edge_v are parallel: the quad has no area",
                    ));
                }
                primitives::quad(corner, edge_u, edge_v)
            }
            "disk" => {
                self.only(&what, present, &["radius", "segments"])?;
                let segments = count(&r.segments, "segments", 3, MAX_SEGMENTS, 64)?;
                let m = MeshSize::disk(segments);
                self.account(Some(m), m, prim, prim.span())?;
                primitives::disk(f(&r.radius, "radius", 1.0)?, segments)
            }
            "box" => {
                self.only(&what, present, &["size"])?;
                let size = match &r.size {
                    None => Vec3::splat(2.0),
                    Some(s) => {
                        let v = s.get_ref().vec3();
                        if v.min_element() <= 0.0 {
                            return Err(self.at(s.span(), format!("box size must be > 0, got {v}")));
                        }
                        v
                    }
                };
                primitives::box_mesh(0.5 * size)
            }
            "cylinder" => {
                self.only(&what, present, &["radius", "height", "segments"])?;
                let segments = count(&r.segments, "segments", 3, MAX_SEGMENTS, 64)?;
                let m = MeshSize::cylinder(segments);
                self.account(Some(m), m, prim, prim.span())?;
                primitives::cylinder(
                    f(&r.radius, "radius", 1.0)?,
                    f(&r.height, "height", 2.0)?,
                    segments,
                )
            }
            "teapot" => {
                self.only(&what, present, &["subdivisions"])?;
                let n = count(
                    &r.subdivisions,
                    "subdivisions",
                    1,
                    MAX_TEAPOT_SUBDIVISIONS,
                    8,
                )?;
                let m = MeshSize::teapot(n);
                self.account(Some(m), m, prim, prim.span())?;
                chiaro_core::geometry::teapot::teapot(n)
            }
            other => {
                return Err(self.at(
                    prim.span(),
                    format!(
                        "unknown primitive {other:?}, expected one of: sphere, plane, quad, disk, box, cylinder, teapot"
                    ),
                ));
            }
        };
        Ok(Geometry::Mesh(scene.add_mesh(mesh)))
    }

    pub(super) fn mesh_file(
        &mut self,
        scene: &mut Scene,
        file: &Sp<String>,
        material: Option<MaterialId>,
        template: &Object,
        span: Range<usize>,
    ) -> Result<()> {
        let path = crate::resolve(self.base, file.get_ref());
        self.check_file(file, &path, "mesh file", "cannot read mesh file")?;
        let key = (
            std::fs::canonicalize(&path).unwrap_or(path.clone()),
            material,
        );
        let (imported, shared) = match self.mesh_files.get(&key) {
            Some((imported, shared)) => (imported.clone(), *shared),
            None => {
                let imported = std::rc::Rc::new(self.read_mesh_file(&path, file)?);
                let mesh_start = scene.meshes.len();
                let mat_start = scene.materials.len();
                let shared = imported.add_shared(scene, material);
                for _ in mat_start..scene.materials.len() {
                    self.spans.materials.push(file.span());
                }
                for _ in mesh_start..scene.meshes.len() {
                    self.spans.meshes.push(span.clone());
                }
                self.warnings.extend(imported.warnings.iter().cloned());
                self.mesh_files.insert(key, (imported.clone(), shared));
                (imported, shared)
            }
        };
        if imported.objects.is_empty() {
            self.warnings.push(format!(
                "{}: mesh file {:?} contains no triangles",
                self.where_(file.span()),
                file.get_ref()
            ));
        }
        let world_from_file = template.transform.world_from_object();
        let mut tmpl = template.clone();
        tmpl.transform = Transform::default();
        if tmpl.name.is_empty() {
            tmpl.name = file.get_ref().clone();
        }
        let new = imported.place(scene, &shared, world_from_file, &tmpl);
        for _ in new {
            self.spans.objects.push(span.clone());
        }
        for l in &imported.lights {
            scene
                .lights
                .push(crate::transform_light(l, world_from_file));
            self.spans.lights.push(file.span());
        }
        Ok(())
    }

    /// Reads an OBJ or glTF file (`path`, resolved from `file`).
    pub(super) fn read_mesh_file(&self, path: &Path, file: &Sp<String>) -> Result<crate::Imported> {
        // glTF is read within the scene's memory budget; other formats as
        // `load_mesh_file` reads them.
        let loaded = match crate::lowercase_extension(path).as_str() {
            "gltf" | "glb" => Some(crate::gltf_import::load_gltf_within(path, self.budget)),
            _ => crate::load_mesh_file(path),
        };
        loaded
            .ok_or_else(|| {
                self.at(
                    file.span(),
                    format!(
                        "mesh file {:?}: expected a .obj, .gltf, .glb or .ply file",
                        file.get_ref()
                    ),
                )
            })?
            .map_err(|e| self.at(file.span(), format!("cannot load mesh file: {e}")))
    }

    /// Adds a primitive object's memory (a `new` mesh, if it is tessellated
    /// for it, and the prepared copy of `instance`) to the scene's total,
    /// refused at `span` when the total exceeds the budget.
    pub(super) fn account(
        &self,
        new: Option<MeshSize>,
        instance: MeshSize,
        prim: &Sp<String>,
        span: Range<usize>,
    ) -> Result<()> {
        let total = self
            .load_bytes
            .get()
            .saturating_add(new.map_or(0, |m| m.mesh_bytes()))
            .saturating_add(instance.prepared_bytes());
        self.budget
            .check(
                &format!(
                    "primitive {:?} ({} triangles), with the primitives before it,",
                    prim.get_ref(),
                    instance.triangles
                ),
                total,
            )
            .map_err(|m| self.at(span, m))?;
        self.load_bytes.set(total);
        Ok(())
    }
}
