//! `PreparedScene`: the scene flattened once per render into world-space
//! triangles (and analytic spheres), with smoothed normals, tangents and
//! object-space points for solid textures. Every technique builds its own
//! structures (BVH, shadow maps, patches) from this.

use crate::geometry::normals::{tangents, vertex_normals};
use crate::geometry::tessellation::{FIXED_SEGMENTS, Tessellation};
use crate::geometry::{Aabb, Ray, face_normal, primitives};
use crate::scene::TextureId;
use crate::scene::Transmission;
use crate::scene::{
    AlphaMode, AreaShape, Geometry, Light, Material, MaterialId, MetallicRoughness, Scene, Texture,
};
use crate::shading::SurfaceMaterial;
use crate::shading::brdf::clearcoat_alpha;
use crate::shading::texture::{
    MipMap, PrefilteredEnvironment, TexCoord, bump_normal, eval_height, eval_texture,
    normal_map_normal, uv_surface_gradient,
};
use glam::{Mat2, Mat3, Mat4, Vec2, Vec3, Vec4};
use std::sync::OnceLock;

/// How to flatten the scene.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PrepareOptions {
    /// Keep spheres analytic (ray tracers) instead of tessellating them.
    pub analytic_spheres: bool,
    /// Segments around a tessellated sphere (slices; stacks are half of
    /// it): fixed, or by its projected size in the view.
    pub tessellation: Tessellation,
}

