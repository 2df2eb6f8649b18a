//! `PreparedScene`: the scene flattened once per render into world-space
//! triangles (and analytic spheres), with smoothed normals, tangents and
//! object-space points for solid textures. Every technique builds its own
//! structures (BVH, shadow maps, patches) from this.

use crate::geometry::normals::{tangents, vertex_normals};
use crate::geometry::{Aabb, Ray, face_normal, primitives};
use crate::scene::{AreaShape, Geometry, Light, Material, MaterialId, Scene, Texture};
use crate::shading::SurfaceMaterial;
use crate::shading::texture::bilinear;
use glam::{Mat3, Mat4, Vec2, Vec3, Vec4};

/// How to flatten the scene.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PrepareOptions {
    /// Keep spheres analytic (ray tracers) instead of tessellating them.
    pub analytic_spheres: bool,
    /// Slices of a tessellated sphere (stacks are half of it).
    pub sphere_slices: u32,
}

impl Default for PrepareOptions {
    fn default() -> Self {
        Self {
            analytic_spheres: false,
            sphere_slices: 64,
        }
    }
}

/// An analytic sphere in world space.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PreparedSphere {
    /// Centre, world space.
    pub center: Vec3,
    /// Radius, world units (uniform scale of the object applied).
    pub radius: f32,
    /// Material.
    pub material: MaterialId,
    /// Object index.
    pub object: u32,
    /// `object_from_world`, for solid textures.
    pub object_from_world: Mat4,
}

/// The flattened scene.
#[derive(Debug)]
pub struct PreparedScene<'s> {
    /// The authoring scene.
    pub scene: &'s Scene,
    /// World-space vertex positions.
    pub positions: Vec<Vec3>,
    /// Object-space vertex positions (for solid textures).
    pub object_positions: Vec<Vec3>,
    /// World-space unit shading normals (crease-split for smooth objects,
    /// face normals for faceted ones).
    pub normals: Vec<Vec3>,
    /// Texture coordinates (zero when the mesh has none).
    pub uvs: Vec<Vec2>,
    /// World-space tangents with bitangent sign in `w`.
    pub tangents: Vec<Vec4>,
    /// Vertex colours (one when the mesh has none).
    pub colors: Vec<Vec3>,
    /// Triangles (counter-clockwise front).
    pub triangles: Vec<[u32; 3]>,
    /// Material of each triangle.
    pub tri_material: Vec<MaterialId>,
    /// Object of each triangle.
    pub tri_object: Vec<u32>,
    /// Analytic spheres (only with `analytic_spheres`).
    pub spheres: Vec<PreparedSphere>,
    /// Triangles whose material emits.
    pub emissive_triangles: Vec<u32>,
    /// The lights every technique uses: the scene's lights followed by one
    /// [`AreaShape::Triangle`] area light per emissive triangle (radiance =
    /// the material's emission, one-sided unless the material is two-sided).
    pub lights: Vec<Light>,
    /// World-space bounds of everything.
    pub bounds: Aabb,
}

/// A surface point found by a ray, with everything shading needs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SurfaceHit {
    /// Position, world space.
    pub p: Vec3,
    /// Unit geometric normal (front side, not flipped towards the ray).
    pub ng: Vec3,
    /// Unit interpolated shading normal (front side).
    pub ns: Vec3,
    /// Texture coordinates.
    pub uv: Vec2,
    /// Object-space position (solid textures).
    pub p_object: Vec3,
    /// Tangent with bitangent sign.
    pub tangent: Vec4,
    /// Vertex colour.
    pub color: Vec3,
    /// Material.
    pub material: MaterialId,
    /// Object index.
    pub object: u32,
}

