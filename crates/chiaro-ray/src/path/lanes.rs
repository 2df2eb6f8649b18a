//! The path tracer's lock-step kernel: [`LANES`] samples of one pixel
//! traced together, bounce by bounce, so that the shading and sampling
//! arithmetic of their Lambertian vertices runs as one vectorised loop per
//! step instead of once per path.
//!
//! It computes exactly what [`PathTracer::radiance`] computes for each
//! sample, bit for bit: every lane does the scalar loop's operations in
//! the scalar loop's order (Rust never fuses or reorders float operations,
//! so a loop over lanes gives each lane the scalar result), and draws its
//! numbers from the same Sobol pairs ([`SobolSampler::lanes_2d`]). It
//! shades the vertices whose material is Lambertian, a mixture of Lambert
//! and a glossy lobe (GGX and the other microfacet and Phong lobes: the
//! glTF metal/dielectric mix), or delta lobes alone (ideal mirror, smooth
//! conductor, smooth Fresnel or fixed-weight transmission, without
//! absorption: `lanes_delta.rs`), `MaterialInfo::lock_step` (a one-sided
//! Lambert or mixture where it is seen from the front: `front_lock_step`,
//! a one-sided emitter say): of plain
//! triangles and spheres from their cached material
//! ([`PathTracer::plain_vertex`]), of textured, vertex-coloured or
//! normal-mapped ones from the material the scalar loop resolves at the
//! hit ([`PathTracer::surface_vertex`], lane by lane). A delta vertex's
//! Fresnel choice draws one more number, so each lane keeps its own lead
//! over the batch's pair count (`LanePairs`). A lane whose vertex it does
//! not shade (a delta lobe mixed with diffuse or glossy ones, a rough
//! dielectric, a clear coat, an absorbing medium, the black back of a
//! one-sided surface) leaves the batch there and finishes in the scalar loop from
//! the same state and the same pair ([`PathTracer::radiance_from`]), and
//! so do the last few lanes of a batch ([`SCALAR_TAIL`]).
//!
//! Rays are still traced one at a time; what runs lane-parallel is the
//! rest: Sobol draws, light sampling, the Lambert terms, MIS weights,
//! cosine sampling, Russian roulette. Emissive-triangle lights are sampled
//! lane-parallel at Lambertian vertices. The environment's work is in
//! `lanes_env.rs`: the lanes that escape at a bounce see the map through
//! one batched lookup ([`PathTracer::escaped_lanes`]: the lat-long
//! mapping, the bilinear weights and blends, the MIS weights in lane
//! loops, the texel and density reads issued together), and the lanes
//! that choose the environment, Lambert and mixture alike, get its
//! samples the same way ([`PathTracer::direct_env_lanes`]: the CDF
//! searches lane by lane but batched, the directions by the polynomial
//! `sin_cos` lane-parallel; the mixture lanes' `Bsdf::eval` and `pdf` and
//! the shadow rays one lane at a time). A mixture vertex, or a lane that
//! picks another light (point, spot, directional, an area light's quad,
//! disk or sphere), gets its light sample from the scalar loop's own code
//! ([`PathTracer::direct_from`]), and a mixture or delta vertex its next
//! direction from `Bsdf::sample`, lane by lane, the lanes staying in the
//! batch. The lat-long mapping under every environment lookup is the
//! polynomial one of `chiaro_core::shading::texture::latlong_uv`, and the
//! scalar loop's lookups and samples are the one-lane case of the
//! functions the lanes call.

// A lane loop indexes a dozen arrays by the lane number: that is the
// form LLVM vectorises, and clearer than a dozen zipped iterators.
#![allow(clippy::needless_range_loop)]

use super::lanes_env::lambert_f_cos;
use super::{PathState, PathTracer};
use chiaro_core::accel::Hit;
use chiaro_core::geometry::{Frame, Ray, offset_ray_origin};
use chiaro_core::sampling::sobol::LANES;
use chiaro_core::sampling::{
    SobolSampler, cosine_hemisphere_pdf, sample_cosine_hemisphere_xyz, sample_uniform_triangle_xy,
};
use chiaro_core::shading::TriangleEmitter;
use delta::{LanePairs, delta_lanes, without};
use glam::{Vec2, Vec3};

#[path = "lanes_delta.rs"]
mod delta;
#[cfg(test)]
pub(super) use delta::KERNEL_DELTAS;

/// Live lanes at or below which a batch hands its paths to the scalar
/// loop at the next bounce (BENCHMARKS.md, "Plain spheres, dark materials
/// and a scalar tail in the path tracer": 0, 2, 4 and 8 measured).
const SCALAR_TAIL: usize = 4;

/// One `f32` per lane.
type F = [f32; LANES];

/// Lights up to which, when all are emissive triangles, the kernel gathers
/// each lane's light by a select per light over all lanes (vector blends)
/// rather than by storing the picked light's fields lane by lane (single
/// lane stores that the light sample then reads back as vectors, a
/// store-forwarding stall per field).
pub(super) const SELECT_LIGHTS: usize = 4;

