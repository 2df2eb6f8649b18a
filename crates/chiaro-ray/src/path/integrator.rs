//! The scalar path integrator: one path at a time, the unidirectional path
//! tracer of Kajiya (1986) with Russian roulette (Arvo and Kirk 1990).

use super::lanes;
use super::lanes_env::escape_mis;
use super::lights::NO_LIGHT;
use chiaro_core::accel::{Accelerator, Hit};
use chiaro_core::geometry::{Ray, offset_ray_origin};
use chiaro_core::prepared::PreparedScene;
use chiaro_core::sampling::{SobolSampler, power_heuristic};
use chiaro_core::scene::{AlphaMode, AreaShape, Facing, Light, RenderSettings, Sidedness};
use chiaro_core::shading::texture::EnvironmentLight;
use chiaro_core::shading::{Bsdf, BsdfSample, LightSampler, SurfaceMaterial, TriangleEmitter};
use chiaro_core::shadow::ShadowCasters;
use glam::Vec3;

/// The path tracer over one prepared scene.
pub(super) struct PathTracer<'a, 's> {
    pub(super) prepared: &'a PreparedScene<'s>,
    pub(super) accel: &'a dyn Accelerator,
    /// Lights that next-event estimation samples (not ambient).
    pub(super) lights: Vec<&'a Light>,
    /// The environment map as a light: light number `lights.len()`, after
    /// `lights` (`None` without a map, or when it is black).
    pub(super) env: Option<EnvironmentLight<'s>>,
    /// Selection of `lights` and then `env`: by power, or by the light
    /// hierarchy as seen from the shading point.
    pub(super) light_sampler: LightSampler,
    /// Sampling data of each light in `lights` that is an emissive triangle
    /// (`None` for the others, sampled through `sample_light`, and for the
    /// environment).
    pub(super) tri_lights: Vec<Option<TriangleEmitter>>,
    /// `tri_lights` without the `Option`s when every light is an emissive
    /// triangle and there are at most `lanes::SELECT_LIGHTS` of them (the
    /// lock-step kernel then gathers each lane's light by selects over
    /// this list); empty otherwise.
    pub(super) select_lights: Vec<TriangleEmitter>,
    /// Light index (in `lights`) of each triangle, `NO_LIGHT` when it does not emit.
    pub(super) triangle_light: Vec<u32>,
    /// Per-triangle geometry cached for the common untextured case.
    tris: Vec<TriInfo>,
    /// Per sphere: true when its material is the cached one unchanged
    /// (untextured, no maps, not metallic-roughness), so that
    /// [`Self::plain_sphere`] shades it.
    plain_spheres: Vec<bool>,
    /// Per-material constants, by material id.
    pub(super) materials: Vec<MaterialInfo>,
    /// Shadow rays' casters when the scene has BLEND surfaces (they pass
    /// those, stop at every other surface); `None`: the plain any-hit query.
    pub(super) shadows: Option<ShadowCasters>,
    pub(super) max_depth: u32,
    pub(super) rr_depth: u32,
}

/// Largest difference in any coordinate between the unit vertex normals of
/// a triangle whose shading normal is taken as constant (16 float ulps at
/// 1: far below any intended smoothing, far above rounding).
const FLAT_NORMAL_TOLERANCE: f32 = 1e-6;

/// Consecutive BLEND pass-throughs a path makes without counting them as
/// bounces; past this each counts (a bound on the loop, never met by a
/// real scene).
pub(super) const MAX_PASSES: u32 = 64;

/// What shading needs of a triangle whose material has no texture and whose
/// vertices have no colours (`plain`): the surface is then its position,
/// normals and the material's constants.
#[derive(Clone, Copy)]
struct TriInfo {
    ng: Vec3,
    /// The shading normal when the three vertex normals are equal (within
    /// `FLAT_NORMAL_TOLERANCE`).
    flat_ns: Option<Vec3>,
    plain: bool,
}