impl<'s> PreparedScene<'s> {
    /// Flattens `scene`. The scene should have passed `Scene::validate`
    /// (out-of-range ids are skipped here, never a panic).
    pub fn new(scene: &'s Scene, opts: PrepareOptions) -> Self {
        let mut ps = PreparedScene {
            scene,
            positions: Vec::new(),
            object_positions: Vec::new(),
            normals: Vec::new(),
            uvs: Vec::new(),
            tangents: Vec::new(),
            colors: Vec::new(),
            triangles: Vec::new(),
            tri_material: Vec::new(),
            tri_object: Vec::new(),
            spheres: Vec::new(),
            emissive_triangles: Vec::new(),
            lights: scene.lights.clone(),
            bounds: Aabb::EMPTY,
        };
        for (oi, obj) in scene.objects.iter().enumerate() {
            let world_from_object = obj.transform.world_from_object();
            let tessellated;
            let mesh = match obj.geometry {
                Geometry::Mesh(id) => match scene.meshes.get(id.index()) {
                    Some(m) => m,
                    None => continue,
                },
                Geometry::Sphere { radius } => {
                    if opts.analytic_spheres {
                        let center = world_from_object.transform_point3(Vec3::ZERO);
                        let scale = world_from_object.to_scale_rotation_translation().0;
                        let r = radius * scale.abs().max_element();
                        ps.spheres.push(PreparedSphere {
                            center,
                            radius: r,
                            material: obj.material,
                            object: oi as u32,
                            object_from_world: world_from_object.inverse(),
                        });
                        ps.bounds = ps
                            .bounds
                            .grow(center - Vec3::splat(r))
                            .grow(center + Vec3::splat(r));
                        continue;
                    }
                    tessellated =
                        primitives::uv_sphere(radius, opts.sphere_slices, opts.sphere_slices / 2);
                    &tessellated
                }
            };
            ps.add_mesh(mesh, obj, oi as u32, world_from_object);
        }
        ps.emissive_triangles = (0..ps.triangles.len() as u32)
            .filter(|&t| ps.material(ps.tri_material[t as usize]).is_emissive())
            .collect();
        for &t in &ps.emissive_triangles {
            let [a, b, c] = ps.triangles[t as usize].map(|i| ps.positions[i as usize]);
            let m = ps.material(ps.tri_material[t as usize]);
            if crate::geometry::face_normal(a, b, c).is_some() {
                ps.lights.push(Light::Area { shape: AreaShape::Triangle { a, b, c }, color: m.emission, intensity: 1.0, two_sided: m.two_sided });
            }
        }
        ps
    }

    fn add_mesh(
        &mut self,
        mesh: &crate::scene::Mesh,
        obj: &crate::scene::Object,
        oi: u32,
        world_from_object: Mat4,
    ) {
        let nv = mesh.positions.len();
        let valid: Vec<(usize, [u32; 3])> = mesh
            .indices
            .iter()
            .enumerate()
            .filter(|(_, t)| t.iter().all(|&i| (i as usize) < nv))
            .map(|(f, t)| (f, *t))
            .collect();
        let normal_from_object = Mat3::from_mat4(world_from_object).inverse().transpose();
        let flip = world_from_object.determinant() < 0.0;
        let world: Vec<Vec3> = mesh
            .positions
            .iter()
            .map(|&p| world_from_object.transform_point3(p))
            .collect();
        let tris: Vec<[u32; 3]> = valid
            .iter()
            .map(|(_, t)| if flip { [t[0], t[2], t[1]] } else { *t })
            .collect();
        // Normals: given ones are kept for smooth objects; otherwise derived with
        // the crease angle (0 for faceted objects = face normals).
        let (src, normals, indices): (Vec<u32>, Vec<Vec3>, Vec<[u32; 3]>) =
            if obj.smooth && mesh.normals.len() == nv {
                let n = mesh
                    .normals
                    .iter()
                    .map(|&n| (normal_from_object * n).try_normalize().unwrap_or(Vec3::Z))
                    .collect();
                ((0..nv as u32).collect(), n, tris)
            } else {
                let crease = if obj.smooth {
                    obj.crease_angle_degrees
                } else {
                    0.0
                };
                let s = vertex_normals(&world, &tris, crease);
                (s.source_vertex, s.normals, s.indices)
            };
        let base = self.positions.len() as u32;
        for &v in &src {
            let v = v as usize;
            self.positions.push(world[v]);
            self.object_positions.push(mesh.positions[v]);
            self.uvs
                .push(mesh.uvs.get(v).copied().unwrap_or(Vec2::ZERO));
            self.colors
                .push(mesh.colors.get(v).copied().unwrap_or(Vec3::ONE));
            self.bounds = self.bounds.grow(world[v]);
        }
        self.normals.extend(normals.iter().copied());
        let local_uvs: Vec<Vec2> = src
            .iter()
            .map(|&v| mesh.uvs.get(v as usize).copied().unwrap_or(Vec2::ZERO))
            .collect();
        let local_pos: Vec<Vec3> = src.iter().map(|&v| world[v as usize]).collect();
        if mesh.tangents.len() == nv && !flip {
            let m3 = Mat3::from_mat4(world_from_object);
            self.tangents.extend(src.iter().map(|&v| {
                let t = mesh.tangents[v as usize];
                (m3 * t.truncate()).normalize_or_zero().extend(t.w)
            }));
        } else {
            self.tangents
                .extend(tangents(&local_pos, &normals, &local_uvs, &indices));
        }
        for ((f, _), t) in valid.iter().zip(&indices) {
            self.triangles.push(t.map(|i| i + base));
            self.tri_material
                .push(mesh.face_materials.get(*f).copied().unwrap_or(obj.material));
            self.tri_object.push(oi);
        }
    }