/// `dst[i] = v` in the lanes where `m` is set.
#[inline(always)]
fn select<T: Copy>(dst: &mut [T; LANES], m: &[bool; LANES], v: T) {
    for i in 0..LANES {
        dst[i] = if m[i] { v } else { dst[i] };
    }
}

/// A vector per lane, as three component arrays.
#[derive(Clone, Copy, Default)]
struct V3 {
    x: F,
    y: F,
    z: F,
}

impl V3 {
    #[inline(always)]
    fn get(&self, i: usize) -> Vec3 {
        Vec3::new(self.x[i], self.y[i], self.z[i])
    }

    #[inline(always)]
    fn set(&mut self, i: usize, v: Vec3) {
        (self.x[i], self.y[i], self.z[i]) = (v.x, v.y, v.z);
    }

    /// Lane `i` as an array.
    #[inline(always)]
    fn at(&self, i: usize) -> [f32; 3] {
        [self.x[i], self.y[i], self.z[i]]
    }

    #[inline(always)]
    fn put(&mut self, i: usize, v: [f32; 3]) {
        (self.x[i], self.y[i], self.z[i]) = (v[0], v[1], v[2]);
    }

    /// `v` in the lanes where `m` is set.
    #[inline(always)]
    fn select(&mut self, m: &[bool; LANES], v: Vec3) {
        select(&mut self.x, m, v.x);
        select(&mut self.y, m, v.y);
        select(&mut self.z, m, v.z);
    }

    /// The three component arrays.
    #[inline(always)]
    fn arrays(&self) -> [F; 3] {
        [self.x, self.y, self.z]
    }

    #[inline(always)]
    fn splat(v: Vec3) -> Self {
        Self {
            x: [v.x; LANES],
            y: [v.y; LANES],
            z: [v.z; LANES],
        }
    }
}

/// The dot product as `glam::Vec3::dot` evaluates it.
#[inline(always)]
pub(super) fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    (a[0] * b[0]) + (a[1] * b[1]) + (a[2] * b[2])
}

/// `glam::Vec3::max_element`, operation for operation.
#[inline(always)]
fn max_element(v: [f32; 3]) -> f32 {
    let max = |a: f32, b: f32| if a > b { a } else { b };
    max(v[0], max(v[1], v[2]))
}

/// False when `x <= 0`; true for a NaN, as the scalar loop's early
/// returns (`if x <= 0.0 { return ... }`) let a NaN through.
#[allow(clippy::neg_cmp_op_on_partial_ord)]
#[inline(always)]
pub(super) fn passes(x: f32) -> bool {
    !(x <= 0.0)
}

/// The per-lane data of the light sample of [`PathTracer::direct`]'s
/// emissive-triangle case, gathered for the vectorised part.
#[derive(Default)]
struct LightLanes {
    a: V3,
    b: V3,
    c: V3,
    n: V3,
    le: V3,
    area: F,
    pick: F,
    two_sided: [bool; LANES],
}

impl LightLanes {
    /// `tl` (chosen with probability `pick`) in every lane.
    #[inline(always)]
    fn splat(tl: &TriangleEmitter, pick: f32) -> Self {
        Self {
            a: V3::splat(tl.a),
            b: V3::splat(tl.b),
            c: V3::splat(tl.c),
            n: V3::splat(tl.n),
            le: V3::splat(tl.le),
            area: [tl.area; LANES],
            pick: [pick; LANES],
            two_sided: [tl.two_sided; LANES],
        }
    }

    /// `tl` in the lanes where `m` is set.
    #[inline(always)]
    fn select(&mut self, m: &[bool; LANES], tl: &TriangleEmitter, pick: f32) {
        self.a.select(m, tl.a);
        self.b.select(m, tl.b);
        self.c.select(m, tl.c);
        self.n.select(m, tl.n);
        self.le.select(m, tl.le);
        select(&mut self.area, m, tl.area);
        select(&mut self.pick, m, pick);
        select(&mut self.two_sided, m, tl.two_sided);
    }

    /// `tl` in lane `i`.
    #[inline(always)]
    fn set(&mut self, i: usize, tl: &TriangleEmitter, pick: f32) {
        self.a.set(i, tl.a);
        self.b.set(i, tl.b);
        self.c.set(i, tl.c);
        self.n.set(i, tl.n);
        self.le.set(i, tl.le);
        self.area[i] = tl.area;
        self.pick[i] = pick;
        self.two_sided[i] = tl.two_sided;
    }
}