/// A material's parameters and the constants derived from them: per
/// material for the untextured case, per hit point otherwise.
#[derive(Clone, Copy)]
pub(super) struct MaterialInfo {
    /// The parameters and their lobe choice.
    pub(super) bsdf: Bsdf,
    /// Emits from both faces (`Material::emission_two_sided`).
    pub(super) emission_two_sided: bool,
    /// The material's sidedness (the back of a one-sided one is black).
    pub(super) sidedness: Sidedness,
    /// True when the emission is positive in some channel.
    pub(super) emissive: bool,
    /// True when textures, a bump map or a normal map change the
    /// parameters or the shading normal per point.
    pub(super) textured: bool,
    /// True when the only lobe is Lambert's (no glossy, mirror or
    /// transmission lobe), chosen with probability 1 and weighted by `kd`:
    /// the vertices that [`lanes`] shades with its own Lambert arithmetic.
    pub(super) lambert: bool,
    /// True for the vertices [`lanes`] shades wherever they are seen: a
    /// two-sided `lambert` or mixture of Lambert and a glossy lobe (GGX,
    /// Beckmann, Phong or Blinn: the glTF metal/dielectric mix) without
    /// mirror, transmission, clear coat or BLEND, or `delta`. A mixture's sample never reads
    /// the Fresnel choice's number (see [`Bsdf::sample`]: the lobe number is
    /// below 1, so the choice falls in the non-delta lobes); a `delta`
    /// vertex's may, and the kernel then moves that lane's later pairs on
    /// by one.
    pub(super) lock_step: bool,
    /// True for a one-sided Lambert or Lambert-and-glossy material (a
    /// one-sided emitter, say): [`lanes`] shades it where it is seen from
    /// the front (`Sidedness::seen_from`), where it is the two-sided
    /// material, and hands its black back to the scalar loop.
    pub(super) front_lock_step: bool,
    /// True when every lobe is a delta one (ideal mirror, smooth conductor,
    /// smooth Fresnel or fixed-weight transmission: no diffuse, glossy,
    /// rough or coat lobe, so next-event estimation finds nothing), without
    /// absorption or BLEND, and its back not black: the vertices that
    /// `lanes_delta` samples in the kernel.
    pub(super) delta: bool,
    /// True when `Bsdf::eval` is zero for every pair of directions (no
    /// diffuse colour, no specular lobe): next-event estimation then finds
    /// nothing, and skips its light sample.
    pub(super) dark: bool,
    /// A glTF BLEND material: its transmission is a straight pass-through.
    pub(super) blend: bool,
    /// Beer's absorption coefficient inside a transmissive material (per
    /// scene unit; zero for the rest).
    pub(super) absorption: Vec3,
}

impl MaterialInfo {
    fn new(surface: SurfaceMaterial, m: &chiaro_core::scene::Material) -> Self {
        let bsdf = Bsdf::new(surface, m.fresnel);
        let lobes = &bsdf.lobes;
        let [wd, ws, wr, wt] = lobes.weights;
        // (The lone lobe's probability is wd / wd = 1 and its weight kd / 1
        // = kd exactly; the kernel relies on both.)
        let lambert = wd > 0.0 && ws == 0.0 && wr == 0.0 && wt == 0.0 && !lobes.specular;
        // (A one-sided material's back is black: the scalar loop's test.)
        let two_sided = m.sidedness != Sidedness::OneSided;
        let lambert = lambert && lobes.p_diffuse == 1.0 && lobes.lambert_weight == surface.kd;
        // Diffuse and glossy lobes only; no absorption (no `kt` at all).
        let mixture = lobes.total > 0.0
            && wr == 0.0
            && wt == 0.0
            && !lobes.rough
            && lobes.p_coat == 0.0
            && surface.kt == Vec3::ZERO
            && m.alpha_mode != AlphaMode::Blend;
        let transmissive = surface.kt.max_element() > 0.0;
        let absorption = if transmissive {
            m.absorption.max(Vec3::ZERO)
        } else {
            Vec3::ZERO
        };
        let delta = (wr > 0.0 || wt > 0.0)
            && surface.kd == Vec3::ZERO
            && ws == 0.0
            && !lobes.specular
            && !lobes.rough
            && lobes.p_coat == 0.0
            && (two_sided || transmissive)
            && absorption.max_element() <= 0.0
            && m.alpha_mode != AlphaMode::Blend;
        Self {
            lambert,
            lock_step: ((lambert || mixture) && two_sided) || delta,
            front_lock_step: (lambert || mixture) && !two_sided,
            delta,
            // (The rough dielectric reflects light samples in front of it.)
            dark: surface.kd == Vec3::ZERO
                && !lobes.specular
                && !lobes.rough
                && lobes.p_coat == 0.0,
            emissive: surface.emission.max_element() > 0.0,
            bsdf,
            emission_two_sided: m.emission_two_sided,
            sidedness: m.sidedness,
            textured: m.is_textured() || m.bump.is_some() || m.normal_map.is_some(),
            blend: m.alpha_mode == AlphaMode::Blend,
            absorption,
        }
    }
}