    /// The material with id `m` (the default material if out of range).
    pub fn material(&self, m: MaterialId) -> &Material {
        static DEFAULT: std::sync::OnceLock<Material> = std::sync::OnceLock::new();
        self.scene
            .materials
            .get(m.index())
            .unwrap_or_else(|| DEFAULT.get_or_init(Material::default))
    }

    /// Number of triangles.
    pub fn triangle_count(&self) -> usize {
        self.triangles.len()
    }

    /// Geometric (face) normal of triangle `t`, or +z for a degenerate one.
    pub fn face_normal(&self, t: u32) -> Vec3 {
        let [a, b, c] = self.triangles[t as usize].map(|i| self.positions[i as usize]);
        face_normal(a, b, c).unwrap_or(Vec3::Z)
    }

    /// The surface at a ray hit on primitive `prim` (triangles first, then
    /// spheres) with barycentrics `(u, v)`.
    pub fn surface(&self, ray: &Ray, hit: &crate::accel::Hit) -> SurfaceHit {
        let nt = self.triangles.len() as u32;
        if hit.prim < nt {
            self.triangle_surface(hit.prim, hit.u, hit.v)
        } else {
            let s = &self.spheres[(hit.prim - nt) as usize];
            let p = ray.at(hit.t);
            let n = ((p - s.center) / s.radius)
                .try_normalize()
                .unwrap_or(Vec3::Y);
            let po = s.object_from_world.transform_point3(p);
            let d = po.normalize_or_zero();
            let uv = Vec2::new(
                0.5 + d.x.atan2(d.z) / std::f32::consts::TAU,
                d.y.clamp(-1.0, 1.0).acos() / std::f32::consts::PI,
            );
            let tangent = Vec3::Y
                .cross(n)
                .try_normalize()
                .unwrap_or(Vec3::X)
                .extend(1.0);
            SurfaceHit {
                p,
                ng: n,
                ns: n,
                uv,
                p_object: po,
                tangent,
                color: Vec3::ONE,
                material: s.material,
                object: s.object,
            }
        }
    }

    /// The surface of triangle `t` at barycentrics `(u, v)` of its vertices 1 and 2.
    pub fn triangle_surface(&self, t: u32, u: f32, v: f32) -> SurfaceHit {
        let [i0, i1, i2] = self.triangles[t as usize].map(|i| i as usize);
        let w = 1.0 - u - v;
        let lerp3 = |a: &[Vec3]| a[i0] * w + a[i1] * u + a[i2] * v;
        let ng = self.face_normal(t);
        let mut ns = lerp3(&self.normals).try_normalize().unwrap_or(ng);
        if ns.dot(ng) < 0.0 {
            // Interpolated normals may point away from a thin face; keep the front side.
            ns = ng;
        }
        let tan = self.tangents[i0] * w + self.tangents[i1] * u + self.tangents[i2] * v;
        SurfaceHit {
            p: lerp3(&self.positions),
            ng,
            ns,
            uv: self.uvs[i0] * w + self.uvs[i1] * u + self.uvs[i2] * v,
            p_object: lerp3(&self.object_positions),
            tangent: tan.truncate().normalize_or_zero().extend(if tan.w < 0.0 {
                -1.0
            } else {
                1.0
            }),
            color: lerp3(&self.colors),
            material: self.tri_material[t as usize],
            object: self.tri_object[t as usize],
        }
    }

    /// The material parameters at a surface point with textures and vertex
    /// colours applied (base level of image textures).
    pub fn surface_material(&self, hit: &SurfaceHit) -> SurfaceMaterial {
        let m = self.material(hit.material);
        let mut sm = SurfaceMaterial::from_material(m);
        sm.kd *= hit.color;
        if let Some(Texture::Image(img)) =
            m.texture.and_then(|t| self.scene.textures.get(t.index()))
        {
            sm.kd *= bilinear(img, hit.uv).truncate();
        }
        if let Some(Texture::Image(img)) = m
            .emission_texture
            .and_then(|t| self.scene.textures.get(t.index()))
        {
            sm.emission *= bilinear(img, hit.uv).truncate();
        }
        sm
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{Object, Transform};

    #[test]
    fn mirrored_transform_keeps_front_faces() {
        let mut s = Scene::default();
        s.add_material(Material::default());
        let m = s.add_mesh(primitives::quad(Vec3::ZERO, Vec3::X, Vec3::Y));
        s.objects.push(Object {
            geometry: Geometry::Mesh(m),
            transform: Transform {
                scale: Vec3::new(-1.0, 1.0, 1.0),
                ..Default::default()
            },
            ..Default::default()
        });
        let ps = PreparedScene::new(&s, PrepareOptions::default());
        for t in 0..ps.triangle_count() as u32 {
            assert!(ps.face_normal(t).dot(Vec3::Z) > 0.99);
        }
    }
}