impl PathTracer<'_, '_> {
    /// Radiance of samples `first..first + count` (`count <= LANES`) of
    /// the pixel `rng` is set to, each as [`Self::radiance`] computes it
    /// from the camera ray `camera(jitter)`; and the first hit of sample
    /// `first` (distance and normal), as `radiance` reports it. `rng` is
    /// left at an unspecified sample.
    pub(super) fn radiance_lanes(
        &self,
        first: u32,
        count: usize,
        camera: &impl Fn(Vec2) -> Ray,
        rng: &mut SobolSampler,
        rays: &mut u64,
    ) -> ([Vec3; LANES], Option<(f32, Vec3)>) {
        let mut pairs = LanePairs::new(first);
        let mut out = [Vec3::ZERO; LANES];
        let mut first_hit = None;
        let mut alive: [bool; LANES] = std::array::from_fn(|i| i < count);
        // Path state, per lane.
        let (mut org, mut dir) = (V3::default(), V3::default());
        let mut beta = V3::splat(Vec3::ONE);
        let mut l = V3::default();
        let mut prev_pdf: F = [0.0; LANES];
        let mut prev_p = V3::default();
        let mut prev_n = V3::default();
        // Pairs drawn so far (the same for every live lane).
        let mut dim = 0u32;
        let jitter = pairs.lanes_2d(rng, dim);
        dim += 1;
        for i in 0..LANES {
            let ray = camera(Vec2::new(jitter[0][i], jitter[1][i]));
            org.set(i, ray.origin);
            dir.set(i, ray.dir);
            prev_p.set(i, ray.origin);
        }
        // The vertex of each lane shaded here: position, geometric normal,
        // both normals on the viewer's side, Lambert's constants.
        let mut vx = Vertices::default();
        // The material at each lane's vertex when it is not a plain one
        // (textured, vertex-coloured, mapped): resolved per hit.
        let mut surfaces: [Option<super::MaterialInfo>; LANES] = [None; LANES];
        let mut lights = LightLanes::default();
        let mut u_next = [[0.0; LANES]; 2];
        for depth in 0..self.max_depth {
            // A few lanes left: the scalar loop finishes them from their
            // state and pair (a lane loop costs the same for one lane as
            // for sixteen).
            if alive.iter().filter(|&&a| a).count() <= SCALAR_TAIL {
                for i in set_lanes(&alive) {
                    let ray = Ray::new(org.get(i), dir.get(i));
                    let path = (&beta, &l, &prev_pdf, (&prev_p, &prev_n));
                    let pair = (first, pairs.dim(i, dim));
                    let (li, fh) = self.hand_off(i, ray, None, depth, path, pair, rng, rays);
                    out[i] = li;
                    if depth == 0 && i == 0 {
                        first_hit = fh;
                    }
                }
                break;
            }
            // Trace; sort the lanes into escaped, handed to the scalar
            // loop, and shaded here (whose emission is added now).
            let mut shade = [false; LANES];
            let mut escaped = [false; LANES];
            // Each shaded lane's material: the cached one of a plain vertex,
            // or (lanes in `resolved`) its slot in `surfaces`, filled in
            // after this loop.
            let mut info = [None; LANES];
            let mut resolved = [false; LANES];
            for i in set_lanes(&alive) {
                *rays += 1;
                let ray = Ray::new(org.get(i), dir.get(i));
                // Camera rays skip the backs of single-sided materials.
                let hit = if depth == 0 {
                    self.accel.intersect_camera(&ray)
                } else {
                    self.accel.intersect(&ray)
                };
                let Some(hit) = hit else {
                    // (What it sees is looked up below, with the others'.)
                    escaped[i] = true;
                    alive[i] = false;
                    continue;
                };
                let Hit { t, prim, u, v: hv } = hit;
                let plain = self.plain_vertex(&ray, t, prim, u, hv);
                let (v, m) = match plain {
                    Some(vm) => vm,
                    None => {
                        let (v, m) = self.surface_vertex(&ray, &Hit { t, prim, u, v: hv });
                        (v, &*surfaces[i].insert(m))
                    }
                };
                // (A one-sided surface's front is shaded here, as the scalar
                // loop's `seen_from` decides: the same `cos_o`.)
                let front = m.front_lock_step && v.ng.dot(-ray.dir) >= 0.0;
                #[cfg(test)]
                FRONTS_SHADED.set(FRONTS_SHADED.get() + u64::from(front));
                if !(m.lock_step || front) {
                    #[cfg(test)]
                    HANDED_OFF.set(HANDED_OFF.get() + 1);
                    // The scalar loop from this vertex, at this pair.
                    let path = (&beta, &l, &prev_pdf, (&prev_p, &prev_n));
                    let pair = (first, pairs.dim(i, dim));
                    let (li, fh) = self.hand_off(i, ray, Some(hit), depth, path, pair, rng, rays);
                    out[i] = li;
                    if depth == 0 && i == 0 {
                        first_hit = fh;
                    }
                    alive[i] = false;
                    continue;
                }
                if depth == 0 && i == 0 {
                    first_hit = Some((t * ray.dir.length(), v.ns));
                }
                if m.emissive {
                    let wo = -ray.dir;
                    if m.emission_two_sided || v.ng.dot(wo) > 0.0 {
                        let w = if prev_pdf[i] == 0.0 {
                            1.0
                        } else {
                            let from = (prev_p.get(i), prev_n.get(i));
                            self.emitter_mis_weight(prim, from, &v, wo, prev_pdf[i])
                        };
                        l.set(i, l.get(i) + beta.get(i) * m.bsdf.m.emission * w);
                    }
                }
                vx.p.set(i, v.p);
                vx.ng.set(i, v.ng);
                vx.n.set(i, v.ns);
                vx.kd.set(i, m.bsdf.m.kd);
                vx.glossy[i] = !m.lambert;
                info[i] = plain.map(|(_, m)| m);
                resolved[i] = plain.is_none();
                shade[i] = true;
            }
            for i in set_lanes(&resolved) {
                info[i] = surfaces[i].as_ref();
            }
            if escaped.iter().any(|&e| e) {
                let seen =
                    self.escaped_lanes(&escaped, &org.arrays(), &dir.arrays(), depth, &prev_pdf);
                for i in set_lanes(&escaped) {
                    let c = Vec3::new(seen[0][i], seen[1][i], seen[2][i]);
                    out[i] = l.get(i) + beta.get(i) * c;
                }
            }
            if !shade.iter().any(|&s| s) {
                break;
            }
            // The light choice's and the light sample's pairs first:
            // independent work while the hit loop's single-lane stores
            // drain before the lane loop below reads them as vectors.
            let u_pick = if self.light_count() > 1 {
                pairs.lanes_1d(rng, dim)
            } else {
                [0.0; LANES]
            };
            let u_light = pairs.lanes_2d(rng, dim + 1);
            // Both normals onto the viewer's side, lane-parallel (lanes not
            // shaded compute on stale values, masked off later).
            for i in 0..LANES {
                let (ng, d) = (vx.ng.at(i), dir.at(i));
                let cos_o = dot(ng, d.map(|x| -x));
                let side = if cos_o >= 0.0 { 1.0 } else { -1.0 };
                vx.n.put(i, vx.n.at(i).map(|x| x * side));
                vx.ngs.put(i, ng.map(|x| x * side));
            }
            let last = depth + 1 >= self.max_depth;
            // (Delta vertices: next-event estimation finds nothing there.)
            let delta = delta_lanes(&info, &shade);
            self.direct_lanes(
                &vx,
                &info,
                &without(&shade, &delta),
                &dir,
                !last,
                &mut lights,
                &mut l,
                &beta,
                &pairs,
                rng,
                rays,
                (u_pick, u_light),
                (!last).then_some((dim + 3, &mut u_next)),
            );
            dim += 2;
            if last {
                for i in set_lanes(&shade) {
                    out[i] = l.get(i);
                }
                break;
            }
            // Continue the path. Mixture lanes sample their BSDF through
            // `Bsdf::sample`, lane by lane, with the lobe choice's number
            // (pair `dim`, drawn when some lane needs it) and the
            // direction's pair; Lambert lanes draw Lambert's lobe alone
            // (its choice's pair skipped), cosine-distributed, in
            // `Frame::from_normal(n)`, lane-parallel. (Pair `dim + 1`,
            // drawn inside `direct_lanes`.)
            let u = u_next;
            // Delta lanes (glossy too: not Lambert) sample theirs through
            // `sample_deltas`.
            let glossy: [bool; LANES] = std::array::from_fn(|i| shade[i] & vx.glossy[i]);
            let mixed = without(&glossy, &delta);
            let mut g = self.sample_mixtures(&vx, &info, &mixed, &dir, u, dim, &pairs, rng);
            self.sample_deltas(&mut g, &vx, &info, &delta, &dir, u, dim, &mut pairs, rng);
            dim += 2;
            let mut q: F = [0.0; LANES];
            let mut ended = [false; LANES];
            for i in 0..LANES {
                let n = vx.n.at(i);
                let local = Vec3::from_array(sample_cosine_hemisphere_xyz(u[0][i], u[1][i]));
                let wi = Frame::from_normal(Vec3::from_array(n))
                    .to_world(local)
                    .to_array();
                let cos_i = dot(n, wi);
                let ok = passes(cos_i) & passes(dot(vx.ngs.at(i), wi));
                // The mixture lanes' sample in their place (selects).
                let gi = glossy[i];
                let wi = if gi { g.wi.at(i) } else { wi };
                let ok = if gi { g.ok[i] } else { ok };
                // (`Lobes::lambert_weight` is kd for Lambert's materials.)
                let (bt, w) = (beta.at(i), if gi { g.weight.at(i) } else { vx.kd.at(i) });
                let b: [f32; 3] = std::array::from_fn(|k| bt[k] * w[k]);
                let live =
                    shade[i] && ok && b.iter().all(|c| c.is_finite()) && passes(max_element(b));
                ended[i] = shade[i] && !live;
                shade[i] = live;
                beta.put(i, b);
                // (Lambert's `p_diffuse` is 1: the pdf is the cosine's.)
                prev_pdf[i] = if gi {
                    g.pdf[i]
                } else {
                    cosine_hemisphere_pdf(cos_i)
                };
                let p = vx.p.get(i);
                prev_p.set(i, p);
                prev_n.set(i, vx.ngs.get(i));
                org.set(i, offset_ray_origin(p, vx.ng.get(i), Vec3::from_array(wi)));
                dir.put(i, wi);
                q[i] = max_element(b).min(0.95);
            }
            for i in set_lanes(&ended) {
                out[i] = l.get(i);
            }
            // Russian roulette.
            if depth + 1 >= self.rr_depth {
                let r = pairs.lanes_1d(rng, dim);
                dim += 1;
                let stop: [bool; LANES] = std::array::from_fn(|i| shade[i] & (r[i] >= q[i]));
                for i in set_lanes(&stop) {
                    out[i] = l.get(i);
                    shade[i] = false;
                }
                for i in 0..LANES {
                    let bt = beta.at(i);
                    beta.put(i, bt.map(|c| c / q[i]));
                }
            }
            pairs.retire(&shade);
            alive = shade;
        }
        (out, first_hit)
    }