impl Default for PrepareOptions {
    fn default() -> Self {
        Self {
            analytic_spheres: false,
            tessellation: Tessellation::Fixed(FIXED_SEGMENTS),
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

impl PreparedSphere {
    /// The point of `ray` at `t` and the unit outward normal there (up
    /// if the point is the centre): what every surface of it starts from.
    #[inline]
    pub fn point_normal(&self, ray: &Ray, t: f32) -> (Vec3, Vec3) {
        let p = ray.at(t);
        let n = ((p - self.center) / self.radius)
            .try_normalize()
            .unwrap_or(Vec3::Y);
        (p, n)
    }
}

/// The world-space centre and radius of a sphere of `radius` about the
/// origin of an object placed by `world_from_object` (the largest axis
/// scale applied: the analytic sphere is round).
pub fn sphere_in_world(world_from_object: Mat4, radius: f32) -> (Vec3, f32) {
    let center = world_from_object.transform_point3(Vec3::ZERO);
    let scale = world_from_object.to_scale_rotation_translation().0;
    (center, radius * scale.abs().max_element())
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
    /// The second texture-coordinate set (a mesh's `uvs1`, else its
    /// `uvs`); empty when no mesh of the scene has a second set.
    pub uvs1: Vec<Vec2>,
    /// World-space tangents with bitangent sign in `w`.
    pub tangents: Vec<Vec4>,
    /// Vertex colours (one when the mesh has none).
    pub colors: Vec<Vec3>,
    /// Per-vertex alpha of the vertex colours (1 where a mesh has none).
    pub color_alphas: Vec<f32>,
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
    /// the material's emission, times its emission texture's mean over the
    /// triangle; one-sided unless the material is two-sided).
    pub lights: Vec<Light>,
    /// World-space bounds of everything.
    pub bounds: Aabb,
    /// Mip-map pyramids of the scene's image textures (index = texture id),
    /// built on first use by [`PreparedScene::mip_map`].
    pub mip_maps: OnceLock<Vec<Option<MipMap>>>,
    /// The environment map prefiltered for the local techniques' glossy
    /// reflection, built on first use by
    /// [`PreparedScene::prefiltered_environment`].
    pub prefiltered: OnceLock<Option<PrefilteredEnvironment>>,
}

/// The alpha (coverage) of a surface point: the base colour factor's alpha
/// times the base-colour texture's alpha times the vertex colour's alpha
/// (glTF 2.0, section 3.9.2), clamped to `[0, 1]` (NaN counts as 1: a bad
/// value never makes geometry vanish).
#[inline]
pub fn alpha_product(factor: f32, texture: f32, vertex: f32) -> f32 {
    let a = factor * texture * vertex;
    if a.is_nan() { 1.0 } else { a.clamp(0.0, 1.0) }
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
    /// The second texture-coordinate set (`uv` where there is none).
    pub uv1: Vec2,
    /// `d(uv1)/d(uv)` on the triangle: carries a footprint in `uv` to one
    /// in `uv1` (identity without a second set, zero where `uv` degenerates).
    pub uv1_from_uv: Mat2,
    /// Object-space position (solid textures).
    pub p_object: Vec3,
    /// Tangent with bitangent sign.
    pub tangent: Vec4,
    /// Vertex colour.
    pub color: Vec3,
    /// Vertex colour's alpha (1 without one).
    pub color_alpha: f32,
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
            uvs1: Vec::new(),
            tangents: Vec::new(),
            colors: Vec::new(),
            color_alphas: Vec::new(),
            triangles: Vec::new(),
            tri_material: Vec::new(),
            tri_object: Vec::new(),
            spheres: Vec::new(),
            emissive_triangles: Vec::new(),
            lights: scene.lights.clone(),
            bounds: Aabb::EMPTY,
            mip_maps: OnceLock::new(),
            prefiltered: OnceLock::new(),
        };
        let two_sets = scene.meshes.iter().any(|m| !m.uvs1.is_empty());
        for (oi, obj) in scene.objects.iter().enumerate() {
            let world_from_object = obj.transform.world_from_object();
            let tessellated;
            let mesh = match obj.geometry {
                Geometry::Mesh(id) => match scene.meshes.get(id.index()) {
                    Some(m) => m,
                    None => continue,
                },
                Geometry::Sphere { radius } => {
                    let (center, r) = sphere_in_world(world_from_object, radius);
                    if opts.analytic_spheres {
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
                    let slices = opts.tessellation.sphere_segments(center, r);
                    tessellated = primitives::uv_sphere(radius, slices, slices / 2);
                    &tessellated
                }
            };
            ps.add_mesh(mesh, obj, oi as u32, world_from_object, two_sets);
        }
        ps.emissive_triangles = (0..ps.triangles.len() as u32)
            .filter(|&t| ps.material(ps.tri_material[t as usize]).is_emissive())
            .collect();
        let emitted: Vec<Vec3> = {
            use rayon::prelude::*;
            ps.emissive_triangles
                .par_iter()
                .map(|&t| ps.triangle_emission(t))
                .collect()
        };
        for (&t, color) in ps.emissive_triangles.iter().zip(emitted) {
            let [a, b, c] = ps.triangles[t as usize].map(|i| ps.positions[i as usize]);
            let m = ps.material(ps.tri_material[t as usize]);
            if crate::geometry::face_normal(a, b, c).is_some() {
                ps.lights.push(Light::Area {
                    shape: AreaShape::Triangle { a, b, c },
                    color,
                    intensity: 1.0,
                    two_sided: m.emission_two_sided,
                });
            }
        }
        ps
    }

    /// The indices in [`Self::lights`] of the emissive triangles' lights
    /// (they follow the scene's own lights).
    pub fn emissive_lights(&self) -> std::ops::Range<usize> {
        self.scene.lights.len().min(self.lights.len())..self.lights.len()
    }

    /// The emitted radiance of triangle `t` as a light: its material's
    /// emission, times the mean of the emission texture over the triangle
    /// when there is one, estimated from a stratified grid of 16 bilinear
    /// lookups (the mip-maps are not built for this: that took longer than
    /// a path-traced preview of a textured emitter).
    fn triangle_emission(&self, t: u32) -> Vec3 {
        let m = self.material(self.tri_material[t as usize]);
        let Some(tex) = m.emission_texture else {
            return m.emission;
        };
        let [i0, i1, i2] = self.triangles[t as usize].map(|i| i as usize);
        const N: u32 = 16;
        let mut sum = Vec3::ZERO;
        for i in 0..N {
            let b = crate::sampling::sample_uniform_triangle(crate::shading::stratum(
                i,
                N,
                Vec2::splat(0.5),
            ));
            // `sample_uniform_triangle` weights (a, b, c) by (x, y, 1 - x - y).
            let w = [b.x, b.y, 1.0 - b.x - b.y];
            let uv = self.uvs[i0] * w[0] + self.uvs[i1] * w[1] + self.uvs[i2] * w[2];
            let tc = TexCoord {
                uv,
                p_object: self.object_positions[i0] * w[0]
                    + self.object_positions[i1] * w[1]
                    + self.object_positions[i2] * w[2],
                uv1: self.second_uv([i0, i1, i2], w[1], w[2], uv).0,
                ..TexCoord::default()
            };
            sum += self.eval_texture(tex, &tc).truncate().max(Vec3::ZERO);
        }
        let mean = m.emission * (sum / N as f32);
        if mean.is_finite() { mean } else { Vec3::ZERO }
    }

    fn add_mesh(
        &mut self,
        mesh: &crate::scene::Mesh,
        obj: &crate::scene::Object,
        oi: u32,
        world_from_object: Mat4,
        two_sets: bool,
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
            if two_sets {
                let uv1 = mesh.uvs1.get(v).or(mesh.uvs.get(v));
                self.uvs1.push(uv1.copied().unwrap_or(Vec2::ZERO));
            }
            self.colors
                .push(mesh.colors.get(v).copied().unwrap_or(Vec3::ONE));
            self.color_alphas
                .push(mesh.color_alphas.get(v).copied().unwrap_or(1.0));
            self.bounds = self.bounds.grow(world[v]);
        }
        self.normals.extend(normals.iter().copied());
        // Tangents follow the uv set of the object's normal map.
        let normal_map_set = self.material(obj.material).normal_map.and_then(|t| {
            match self.scene.textures.get(t.index()) {
                Some(Texture::Image(img)) => Some(img.uv_set),
                _ => None,
            }
        });
        let tangent_uvs = match normal_map_set {
            Some(1) if !mesh.uvs1.is_empty() => &mesh.uvs1,
            _ => &mesh.uvs,
        };
        let local_uvs: Vec<Vec2> = src
            .iter()
            .map(|&v| tangent_uvs.get(v as usize).copied().unwrap_or(Vec2::ZERO))
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
            let (p, n) = s.point_normal(ray, hit.t);
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
                uv1: uv,
                uv1_from_uv: Mat2::IDENTITY,
                p_object: po,
                tangent,
                color: Vec3::ONE,
                color_alpha: 1.0,
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
        let uv = self.uvs[i0] * w + self.uvs[i1] * u + self.uvs[i2] * v;
        let (uv1, uv1_from_uv) = self.second_uv([i0, i1, i2], u, v, uv);
        SurfaceHit {
            p: lerp3(&self.positions),
            ng,
            ns,
            uv,
            uv1,
            uv1_from_uv,
            p_object: lerp3(&self.object_positions),
            tangent: tan.truncate().normalize_or_zero().extend(if tan.w < 0.0 {
                -1.0
            } else {
                1.0
            }),
            color: lerp3(&self.colors),
            color_alpha: self.color_alphas[i0] * w
                + self.color_alphas[i1] * u
                + self.color_alphas[i2] * v,
            material: self.tri_material[t as usize],
            object: self.tri_object[t as usize],
        }
    }

    /// The second uv set at barycentrics `(u, v)` of the triangle with
    /// vertices `idx`, where the first set is `uv`, and `d(uv1)/d(uv)`
    /// over the triangle (both sets are affine in the barycentrics, so
    /// `uv1 = J uv + c` with `J = D1 D0^-1`, `D` the edge differences):
    /// `(uv, identity)` when the scene has no second set, a zero `J` where
    /// the first set is degenerate on the triangle.
    #[inline]
    pub fn second_uv(&self, idx: [usize; 3], u: f32, v: f32, uv: Vec2) -> (Vec2, Mat2) {
        if self.uvs1.is_empty() {
            return (uv, Mat2::IDENTITY);
        }
        let [i0, i1, i2] = idx;
        let (a, b, c) = (self.uvs1[i0], self.uvs1[i1], self.uvs1[i2]);
        let uv1 = a * (1.0 - u - v) + b * u + c * v;
        let d0 = Mat2::from_cols(self.uvs[i1] - self.uvs[i0], self.uvs[i2] - self.uvs[i0]);
        let d1 = Mat2::from_cols(b - a, c - a);
        let det = d0.determinant();
        let j = if det.abs() > 1e-12 {
            d1 * d0.inverse()
        } else {
            Mat2::ZERO
        };
        (uv1, if j.is_finite() { j } else { Mat2::ZERO })
    }

    /// The material parameters at a surface point with textures and vertex
    /// colours applied (base level of image textures, bilinear). Same as
    /// [`PreparedScene::surface_material_lod`] with no footprint.
    pub fn surface_material(&self, hit: &SurfaceHit) -> SurfaceMaterial {
        self.surface_material_lod(hit, Vec2::ZERO, Vec2::ZERO)
    }

    /// The mip-map pyramid of image texture `t` (`None` for a procedural or
    /// missing texture). All pyramids are built, in parallel, on the first
    /// call, on threads of their own; threads calling meanwhile wait for them.
    pub fn mip_map(&self, t: TextureId) -> Option<&MipMap> {
        self.mip_maps
            .get_or_init(|| build_mip_maps(&self.scene.textures))
            .get(t.index())
            .and_then(Option::as_ref)
    }

    /// The environment map prefiltered for glossy reflection by the local
    /// techniques, built on the first call; `None` (and nothing built)
    /// without an environment map.
    pub fn prefiltered_environment(&self) -> Option<&PrefilteredEnvironment> {
        self.scene.environment.as_ref()?;
        // Built outside the lock, as the mip-maps are.
        if self.prefiltered.get().is_none() {
            let _ = self
                .prefiltered
                .set(PrefilteredEnvironment::new(self.scene));
        }
        self.prefiltered.get()?.as_ref()
    }

    /// Evaluates texture `t` at `tc` (linear RGBA), trilinear through its
    /// mip-map when `tc` has a footprint, bilinear on the base image
    /// otherwise; white for a missing texture.
    pub fn eval_texture(&self, t: TextureId, tc: &TexCoord) -> Vec4 {
        let Some(tex) = self.scene.textures.get(t.index()) else {
            return Vec4::ONE;
        };
        let has_footprint = tc.duv_dx != Vec2::ZERO || tc.duv_dy != Vec2::ZERO;
        let mip = if has_footprint && matches!(tex, Texture::Image(_)) {
            self.mip_map(t)
        } else {
            None
        };
        eval_texture(tex, mip, tc)
    }

    /// The texture lookup point of `hit` with screen-space uv derivatives
    /// (those of the second set follow by `hit.uv1_from_uv`).
    pub fn tex_coord(hit: &SurfaceHit, duv_dx: Vec2, duv_dy: Vec2) -> TexCoord {
        TexCoord {
            uv: hit.uv,
            duv_dx,
            duv_dy,
            p_object: hit.p_object,
            uv1: hit.uv1,
            duv1_dx: hit.uv1_from_uv * duv_dx,
            duv1_dy: hit.uv1_from_uv * duv_dy,
        }
    }

    /// The material parameters at a surface point with vertex colours and
    /// textures applied; image textures are filtered over the pixel footprint
    /// given by the screen-space derivatives of the uvs, `duv_dx` and `duv_dy`
    /// (uv units per pixel; zero for the base level). Procedural textures are
    /// evaluated at the object-space point (or the uvs).
    pub fn surface_material_lod(
        &self,
        hit: &SurfaceHit,
        duv_dx: Vec2,
        duv_dy: Vec2,
    ) -> SurfaceMaterial {
        self.textured_material(hit, duv_dx, duv_dy).0
    }

    /// [`PreparedScene::surface_material_lod`] and the coverage (alpha) at
    /// the point ([`alpha_product`]).
    fn textured_material(
        &self,
        hit: &SurfaceHit,
        duv_dx: Vec2,
        duv_dy: Vec2,
    ) -> (SurfaceMaterial, f32) {
        let m = self.material(hit.material);
        let mut sm = SurfaceMaterial::from_material(m);
        let tc = Self::tex_coord(hit, duv_dx, duv_dy);
        let texel = m.texture.map(|t| self.eval_texture(t, &tc));
        let alpha = alpha_product(m.alpha, texel.map_or(1.0, |c| c.w), hit.color_alpha);

        let texture = texel.map(|c| c.truncate());
        match m.metallic_roughness {
            // Metallic-roughness: the base colour feeds kd and ks (F0).
            Some(mr) => {
                let base = texture.unwrap_or(Vec3::ONE) * hit.color;
                let (metallic, rough) = mr.texture.map_or((1.0, 1.0), |t| {
                    let c = self.eval_texture(t, &tc);
                    (c.z, c.y)
                });
                (sm.kd, sm.ks, sm.roughness) = MetallicRoughness::coefficients(
                    mr.base_color * base,
                    mr.metallic * metallic,
                    mr.roughness * rough,
                );
                // Transmission: part of the diffuse colour becomes glass.
                if let Some(tr) = m.gltf_transmission {
                    let t = tr.texture.map_or(1.0, |t| self.eval_texture(t, &tc).x);
                    (sm.kd, sm.ks, sm.kt) = Transmission::split(
                        sm.kd,
                        sm.ks,
                        mr.metallic * metallic,
                        tr.factor * t,
                        m.ior,
                    );
                }
                // Uniform light reflects off the specular lobe too (about
                // F0 of it): metals are not black under ambient light.
                sm.ks_ambient = sm.ks;
            }
            None => {
                sm.kd *= hit.color;
                if let Some(t) = texture {
                    sm.kd *= t;
                }
            }
        }
        if let Some(c) = m.clearcoat {
            if let Some(t) = c.texture {
                sm.clearcoat *= self.eval_texture(t, &tc).x.clamp(0.0, 1.0);
            }
            if let Some(t) = c.roughness_texture {
                sm.clearcoat_alpha = clearcoat_alpha(c.roughness * self.eval_texture(t, &tc).y);
            }
        }
        if let Some(o) = m.occlusion {
            let r = self.eval_texture(o.texture, &tc).x.clamp(0.0, 1.0);
            sm.ka *= 1.0 + o.strength.clamp(0.0, 1.0) * (r - 1.0);
        }
        if let Some(t) = m.emission_texture {
            sm.emission *= self.eval_texture(t, &tc).truncate();
        }
        if m.alpha_mode == AlphaMode::Blend {
            // BLEND: the point covers a fraction alpha (its reflection and
            // emission premultiplied) and lets `1 - alpha` straight through,
            // so additive techniques give alpha I_surface + (1 - alpha) I_behind.
            sm.kd *= alpha;
            sm.ks *= alpha;
            sm.kr *= alpha;
            sm.emission *= alpha;
            sm.kt = Vec3::splat(1.0 - alpha);
            sm.ior = 1.0;
        }
        (sm, alpha)
    }

    /// `(dp/du, dp/dv)`: world-space derivatives of position with respect to
    /// the texture coordinates on triangle `t` (pbrt-v4 section 6.5.3). For
    /// degenerate uvs, an arbitrary orthonormal tangent frame of the face.
    pub fn triangle_dpduv(&self, t: u32) -> (Vec3, Vec3) {
        let [i0, i1, i2] = self.triangles[t as usize].map(|i| i as usize);
        let (p0, p1, p2) = (self.positions[i0], self.positions[i1], self.positions[i2]);
        let (uv0, uv1, uv2) = (self.uvs[i0], self.uvs[i1], self.uvs[i2]);
        let (dp1, dp2) = (p1 - p0, p2 - p0);
        let (d1, d2) = (uv1 - uv0, uv2 - uv0);
        let det = d1.x * d2.y - d2.x * d1.y;
        if det.abs() > 1e-12 {
            let inv = 1.0 / det;
            let dpdu = (dp1 * d2.y - dp2 * d1.y) * inv;
            let dpdv = (dp2 * d1.x - dp1 * d2.x) * inv;
            if dpdu.is_finite() && dpdv.is_finite() && dpdu.cross(dpdv) != Vec3::ZERO {
                return (dpdu, dpdv);
            }
        }
        let f = crate::geometry::Frame::from_normal(self.face_normal(t));
        (f.s, f.t)
    }

    /// The shading normal after the material's tangent-space normal map and
    /// bump map: `n` is the unit (front-side) shading normal of `hit`,
    /// `dpdu`/`dpdv` its position derivatives (see
    /// [`PreparedScene::triangle_dpduv`]) and `duv_dx`/`duv_dy` the pixel
    /// footprint (zero for the finest level). Returns a unit normal on the
    /// front side; `n` itself when the material has neither map. Flip the
    /// result afterwards for the back of a two-sided surface.
    pub fn perturbed_normal(
        &self,
        hit: &SurfaceHit,
        n: Vec3,
        dpdu: Vec3,
        dpdv: Vec3,
        duv_dx: Vec2,
        duv_dy: Vec2,
    ) -> Vec3 {
        let m = self.material(hit.material);
        let mut n = n;
        let tc = Self::tex_coord(hit, duv_dx, duv_dy);
        if let Some(t) = m.normal_map {
            let rgb = self.eval_texture(t, &tc).truncate();
            n = normal_map_normal(n, hit.tangent, rgb);
        }
        let Some(bump) = m.bump else {
            return n;
        };
        let Some(tex) = self.scene.textures.get(bump.texture.index()) else {
            return n;
        };
        let grad = match tex {
            Texture::Procedural(p) if !p.use_uv => {
                // Central differences of the solid texture in object space,
                // carried to world space by the transpose of object_from_world
                // (gradients are covectors).
                let eps = 1e-3 / p.scale.abs().max(1e-6);
                let h = |d: Vec3| {
                    let tc = TexCoord {
                        p_object: hit.p_object + d,
                        ..tc
                    };
                    eval_height(tex, None, &tc)
                };
                let g_obj = Vec3::new(
                    h(Vec3::X * eps) - h(Vec3::NEG_X * eps),
                    h(Vec3::Y * eps) - h(Vec3::NEG_Y * eps),
                    h(Vec3::Z * eps) - h(Vec3::NEG_Z * eps),
                ) * (bump.height / (2.0 * eps));
                let object_from_world = self
                    .scene
                    .objects
                    .get(hit.object as usize)
                    .map_or(Mat4::IDENTITY, |o| {
                        o.transform.world_from_object().inverse()
                    });
                Mat3::from_mat4(object_from_world).transpose() * g_obj
            }
            _ => {
                // Central differences in uv, one texel of the filtered level apart.
                let (du, dv) = match tex {
                    Texture::Image(img) => {
                        let mip = self.mip_map(bump.texture);
                        let lod = mip.map_or(0.0, |mm| mm.lod(duv_dx, duv_dy));
                        let s = lod.exp2();
                        (s / img.width.max(1) as f32, s / img.height.max(1) as f32)
                    }
                    Texture::Procedural(p) => {
                        let e = 1e-3 / p.scale.abs().max(1e-6);
                        (e, e)
                    }
                };
                let h = |d: Vec2| {
                    let tc = TexCoord {
                        uv: hit.uv + d,
                        ..tc
                    };
                    let mip = match tex {
                        Texture::Image(_) => self.mip_map(bump.texture),
                        Texture::Procedural(_) => None,
                    };
                    eval_height(tex, mip, &tc)
                };
                let dh_du = (h(Vec2::new(du, 0.0)) - h(Vec2::new(-du, 0.0))) / (2.0 * du);
                let dh_dv = (h(Vec2::new(0.0, dv)) - h(Vec2::new(0.0, -dv))) / (2.0 * dv);
                uv_surface_gradient(n, dpdu, dpdv, bump.height * dh_du, bump.height * dh_dv)
            }
        };
        if !grad.is_finite() {
            return n;
        }
        bump_normal(n, grad)
    }

    /// `(dp/du, dp/dv)` at the surface point `sh` of primitive `prim`
    /// (triangles first, then spheres): [`PreparedScene::triangle_dpduv`]
    /// for a triangle; for a sphere the derivatives of its uv mapping
    /// (`u` the azimuth over 2 pi, `v` the polar angle over pi, object space),
    /// an orthonormal frame of the normal at the poles.
    pub fn surface_dpduv(&self, prim: u32, sh: &SurfaceHit) -> (Vec3, Vec3) {
        let nt = self.triangles.len() as u32;
        if prim < nt {
            return self.triangle_dpduv(prim);
        }
        let fallback = || {
            let f = crate::geometry::Frame::from_normal(sh.ng);
            (f.s, f.t)
        };
        let Some(s) = self.spheres.get((prim - nt) as usize) else {
            return fallback();
        };
        // Object space: p = r_o (sin th sin ph, cos th, sin th cos ph) with
        // ph = 2 pi (u - 1/2), th = pi v, r_o the object-space radius.
        let po = sh.p_object;
        let rho = (po.x * po.x + po.z * po.z).sqrt();
        let r_o = po.length();
        if rho <= 1e-6 * r_o || !rho.is_finite() {
            return fallback();
        }
        use std::f32::consts::{PI, TAU};
        let dpdu_o = Vec3::new(po.z, 0.0, -po.x) * TAU;
        let dpdv_o = Vec3::new(po.y * po.x / rho, -rho, po.y * po.z / rho) * PI;
        let world_from_object = Mat3::from_mat4(s.object_from_world.inverse());
        let (dpdu, dpdv) = (world_from_object * dpdu_o, world_from_object * dpdv_o);
        if dpdu.is_finite() && dpdv.is_finite() && dpdu.cross(dpdv) != Vec3::ZERO {
            (dpdu, dpdv)
        } else {
            fallback()
        }
    }

    /// The surface layer for ray tracers: what `ray`'s `hit` shades, with
    /// image textures filtered over the pixel footprint of `differentials`
    /// (the camera rays through the neighbouring pixels; `None` for the
    /// base level, as for secondary rays). See [`PreparedScene::shading_surface_at`].
    pub fn shading_surface(
        &self,
        ray: &Ray,
        hit: &crate::accel::Hit,
        differentials: Option<&RayDifferentials>,
    ) -> ShadingSurface {
        let sh = self.surface(ray, hit);
        let (dpdu, dpdv) = self.surface_dpduv(hit.prim, &sh);
        let (duv_dx, duv_dy) = differentials.map_or((Vec2::ZERO, Vec2::ZERO), |d| {
            d.uv_footprint(sh.p, sh.ng, dpdu, dpdv)
        });
        self.shading_surface_at(sh, dpdu, dpdv, duv_dx, duv_dy)
    }

    /// The surface layer every technique shades through: from the
    /// interpolated surface `sh` with position derivatives `dpdu`, `dpdv`
    /// and the pixel footprint in uv (`duv_dx`, `duv_dy`: uv units per
    /// pixel, zero for the base level), the textured material, the alpha,
    /// and the shading normal after the normal map and the bump map.
    ///
    /// The shading normal is on the front side of the geometric normal:
    /// a map that tilts it below the geometric horizon (`ns . ng < 0`) is
    /// mirrored back about the tangent plane (`ns - 2 (ns . ng) ng`), which
    /// is continuous at the horizon and keeps the tilt's direction.
    /// Techniques flip `ns` and `ng` together for the back of a surface.
    pub fn shading_surface_at(
        &self,
        sh: SurfaceHit,
        dpdu: Vec3,
        dpdv: Vec3,
        duv_dx: Vec2,
        duv_dy: Vec2,
    ) -> ShadingSurface {
        let m = self.material(sh.material);
        let (material, alpha) = self.textured_material(&sh, duv_dx, duv_dy);
        let mut ns = sh.ns;
        if m.bump.is_some() || m.normal_map.is_some() {
            ns = self.perturbed_normal(&sh, ns, dpdu, dpdv, duv_dx, duv_dy);
            let below = ns.dot(sh.ng);
            if below < 0.0 {
                ns = (ns - 2.0 * below * sh.ng).try_normalize().unwrap_or(sh.ng);
            }
        }
        ShadingSurface {
            hit: sh,
            ns,
            dpdu,
            dpdv,
            material,
            alpha,
            sidedness: m.sidedness,
        }
    }
}

/// What a technique shades at a surface point: the output of the surface
/// layer ([`PreparedScene::shading_surface_at`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShadingSurface {
    /// The interpolated surface: position, geometric normal, uv, ids
    /// (`hit.ns` is the interpolated normal before the maps).
    pub hit: SurfaceHit,
    /// Unit shading normal after the normal and bump maps, on the front
    /// side of `hit.ng`.
    pub ns: Vec3,
    /// World-space derivative of the position with respect to `u`.
    pub dpdu: Vec3,
    /// World-space derivative of the position with respect to `v`.
    pub dpdv: Vec3,
    /// Material parameters with textures and vertex colours applied.
    pub material: SurfaceMaterial,
    /// Coverage in `[0, 1]` ([`alpha_product`]).
    pub alpha: f32,
    /// The material's sidedness: how the back is seen
    /// ([`crate::scene::Sidedness::seen_from`]).
    pub sidedness: crate::scene::Sidedness,
}