/// The MIS pdf a path carries from a BSDF sample `s` at a vertex of
/// viewer-side geometric normal `ng`: 0 for a delta lobe, and for a
/// direction behind the surface (next-event estimation samples no light
/// there, so what a rough refraction finds is not weighted against it);
/// else the sample's pdf. The scalar loop's and the kernel's one rule.
#[inline(always)]
pub(super) fn mis_pdf(s: &BsdfSample, ng: Vec3) -> f32 {
    if s.delta || ng.dot(s.wi) < 0.0 {
        0.0
    } else {
        s.pdf
    }
}

/// The geometry of a path vertex.
#[derive(Clone, Copy)]
pub(super) struct Vertex {
    /// Position, world space.
    pub(super) p: Vec3,
    /// Unit geometric normal (front side).
    pub(super) ng: Vec3,
    /// Unit shading normal (front side).
    pub(super) ns: Vec3,
}

/// A path between two bounces: what the scalar loop carries from one
/// vertex to the next.
#[derive(Clone, Copy)]
pub(super) struct PathState {
    /// The ray to trace next.
    pub(super) ray: Ray,
    /// Its segment number (0 = the camera ray).
    pub(super) depth: u32,
    /// Throughput.
    pub(super) beta: Vec3,
    /// Radiance gathered so far.
    pub(super) l: Vec3,
    /// MIS state of the previous bounce: its pdf (0 = delta or camera).
    pub(super) prev_pdf: f32,
    /// The previous vertex (the camera for a camera ray).
    pub(super) prev_p: Vec3,
    /// Its geometric normal on the side it was left from (zero at the
    /// camera), for the light choice's probability there.
    pub(super) prev_n: Vec3,
}

impl PathState {
    fn camera(ray: Ray) -> Self {
        Self {
            ray,
            depth: 0,
            beta: Vec3::ONE,
            l: Vec3::ZERO,
            prev_pdf: 0.0,
            prev_p: ray.origin,
            prev_n: Vec3::ZERO,
        }
    }
}