    /// Lane `i`'s path finished by the scalar loop: from segment `depth`
    /// with ray `ray` (already traced when `traced` is its hit), the lane's
    /// throughput, radiance, MIS pdf and previous vertex in `path`, at pair
    /// `dim` of sample `first + i`. Its radiance, and its first hit when
    /// `depth` is 0.
    #[allow(clippy::too_many_arguments)]
    fn hand_off(
        &self,
        i: usize,
        ray: Ray,
        traced: Option<Hit>,
        depth: u32,
        (beta, l, prev_pdf, (prev_p, prev_n)): (&V3, &V3, &F, (&V3, &V3)),
        (first, dim): (u32, u32),
        rng: &mut SobolSampler,
        rays: &mut u64,
    ) -> (Vec3, Option<(f32, Vec3)>) {
        let state = PathState {
            ray,
            depth,
            beta: beta.get(i),
            l: l.get(i),
            prev_pdf: prev_pdf[i],
            prev_p: prev_p.get(i),
            prev_n: prev_n.get(i),
        };
        rng.set_sample(first + i as u32);
        rng.skip(dim);
        self.radiance_from(state, traced, rng, rays)
    }

    /// [`PathTracer::pick_light`] of each lane's `u` at its vertex
    /// (`None` without lights): the lights and their probabilities, light
    /// [`NO_PICK`] where the hierarchy finds none for the lane. By power,
    /// for a few lights the count of CDF entries at or below `u`,
    /// lane-parallel and without branches (the same index: the CDF is
    /// sorted, so the entries at or below `u` are the prefix that
    /// `partition_point` finds); for many, the binary search per lane. By
    /// the hierarchy, its walk per lane in `shade`, at the point and
    /// geometric normal the scalar loop gives it.
    #[inline(always)]
    pub(super) fn pick_lights(
        &self,
        u: &F,
        vx: &Vertices,
        shade: &[bool; LANES],
    ) -> Option<([u32; LANES], F)> {
        /// Lights up to which counting beats the search.
        const FEW: usize = 16;
        let n = self.light_count();
        if n == 0 {
            return None;
        }
        let Some(table) = self.light_sampler.power_table() else {
            let mut picked = [NO_PICK; LANES];
            let mut pmf = [0.0; LANES];
            for i in set_lanes(shade) {
                if let Some((li, pk)) = self.pick_light(vx.p.get(i), vx.ngs.get(i), u[i]) {
                    (picked[i], pmf[i]) = (li as u32, pk);
                }
            }
            return Some((picked, pmf));
        };
        let picked = if n > FEW {
            u.map(|u| table.pick(u).unwrap_or(0) as u32)
        } else {
            let mut count = [0u32; LANES];
            for &c in table.cdf().iter() {
                for i in 0..LANES {
                    count[i] += (c <= u[i]) as u32;
                }
            }
            count.map(|k| k.min(n as u32 - 1))
        };
        Some((picked, picked.map(|li| table.pmf(li as usize))))
    }