impl ShadingSurface {
    /// How a viewer in unit direction `wo` sees this surface (the one
    /// sidedness rule, [`crate::scene::Sidedness::seen_from`]); the
    /// surface transmits when its textured `kt` is positive.
    pub fn facing(&self, wo: Vec3) -> crate::scene::Facing {
        let transmissive = self.material.kt.max_element() > 0.0;
        self.sidedness.seen_from(self.hit.ng.dot(wo), transmissive)
    }
}

/// The rays through the neighbouring pixels `(x + 1, y)` and `(x, y + 1)`
/// of a camera ray (pbrt-v4 section 10.1.1), from which ray tracers find a
/// hit's pixel footprint in uv as the scan converter does from its plane
/// equations.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RayDifferentials {
    /// Origin of the ray one pixel to the right (the eye of a perspective
    /// camera; an orthographic camera's rays start on its film).
    pub origin_dx: Vec3,
    /// Origin of the ray one pixel down.
    pub origin_dy: Vec3,
    /// Direction of the ray one pixel to the right.
    pub dir_dx: Vec3,
    /// Direction of the ray one pixel down.
    pub dir_dy: Vec3,
}

impl RayDifferentials {
    /// `(du/dx, dv/dx)` and `(du/dy, dv/dy)` at the point `p` of a surface with
    /// unit normal `n` and position derivatives `dpdu`, `dpdv`: each neighbour
    /// ray meets the tangent plane at `p + dp`, and `dp = dpdu du + dpdv dv`
    /// is solved in the least-squares sense (pbrt-v4 section 10.1.1). Zero
    /// where a ray is parallel to the plane or the parametrisation degenerate.
    pub fn uv_footprint(&self, p: Vec3, n: Vec3, dpdu: Vec3, dpdv: Vec3) -> (Vec2, Vec2) {
        let a00 = dpdu.dot(dpdu);
        let a01 = dpdu.dot(dpdv);
        let a11 = dpdv.dot(dpdv);
        let inv_det = 1.0 / (a00 * a11 - a01 * a01);
        let solve = |origin: Vec3, dir: Vec3| {
            let t = n.dot(p - origin) / n.dot(dir);
            let dp = origin + dir * t - p;
            let (b0, b1) = (dpdu.dot(dp), dpdv.dot(dp));
            let duv = Vec2::new(a11 * b0 - a01 * b1, a00 * b1 - a01 * b0) * inv_det;
            duv.is_finite().then_some(duv)
        };
        match (
            solve(self.origin_dx, self.dir_dx),
            solve(self.origin_dy, self.dir_dy),
        ) {
            (Some(dx), Some(dy)) => (dx, dy),
            _ => (Vec2::ZERO, Vec2::ZERO),
        }
    }
}