impl<'a, 's> PathTracer<'a, 's> {
    pub(super) fn new(
        prepared: &'a PreparedScene<'s>,
        accel: &'a dyn Accelerator,
        settings: &RenderSettings,
        env_sampling: bool,
    ) -> Self {
        let lights: Vec<&Light> = prepared
            .lights
            .iter()
            .filter(|l| !matches!(l, Light::Ambient { .. }))
            .collect();
        // Select lights in proportion to a rough power estimate, or by
        // the hierarchy.
        let scene_radius = 0.5 * prepared.bounds.diagonal().max(1e-3);
        let env = env_sampling
            .then(|| EnvironmentLight::new(prepared.scene))
            .flatten();
        let light_sampler = LightSampler::new(
            &lights,
            scene_radius,
            env.as_ref().map(|e| e.mean_luminance()),
            settings.light_selection,
        );
        let mut tri_lights: Vec<Option<TriangleEmitter>> = lights
            .iter()
            .map(|l| match l {
                Light::Area {
                    shape: AreaShape::Triangle { a, b, c },
                    two_sided,
                    ..
                } => TriangleEmitter::new(*a, *b, *c, l.power_rgb(), *two_sided),
                _ => None,
            })
            .collect();
        if env.is_some() {
            tri_lights.push(None);
        }
        // Emissive triangle lights follow the scene's lights in `prepared.lights`,
        // in the order of `prepared.emissive_triangles` (skipping degenerate ones).
        let mut triangle_light = vec![NO_LIGHT; prepared.triangles.len()];
        let first_tri_light = lights.iter().position(|l| {
            matches!(
                l,
                Light::Area {
                    shape: AreaShape::Triangle { .. },
                    ..
                }
            )
        });
        if let Some(first) = first_tri_light {
            let mut k = first;
            for &t in &prepared.emissive_triangles {
                let [a, b, c] =
                    prepared.triangles[t as usize].map(|i| prepared.positions[i as usize]);
                if chiaro_core::geometry::face_normal(a, b, c).is_some() && k < lights.len() {
                    if let Some(slot) = triangle_light.get_mut(t as usize) {
                        *slot = k as u32;
                    }
                    k += 1;
                }
            }
        }
        let materials: Vec<MaterialInfo> = prepared
            .scene
            .materials
            .iter()
            .map(|m| MaterialInfo::new(SurfaceMaterial::from_material(m), m))
            .collect();
        let tris = prepared
            .triangles
            .iter()
            .enumerate()
            .map(|(t, tri)| {
                let [i0, i1, i2] = tri.map(|i| i as usize);
                let ng = prepared.face_normal(t as u32);
                let n0 = prepared.normals[i0];
                // Vertex normals equal within `FLAT_NORMAL_TOLERANCE` (a faceted
                // quad's two triangles' face normals, averaged onto shared
                // vertices, differ in their last bit): the interpolated normal
                // is then `n0` within the tolerance everywhere on the triangle.
                let close = |n: Vec3| (n - n0).abs().max_element() <= FLAT_NORMAL_TOLERANCE;
                let same_normals = close(prepared.normals[i1]) && close(prepared.normals[i2]);
                // What `triangle_surface` computes for equal vertex normals.
                let flat_ns = same_normals.then(|| {
                    let ns = n0.try_normalize().unwrap_or(ng);
                    if ns.dot(ng) < 0.0 { ng } else { ns }
                });
                let white = [i0, i1, i2]
                    .iter()
                    .all(|&i| prepared.colors[i] == Vec3::ONE);
                let untextured = materials
                    .get(prepared.tri_material[t].index())
                    .is_some_and(|m| !m.textured);
                TriInfo {
                    ng,
                    flat_ns,
                    plain: white && untextured,
                }
            })
            .collect();
        let plain_spheres = prepared
            .spheres
            .iter()
            .map(|sp| {
                let m = prepared.material(sp.material);
                materials
                    .get(sp.material.index())
                    .is_some_and(|info| !info.textured && m.metallic_roughness.is_none())
            })
            .collect();
        let by_power = light_sampler.power_table().is_some();
        let select_lights = if by_power && tri_lights.len() <= lanes::SELECT_LIGHTS {
            // (`None` if any light is not a triangle.)
            let all: Option<Vec<TriangleEmitter>> = tri_lights.iter().copied().collect();
            all.unwrap_or_default()
        } else {
            Vec::new()
        };
        Self {
            prepared,
            accel,
            lights,
            env,
            light_sampler,
            tri_lights,
            select_lights,
            triangle_light,
            tris,
            plain_spheres,
            materials,
            shadows: ShadowCasters::blend_only(prepared),
            max_depth: settings.path.max_depth,
            rr_depth: settings.path.rr_depth.max(1),
        }
    }