    /// [`PathTracer::direct`] for the lanes in `shade`, its contribution
    /// `beta * L` added to `l`: emissive-triangle lights lane-parallel, the
    /// others through [`PathTracer::direct_from`]. `u_pick` and `u` are
    /// the numbers of the light choice (pair `dim`, not drawn for one
    /// light) and of the light sample (pair `dim + 1`); `next`, when set,
    /// is a pair to draw into its array between the light gather and the
    /// light sample (the path's next direction's, whose drawing hides the
    /// gather's store latency).
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn direct_lanes(
        &self,
        vx: &Vertices,
        info: &[Option<&super::MaterialInfo>; LANES],
        shade: &[bool; LANES],
        dir: &V3,
        mis: bool,
        lt: &mut LightLanes,
        l: &mut V3,
        beta: &V3,
        pairs: &LanePairs,
        rng: &mut SobolSampler,
        rays: &mut u64,
        (u_pick, u): (F, [[f32; LANES]; 2]),
        next: Option<(u32, &mut [[f32; LANES]; 2])>,
    ) {
        // Gather the chosen lights (lanes not gathered keep stale values,
        // computed on and then masked off).
        let mut ok = [false; LANES];
        let picked = self.pick_lights(&u_pick, vx, shade);
        if let Some((p, _)) = picked.filter(|_| !self.select_lights.is_empty()) {
            // Every light an emissive triangle: light 0 everywhere, then
            // each other light selected into the lanes that picked it (by
            // power: the probability is the light's). Mixture lanes are
            // sampled below.
            ok = std::array::from_fn(|i| shade[i] & !vx.glossy[i]);
            let pick = |j: usize| self.light_pick_pdf(Vec3::ZERO, Vec3::ZERO, j);
            let (first, rest) = self.select_lights.split_first().expect("lights");
            *lt = LightLanes::splat(first, pick(0));
            for (j, tl) in rest.iter().enumerate().map(|(j, tl)| (j + 1, tl)) {
                let m: [bool; LANES] = std::array::from_fn(|i| p[i] == j as u32);
                lt.select(&m, tl, pick(j));
            }
        } else {
            let flat: [bool; LANES] = std::array::from_fn(|i| shade[i] & !vx.glossy[i]);
            for i in set_lanes(&flat) {
                let Some((li, pk)) = picked.map(|(p, pmf)| (p[i] as usize, pmf[i])) else {
                    break;
                };
                if li == NO_PICK as usize {
                    continue;
                }
                let Some(tl) = &self.tri_lights[li] else {
                    // Not an emissive triangle: the scalar loop's code (the
                    // environment's lanes together, below).
                    if let Some(m) = info[i].filter(|_| li != self.lights.len()) {
                        let (n, ng, wo) = (vx.n.get(i), vx.ngs.get(i), -dir.get(i));
                        let u = Vec2::new(u[0][i], u[1][i]);
                        let c = self.direct_from((li, pk), vx.p.get(i), m, n, ng, wo, mis, u, rays);
                        l.set(i, l.get(i) + beta.get(i) * c);
                    }
                    continue;
                };
                ok[i] = true;
                lt.set(i, tl, pk);
            }
        }
        // Mixture lanes: the scalar loop's code, lane by lane (their BSDF
        // is not Lambert's, whose terms the loops below spell out).
        if let Some((p, pmf)) = &picked {
            let glossy: [bool; LANES] = std::array::from_fn(|i| shade[i] & vx.glossy[i]);
            for i in set_lanes(&glossy) {
                if p[i] == NO_PICK || p[i] as usize == self.lights.len() {
                    continue;
                }
                if let Some(m) = info[i] {
                    let (n, ng, wo) = (vx.n.get(i), vx.ngs.get(i), -dir.get(i));
                    let u = Vec2::new(u[0][i], u[1][i]);
                    let pk = (p[i] as usize, pmf[i]);
                    let c = self.direct_from(pk, vx.p.get(i), m, n, ng, wo, mis, u, rays);
                    l.set(i, l.get(i) + beta.get(i) * c);
                }
            }
        }
        // Lanes that chose the environment: its sample, lane-parallel.
        if let Some((p, pmf)) = picked.as_ref().filter(|_| self.env.is_some()) {
            let env: [bool; LANES] =
                std::array::from_fn(|i| shade[i] & (p[i] as usize == self.lights.len()));
            if env.iter().any(|&e| e) {
                let at = super::lanes_env::EnvVertices {
                    p: &vx.p.arrays(),
                    n: &vx.n.arrays(),
                    ngs: &vx.ngs.arrays(),
                    dir: &dir.arrays(),
                    kd: &vx.kd.arrays(),
                    glossy: &vx.glossy,
                };
                let c = self.direct_env_lanes(&env, pmf, &at, info, mis, &u, rays);
                for i in set_lanes(&env) {
                    let c = Vec3::new(c[0][i], c[1][i], c[2][i]);
                    l.set(i, l.get(i) + beta.get(i) * c);
                }
            }
        }
        // The path's next pair, drawn here: independent work while the
        // gather's stores drain (the lane loop below reads them as whole
        // vectors, which cannot be forwarded from single-lane stores).
        if let Some((d, u_next)) = next {
            *u_next = pairs.lanes_2d(rng, d);
        }
        if picked.is_none() || !ok.iter().any(|&o| o) {
            // No lights, or no lane left to sample one lane-parallel (all
            // delta, glossy or lit by other lights): nothing more (the pair
            // above is still drawn).
            return;
        }
        // The light sample (`TriangleEmitter::sample`), the Lambert term
        // (`eval_brdf_cos`) and the MIS weight, lane-parallel.
        let mut o_l = V3::default();
        let mut d_l = V3::default();
        let mut f_l = V3::default();
        let mut light_pdf: F = [0.0; LANES];
        let mut cos_i: F = [0.0; LANES];
        for i in 0..LANES {
            let [bx, by] = sample_uniform_triangle_xy(u[0][i], u[1][i]);
            let (a, b, c) = (lt.a.at(i), lt.b.at(i), lt.c.at(i));
            let q: [f32; 3] =
                std::array::from_fn(|k| a[k] * bx + b[k] * by + c[k] * (1.0 - bx - by));
            let p = vx.p.at(i);
            let d: [f32; 3] = std::array::from_fn(|k| q[k] - p[k]);
            let dist2 = dot(d, d);
            let s = 1.0 / dist2.sqrt();
            let wi = d.map(|x| x * s);
            let cl = -dot(lt.n.at(i), wi);
            let cos_l = if lt.two_sided[i] { cl.abs() } else { cl };
            light_pdf[i] = dist2 / (cos_l * lt.area[i]) * lt.pick[i];
            let c_i = dot(vx.n.at(i), wi);
            cos_i[i] = c_i;
            // `eval_brdf_cos` for these materials (no specular lobe).
            let f_cos = lambert_f_cos(vx.kd.at(i), c_i);
            // (`&` rather than `&&`: no branches in the lane loop.)
            ok[i] = ok[i]
                & (lt.pick[i] > 0.0)
                & passes(dist2)
                & passes(cos_l)
                & passes(dot(vx.ngs.at(i), wi))
                & passes(c_i)
                & ((f_cos[0] != 0.0) | (f_cos[1] != 0.0) | (f_cos[2] != 0.0));
            let le = lt.le.at(i);
            // The shadow ray's origin, off the surface towards the light.
            let o = offset_ray_origin(Vec3::from_array(p), vx.ngs.get(i), Vec3::from_array(wi));
            o_l.set(i, o);
            d_l.set(i, Vec3::from_array(q) - o);
            f_l.put(i, std::array::from_fn(|k| f_cos[k] * le[k]));
        }
        // The power heuristic's weight over the light's pdf (as `direct`).
        let w_l: F = if mis {
            std::array::from_fn(|i| {
                let (lp, bsdf_pdf) = (light_pdf[i], cosine_hemisphere_pdf(cos_i[i]));
                lp / (lp * lp + bsdf_pdf * bsdf_pdf)
            })
        } else {
            light_pdf.map(|lp| 1.0 / lp)
        };
        // Shadow rays, one at a time.
        // (A bit mask, not a `[bool; LANES]`: the lane loop below would read
        // several one-byte stores as one wider load, which cannot be
        // forwarded.)
        let mut lit = 0u32;
        for i in set_lanes(&ok) {
            *rays += 1;
            // `Ray::segment(o, q)`, its `q - o` computed above.
            let o = o_l.get(i);
            let shadow = Ray {
                dir: d_l.get(i),
                ..Ray::segment(o, o)
            };
            lit |= u32::from(!self.accel.occluded(&shadow)) << i;
        }
        // The unoccluded lanes' `beta * f * w`, lane-parallel.
        for i in 0..LANES {
            let (li, bt, f) = (l.at(i), beta.at(i), f_l.at(i));
            let sum: [f32; 3] = std::array::from_fn(|k| li[k] + bt[k] * (f[k] * w_l[i]));
            l.put(i, if lit >> i & 1 == 1 { sum } else { li });
        }
    }
}