/// The mip-map pyramid of every image texture of `textures` (`None` for a
/// procedural one), built on scoped threads rather than rayon. The first
/// lookup comes from rayon workers shading in parallel: a rayon build
/// inside `OnceLock::get_or_init` can steal a shading job that waits on the
/// same lock (a deadlock), and a build outside the lock lets every worker
/// build its own copy (DamagedHelmet's five 2048x2048 textures: 105 MB a
/// copy). These threads take no rayon work, so waiting on them is safe.
fn build_mip_maps(textures: &[Texture]) -> Vec<Option<MipMap>> {
    use std::sync::atomic::{AtomicUsize, Ordering};
    let next = AtomicUsize::new(0);
    // Each thread takes the next texture until none is left.
    let work = || {
        let mut built = Vec::new();
        loop {
            let i = next.fetch_add(1, Ordering::Relaxed);
            let Some(t) = textures.get(i) else {
                return built;
            };
            if let Texture::Image(img) = t {
                built.push((i, MipMap::new(img)));
            }
        }
    };
    let images = textures
        .iter()
        .filter(|t| matches!(t, Texture::Image(_)))
        .count();
    let helpers = rayon::current_num_threads().min(images).saturating_sub(1);
    let mut out: Vec<Option<MipMap>> = textures.iter().map(|_| None).collect();
    std::thread::scope(|s| {
        // A helper that cannot be started leaves its share to the others.
        let handles: Vec<_> = (0..helpers)
            .filter_map(|_| std::thread::Builder::new().spawn_scoped(s, work).ok())
            .collect();
        let mut all = work();
        for h in handles {
            match h.join() {
                Ok(built) => all.extend(built),
                Err(panic) => std::panic::resume_unwind(panic),
            }
        }
        for (i, m) in all {
            out[i] = Some(m);
        }
    });
    out
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

    /// An emissive quad whose emission texture is constant (2, 0, 0.5): each
    /// triangle light carries factor times texture; without the texture the
    /// factor alone. A black texture gives lights of zero radiance.
    #[test]
    fn emissive_triangle_lights_carry_the_emission_texture() {
        for (texel, want) in [
            (Some([2.0, 0.0, 0.5]), Vec3::new(6.0, 0.0, 1.5)),
            (Some([0.0; 3]), Vec3::ZERO),
            (None, Vec3::splat(3.0)),
        ] {
            let mut s = Scene::default();
            let emission_texture = texel.map(|[r, g, b]| {
                s.add_texture(Texture::Image(crate::scene::ImageTexture {
                    source: "t".into(),
                    width: 2,
                    height: 2,
                    texels: vec![[r, g, b, 1.0]; 4],
                    wrap: crate::scene::WrapMode::Repeat,
                    ..Default::default()
                }))
            });
            s.add_material(Material {
                emission: Vec3::splat(3.0),
                emission_texture,
                ..Material::default()
            });
            let m = s.add_mesh(primitives::quad(Vec3::ZERO, Vec3::X, Vec3::Y));
            s.objects.push(Object {
                geometry: Geometry::Mesh(m),
                ..Default::default()
            });
            let ps = PreparedScene::new(&s, PrepareOptions::default());
            assert_eq!(ps.lights.len(), 2);
            for l in &ps.lights {
                let Light::Area { color, .. } = l else {
                    panic!("{l:?}");
                };
                assert!((*color - want).abs().max_element() < 1e-6, "{color}");
            }
        }
    }

    #[test]
    fn uv_footprint_of_a_plane_facing_the_camera_is_the_closed_form() {
        // A plane at distance d with dp/du = a x, dp/dv = b y, seen along -z:
        // a neighbour ray tilted by e in x meets it d e further, du = d e / a.
        let (d, e, a, b) = (4.0f32, 0.01f32, 2.0f32, 0.5f32);
        let rd = RayDifferentials {
            origin_dx: Vec3::ZERO,
            origin_dy: Vec3::ZERO,
            dir_dx: Vec3::new(e, 0.0, -1.0),
            dir_dy: Vec3::new(0.0, -e, -1.0),
        };
        let p = Vec3::new(0.0, 0.0, -d);
        let (dx, dy) = rd.uv_footprint(p, Vec3::Z, Vec3::X * a, Vec3::Y * b);
        assert!(
            (dx - Vec2::new(d * e / a, 0.0)).abs().max_element() < 1e-6,
            "{dx}"
        );
        assert!(
            (dy - Vec2::new(0.0, -d * e / b)).abs().max_element() < 1e-6,
            "{dy}"
        );
        // A ray parallel to the plane has no footprint.
        let par = RayDifferentials {
            dir_dx: Vec3::X,
            ..rd
        };
        let none = par.uv_footprint(p, Vec3::Z, Vec3::X * a, Vec3::Y * b);
        assert_eq!(none, (Vec2::ZERO, Vec2::ZERO));
    }

    #[test]
    fn sphere_dpduv_matches_finite_differences_of_its_uv_mapping() {
        let mut s = Scene::default();
        s.add_material(Material::default());
        s.objects.push(Object {
            geometry: Geometry::Sphere { radius: 1.5 },
            transform: Transform {
                translate: Vec3::new(1.0, 2.0, -3.0),
                ..Default::default()
            },
            ..Default::default()
        });
        let ps = PreparedScene::new(
            &s,
            PrepareOptions {
                analytic_spheres: true,
                ..Default::default()
            },
        );
        let c = ps.spheres[0].center;
        let r = ps.spheres[0].radius;
        let at = |dir: Vec3| {
            let ray = Ray::new(c + dir * 10.0, -dir);
            let hit = crate::accel::Hit {
                t: 10.0 - r,
                prim: 0,
                u: 0.0,
                v: 0.0,
            };
            ps.surface(&ray, &hit)
        };
        let sh = at(Vec3::new(0.3, 0.4, 0.8).normalize());
        let (dpdu, dpdv) = ps.surface_dpduv(0, &sh);
        // Moving along dp/du by h changes u by h and v by 0 (and vice versa).
        for (dp, want) in [(dpdu, Vec2::X), (dpdv, Vec2::Y)] {
            let h = 1e-3;
            let q = at((sh.p + dp * h - c).normalize());
            let got = (q.uv - sh.uv) / h;
            assert!((got - want).abs().max_element() < 2e-2, "{got} vs {want}");
        }
        assert!(dpdu.cross(dpdv).dot(sh.ng) != 0.0);
    }

    #[test]
    fn maps_never_leave_the_shading_normal_below_the_geometric_horizon() {
        use crate::scene::{ImageTexture, WrapMode};
        // A one-texel normal map that tilts the normal 60 degrees along +x,
        // on a quad whose interpolated normals already lean 45 degrees to
        // +x: the map's tilt goes below the horizon and is mirrored back.
        let mut s = Scene::default();
        let tilt = Vec3::new(0.75f32.sqrt(), 0.0, 0.5);
        let rgb = (tilt + Vec3::ONE) * 0.5;
        let tex = s.add_texture(Texture::Image(ImageTexture {
            source: "n".into(),
            width: 1,
            height: 1,
            texels: vec![[rgb.x, rgb.y, rgb.z, 1.0]],
            wrap: WrapMode::Repeat,
            ..Default::default()
        }));
        s.add_material(Material {
            normal_map: Some(tex),
            ..Default::default()
        });
        let mut mesh = primitives::quad(Vec3::ZERO, Vec3::X, Vec3::Y);
        let lean = Vec3::new(1.0, 0.0, 1.0).normalize();
        mesh.normals = vec![lean; mesh.positions.len()];
        let m = s.add_mesh(mesh);
        s.objects.push(Object {
            geometry: Geometry::Mesh(m),
            smooth: true,
            ..Default::default()
        });
        let ps = PreparedScene::new(&s, PrepareOptions::default());
        let sh = ps.triangle_surface(0, 0.25, 0.25);
        let (dpdu, dpdv) = ps.triangle_dpduv(0);
        let ss = ps.shading_surface_at(sh, dpdu, dpdv, Vec2::ZERO, Vec2::ZERO);
        let raw = ps.perturbed_normal(&sh, sh.ns, dpdu, dpdv, Vec2::ZERO, Vec2::ZERO);
        assert!(raw.dot(sh.ng) < 0.0, "the set-up must go below: {raw}");
        assert!(ss.ns.dot(sh.ng) > 0.0, "{}", ss.ns);
        let mirrored = raw - 2.0 * raw.dot(sh.ng) * sh.ng;
        assert!((ss.ns - mirrored).length() < 1e-6);
        assert!((ss.ns.length() - 1.0).abs() < 1e-6);
        assert_eq!(ss.alpha, 1.0);
    }
}