    /// The vertex at `hit` and its cached material when `hit` is on a plain
    /// triangle (`None`: evaluate it through the surface layer,
    /// `PreparedScene::shading_surface`, or a sphere's).
    #[inline(always)]
    pub(super) fn plain_surface(
        &self,
        prim: u32,
        u: f32,
        v: f32,
    ) -> Option<(Vertex, &MaterialInfo)> {
        let t = prim as usize;
        let info = self.tris.get(t).filter(|info| info.plain)?;
        let [i0, i1, i2] = self.prepared.triangles[t].map(|i| i as usize);
        let pos = &self.prepared.positions;
        let w = 1.0 - u - v;
        // As `PreparedScene::triangle_surface` interpolates it.
        // (A `match`, not `unwrap_or_else`: the closure's captures were
        // stored for every hit, flat or not.)
        let ns = match info.flat_ns {
            Some(ns) => ns,
            None => {
                let nrm = &self.prepared.normals;
                let ns = (nrm[i0] * w + nrm[i1] * u + nrm[i2] * v)
                    .try_normalize()
                    .unwrap_or(info.ng);
                if ns.dot(info.ng) < 0.0 { info.ng } else { ns }
            }
        };
        let v = Vertex {
            p: pos[i0] * w + pos[i1] * u + pos[i2] * v,
            ng: info.ng,
            ns,
        };
        let material = self.materials.get(self.prepared.tri_material[t].index())?;
        Some((v, material))
    }

    /// The vertex at `ray`'s hit at `t` on sphere `s` (counted after the
    /// triangles) and its cached material when the sphere is plain: the
    /// surface layer's point and normal (`PreparedSphere::point_normal`,
    /// which `PreparedScene::surface` uses) and the untextured material.
    #[inline]
    pub(super) fn plain_sphere(
        &self,
        ray: &Ray,
        t: f32,
        s: u32,
    ) -> Option<(Vertex, &MaterialInfo)> {
        let s = s as usize;
        if !self.plain_spheres.get(s).copied().unwrap_or(false) {
            return None;
        }
        let sphere = &self.prepared.spheres[s];
        let (p, n) = sphere.point_normal(ray, t);
        let material = self.materials.get(sphere.material.index())?;
        Some((Vertex { p, ng: n, ns: n }, material))
    }

    /// The vertex of a hit (`t`, `prim`, barycentrics `u`, `v`) on a plain
    /// triangle ([`Self::plain_surface`]) or sphere ([`Self::plain_sphere`]);
    /// `None`: evaluate it through the surface layer.
    #[inline(always)]
    pub(super) fn plain_vertex(
        &self,
        ray: &Ray,
        t: f32,
        prim: u32,
        u: f32,
        v: f32,
    ) -> Option<(Vertex, &MaterialInfo)> {
        match prim.checked_sub(self.tris.len() as u32) {
            None => self.plain_surface(prim, u, v),
            Some(s) => self.plain_sphere(ray, t, s),
        }
    }

    /// The vertex at `ray`'s `hit` through the surface layer (the base
    /// level of textures) and its material there: textures, vertex colours
    /// and normal or bump maps applied. What both loops shade at a hit
    /// that [`Self::plain_vertex`] does not take.
    #[inline]
    pub(super) fn surface_vertex(&self, ray: &Ray, hit: &Hit) -> (Vertex, MaterialInfo) {
        let ss = self.prepared.shading_surface(ray, hit, None);
        let mat = self.prepared.material(ss.hit.material);
        let v = Vertex {
            p: ss.hit.p,
            ng: ss.hit.ng,
            ns: ss.ns,
        };
        (v, MaterialInfo::new(ss.material, mat))
    }

    /// Radiance along camera ray `ray`, and the first hit's distance and normal.
    pub(super) fn radiance(
        &self,
        ray: Ray,
        rng: &mut SobolSampler,
        rays: &mut u64,
    ) -> (Vec3, Option<(f32, Vec3)>) {
        self.radiance_from(PathState::camera(ray), None, rng, rays)
    }