/// The mixture lanes' BSDF samples ([`PathTracer::sample_mixtures`]).
#[derive(Default)]
struct MixtureSamples {
    /// Direction, `f cos / pdf`, and the MIS pdf (0 for a delta lobe).
    wi: V3,
    weight: V3,
    pdf: F,
    /// False where the sample was lost (`Bsdf::sample` gave `None`).
    ok: [bool; LANES],
}

impl PathTracer<'_, '_> {
    /// The next direction of each lane in `glossy` (vertices of a
    /// Lambert-and-glossy mixture), as the scalar loop's `sample_bsdf`
    /// draws it: the lobe choice's number from pair `dim` (drawn only when
    /// some lane needs one), the direction's pair `u`, through
    /// [`chiaro_core::shading::Bsdf::sample`] at the lane's viewer-side
    /// normals.
    #[allow(clippy::too_many_arguments)]
    #[inline(never)]
    fn sample_mixtures(
        &self,
        vx: &Vertices,
        info: &[Option<&super::MaterialInfo>; LANES],
        glossy: &[bool; LANES],
        dir: &V3,
        u: [[f32; LANES]; 2],
        dim: u32,
        pairs: &LanePairs,
        rng: &mut SobolSampler,
    ) -> MixtureSamples {
        let mut g = MixtureSamples::default();
        let needs = set_lanes(glossy).any(|i| info[i].is_some_and(|m| m.bsdf.needs_lobe_number()));
        let u_lobe = if needs {
            pairs.lanes_1d(rng, dim)
        } else {
            [0.0; LANES]
        };
        for i in set_lanes(glossy) {
            let Some(m) = info[i] else { continue };
            // (The Fresnel choice is never asked for: delta lanes are not
            // in `glossy`, see `lock_step`.)
            g.sample_lane(i, &m.bsdf, (vx, dir), (&u_lobe, &u), || 0.0);
        }
        g
    }
}