    /// The rest of the path from `state` (whose ray is about to be traced,
    /// or has been: `traced` is then its hit, already counted in `rays`):
    /// its radiance estimate (`state.l` included), and the first hit's
    /// distance and normal when `state.depth` is 0. `rng` must be at the
    /// pair the scalar loop would have reached.
    pub(super) fn radiance_from(
        &self,
        state: PathState,
        mut traced: Option<Hit>,
        rng: &mut SobolSampler,
        rays: &mut u64,
    ) -> (Vec3, Option<(f32, Vec3)>) {
        let PathState {
            mut ray,
            depth: start,
            mut beta,
            mut l,
            mut prev_pdf,
            mut prev_p,
            mut prev_n,
        } = state;
        let mut first = None;
        let mut owned;
        // A straight pass through a BLEND surface is not a bounce: `depth`
        // stays, and so does the MIS state of the vertex before it.
        let (mut depth, mut passes) = (start, 0u32);
        while depth < self.max_depth {
            let hit = match traced.take() {
                Some(hit) => Some(hit),
                None => {
                    *rays += 1;
                    // Camera rays skip the backs of single-sided materials.
                    if depth == 0 {
                        self.accel.intersect_camera(&ray)
                    } else {
                        self.accel.intersect(&ray)
                    }
                }
            };
            let Some(hit) = hit else {
                l += beta * self.escaped(&ray, depth, prev_pdf);
                break;
            };
            // The hit is used field by field: a copy of the whole struct
            // would load 16 bytes that `intersect` stored in pieces, which
            // stalls store-to-load forwarding.
            let Hit { t, prim, u, v: hv } = hit;
            let (v, info) = match self.plain_vertex(&ray, t, prim, u, hv) {
                Some(plain) => plain,
                None => {
                    let v;
                    (v, owned) = self.surface_vertex(&ray, &Hit { t, prim, u, v: hv });
                    (v, &owned)
                }
            };
            // Every ray's direction is unit: the camera's are normalised,
            // and sampled directions are unit vectors (up to rounding).
            let wo = -ray.dir;
            if depth == 0 && first.is_none() {
                first = Some((t * ray.dir.length(), v.ns));
            }
            let m = &info.bsdf.m;
            let cos_o = v.ng.dot(wo);
            // Beer's law along a segment inside an absorbing medium (the
            // ray met the inside of its surface), as the Whitted tracer does.
            if cos_o < 0.0 && info.absorption.max_element() > 0.0 {
                beta *= (-info.absorption * (t * ray.dir.length())).exp();
            }
            // Emission seen along the path (one-sided unless two-sided).
            if info.emissive && (info.emission_two_sided || cos_o > 0.0) {
                let w = if prev_pdf == 0.0 {
                    1.0
                } else {
                    self.emitter_mis_weight(prim, (prev_p, prev_n), &v, wo, prev_pdf)
                };
                l += beta * m.emission * w;
            }
            // The back of a one-sided surface reflects nothing.
            let transmissive = m.kt.max_element() > 0.0;
            if info.sidedness.seen_from(cos_o, transmissive) == Facing::BackBlack {
                break;
            }
            // Shading frame on the side of the viewer.
            let front = cos_o >= 0.0;
            // (A multiplication by the side's sign: the same values, no branch.)
            let side = if front { 1.0 } else { -1.0 };
            let (n, ng) = (v.ns * side, v.ng * side);
            // A rough dielectric is evaluated across the interface from the
            // side of `wo` (ior or 1 / ior).
            let inside;
            let info = if !front && info.bsdf.lobes.rough {
                inside = MaterialInfo {
                    bsdf: info.bsdf.seen_from(false),
                    ..*info
                };
                &inside
            } else {
                info
            };
            let last = depth + 1 >= self.max_depth;
            // Next-event estimation.
            l += beta * self.direct(v.p, info, n, ng, wo, !last, rng, rays);
            if last && !info.blend {
                break;
            }
            // Continue the path.
            let Some(s) = Self::sample_bsdf(&info.bsdf, n, ng, wo, front, rng) else {
                break;
            };
            // (BLEND's delta transmission, at ior 1, is the pass-through.)
            let pass = info.blend && s.delta && ng.dot(s.wi) < 0.0 && passes < MAX_PASSES;
            if last && !pass {
                break;
            }
            beta *= s.weight;
            if !beta.is_finite() || beta.max_element() <= 0.0 {
                break;
            }
            if !pass {
                prev_pdf = mis_pdf(&s, ng);
                prev_p = v.p;
                prev_n = ng;
            }
            ray = Ray::new(offset_ray_origin(v.p, v.ng, s.wi), s.wi);
            // Russian roulette.
            if depth + 1 >= self.rr_depth {
                let q = beta.max_element().min(0.95);
                if rng.next_1d() >= q {
                    break;
                }
                beta /= q;
            }
            if pass {
                passes += 1;
            } else {
                passes = 0;
                depth += 1;
            }
        }
        (l, first)
    }