impl MixtureSamples {
    /// Lane `i`'s next direction through `bsdf`, as the scalar loop's
    /// `sample_bsdf` draws it: at the lane's viewer-side normals, with the
    /// lobe choice's number `u_lobe[i]` (where the BSDF reads one), the
    /// direction's pair `u` and `u_fresnel` for a Fresnel choice; stored
    /// in the lane's slots (left unset where the BSDF gives no sample).
    #[inline(always)]
    fn sample_lane(
        &mut self,
        i: usize,
        bsdf: &chiaro_core::shading::Bsdf,
        (vx, dir): (&Vertices, &V3),
        (u_lobe, u): (&F, &[F; 2]),
        u_fresnel: impl FnOnce() -> f32,
    ) {
        let (n, ng, wo) = (vx.n.get(i), vx.ngs.get(i), -dir.get(i));
        // (The scalar loop's `front`: the unflipped normal's side.)
        let front = vx.ng.get(i).dot(wo) >= 0.0;
        let ul = if bsdf.needs_lobe_number() {
            u_lobe[i]
        } else {
            0.0
        };
        let uv = Vec2::new(u[0][i], u[1][i]);
        let s = if bsdf.scatters() {
            bsdf.sample(n, ng, wo, front, ul, uv, u_fresnel)
        } else {
            None
        };
        if let Some(s) = s {
            self.wi.set(i, s.wi);
            self.weight.set(i, s.weight);
            self.pdf[i] = super::integrator::mis_pdf(&s, ng);
            self.ok[i] = true;
        }
    }
}