    /// Radiance of a ray that escaped at path depth `depth` after a scatter
    /// of pdf `prev_pdf` (0: a delta lobe): `miss_radiance`'s rule (the
    /// camera sees the background, other rays the environment map, which
    /// lights the scene), MIS-weighted against the environment's next-event
    /// estimation after a non-delta scatter; without a map the plain
    /// background is seen only directly (camera or delta chains) and lights
    /// nothing.
    #[inline]
    pub(super) fn escaped(&self, ray: &Ray, depth: u32, prev_pdf: f32) -> Vec3 {
        let scene = self.prepared.scene;
        if let Some(env) = self.env.as_ref().filter(|_| self.sees_map(depth)) {
            // (`miss_radiance` of a scattered ray is the map's radiance:
            // with its pdf from one lookup.)
            let (l, pdf) = env.radiance_pdf(ray.dir);
            return if escape_mis(depth, prev_pdf) {
                l * self.escape_weight(ray.origin, prev_pdf, pdf)
            } else {
                l
            };
        }
        if scene.environment.is_some() || depth == 0 || prev_pdf == 0.0 {
            chiaro_core::shading::texture::miss_radiance(scene, ray.dir, depth == 0)
        } else {
            Vec3::ZERO
        }
    }

    /// True when a ray escaping at segment `depth` sees the environment
    /// light's map (`miss_radiance`'s rule): every scattered ray, and the
    /// camera's when the map is the background.
    #[inline(always)]
    pub(super) fn sees_map(&self, depth: u32) -> bool {
        let background = |e: &chiaro_core::scene::Environment| e.as_background;
        self.env.is_some()
            && (depth > 0
                || self
                    .prepared
                    .scene
                    .environment
                    .as_ref()
                    .is_some_and(background))
    }

    /// The power heuristic's weight of the map's radiance found by BSDF
    /// sampling from `origin` with pdf `prev_pdf`, against the
    /// environment's next-event estimation, whose density there is `pdf`.
    #[inline(always)]
    pub(super) fn escape_weight(&self, origin: Vec3, prev_pdf: f32, pdf: f32) -> f32 {
        // (The environment's choice does not depend on the point.)
        let pick = self.light_pick_pdf(origin, Vec3::ZERO, self.lights.len());
        power_heuristic(prev_pdf, pick * pdf)
    }

    /// Samples the next direction through [`Bsdf::sample`], drawing its
    /// numbers in the order the lock-step kernel follows: the lobe choice's
    /// (its pair skipped when there is one lobe), the direction's pair, and
    /// the Fresnel choice's only when the layer asks for it.
    #[inline]
    fn sample_bsdf(
        bsdf: &Bsdf,
        n: Vec3,
        ng: Vec3,
        wo: Vec3,
        front: bool,
        rng: &mut SobolSampler,
    ) -> Option<BsdfSample> {
        if !bsdf.scatters() {
            return None;
        }
        let u_lobe = if bsdf.needs_lobe_number() {
            rng.next_1d()
        } else {
            rng.skip(1);
            0.0
        };
        let u = rng.next_2d();
        bsdf.sample(n, ng, wo, front, u_lobe, u, || rng.next_1d())
    }
}