/// The lanes set in `m`, in order, read from their bit mask: the loop
/// visits only those lanes, so its branches do not depend on which lanes
/// are set (a test per lane of a random mask would mispredict often).
#[inline(always)]
pub(super) fn set_lanes(m: &[bool; LANES]) -> impl Iterator<Item = usize> + use<> {
    // Each eight bytes (each 0 or 1) as one word; the multiply gathers
    // byte `i`'s bit into bit `56 + i` (no two partial products overlap
    // or carry): a load, a multiply and a shift per eight lanes.
    const _: () = assert!(LANES.is_multiple_of(8) && LANES <= 32);
    let mut bits = 0u32;
    for (k, eight) in m.chunks_exact(8).enumerate() {
        let bytes = u64::from_le_bytes(std::array::from_fn(|j| u8::from(eight[j])));
        bits |= ((bytes.wrapping_mul(0x0102_0408_1020_4080) >> 56) as u32) << (8 * k);
    }
    std::iter::from_fn(move || {
        (bits != 0).then(|| {
            let i = bits.trailing_zeros() as usize;
            bits &= bits - 1;
            i
        })
    })
}

/// [`PathTracer::pick_lights`]'s light of a lane given none.
const NO_PICK: u32 = u32::MAX;

/// The lanes' current vertices, as [`PathTracer::radiance_lanes`] shades
/// them.
#[derive(Default)]
pub(super) struct Vertices {
    p: V3,
    /// Geometric normal (front side).
    ng: V3,
    /// Shading and geometric normal on the viewer's side (`n` holds the
    /// shading normal as interpolated until the sides are chosen).
    n: V3,
    ngs: V3,
    kd: V3,
    /// The material is a Lambert-and-glossy mixture (`lock_step` but not
    /// `lambert`): shaded through the BSDF's own functions.
    glossy: [bool; LANES],
}

#[cfg(test)]
thread_local! {
    /// Lanes this thread's kernel handed to the scalar loop at a vertex it
    /// does not shade: what the tests read to see which vertices stay in
    /// lock-step.
    pub(super) static HANDED_OFF: std::cell::Cell<u64> = const { std::cell::Cell::new(0) };
    /// Lanes this thread's kernel shaded at the front of a one-sided
    /// surface (`MaterialInfo::front_lock_step`).
    pub(super) static FRONTS_SHADED: std::cell::Cell<u64> = const { std::cell::Cell::new(0) };
}

#[cfg(test)]
impl Vertices {
    /// Vertices at `p` with viewer-side geometric normals `ngs`.
    pub(super) fn at(p: [Vec3; LANES], ngs: [Vec3; LANES]) -> Self {
        let mut v = Self::default();
        for i in 0..LANES {
            v.p.set(i, p[i]);
            v.ngs.set(i, ngs[i]);
        }
        v
    }
}
