//! The environment map as a radiosity source: a distant emitter that each
//! element gathers with visibility before a solver runs, so its light then
//! interreflects like any other emission (the "first unshot gather" of
//! `direct.rs`, for the map).
//!
//! The reflected radiance of element `e` is `rho / pi * E_env`, with
//! `E_env = int L_env(w) V(w) cos_theta dw` over the front hemisphere,
//! estimated by multiple importance sampling (Veach 1997, section 9.2,
//! balance heuristic with equal counts) of two stratified strategies: the
//! cosine-weighted hemisphere and the map's own density
//! ([`EnvironmentLight::sample`], the path tracer's). Each ray starts from
//! one of four points spread over the element and is tested against the
//! scene's BVH. Every element draws from its own generator, seeded by its
//! index, so a solution is reproducible bit for bit whatever the threads.

use crate::formfactor::sub_centroids;
use crate::mesh::{Element, ElementMesh, barycentric, element_at};
use crate::ray_cast::Visibility;
use chiaro_core::geometry::{Frame, Ray};
use chiaro_core::sampling::{cosine_hemisphere_pdf, pixel_rng, sample_cosine_hemisphere, uniform2};
use chiaro_core::scene::Scene;
use chiaro_core::shading::texture::{EnvironmentLight, environment_radiance};
use glam::{Vec2, Vec3};
use std::f32::consts::FRAC_1_PI;

/// Visibility rays the whole gather may cast, counted from the number of
/// receiving elements (so the result never depends on timing).
const RAY_BUDGET: usize = 6_000_000;
/// Strata per axis and per strategy: `m x m` directions of each.
const MIN_STRATA: u32 = 1;
const MAX_STRATA: u32 = 6;
/// The gather's seed, fixed: the solution does not change with the
/// render's seed, so a kept solution stays valid.
const SEED: u64 = 0x0E4F_1A5E_ED00_0001;

/// The scene's environment map as a source of light for the elements.
pub(crate) struct EnvironmentSource<'s> {
    scene: &'s Scene,
    light: EnvironmentLight<'s>,
    strata: u32,
}

impl<'s> EnvironmentSource<'s> {
    /// The environment of `scene` as a source for `receivers` elements;
    /// `None` when the scene has no environment map that gives light
    /// ([`EnvironmentLight::new`]).
    pub(crate) fn new(scene: &'s Scene, receivers: usize) -> Option<Self> {
        let light = EnvironmentLight::new(scene)?;
        let per_strategy = RAY_BUDGET / receivers.max(1) / 2;
        let strata = ((per_strategy as f32).sqrt() as u32).clamp(MIN_STRATA, MAX_STRATA);
        Some(Self {
            scene,
            light,
            strata,
        })
    }

    /// Directions per strategy and element (`m x m`).
    pub(crate) fn directions(&self) -> u32 {
        self.strata * self.strata
    }

    /// The radiance element `e` reflects from the environment (W sr^-1
    /// m^-2): `rho / pi` times the irradiance `int L_env V cos dw` over its
    /// front hemisphere, with `key` seeding its generator. Zero for an
    /// element that reflects nothing.
    pub(crate) fn reflected(&self, e: &Element, key: u64, vis: &Visibility<'_>) -> Vec3 {
        if e.rho == Vec3::ZERO {
            return Vec3::ZERO;
        }
        let frame = Frame::from_normal(e.n);
        let mut xs = [Vec3::ZERO; 64];
        let nx = sub_centroids(&e.p, 2, &mut xs);
        let mut rng = pixel_rng(SEED, key as u32, (key >> 32) as u32, 0);
        let m = self.strata;
        let mut sum = Vec3::ZERO;
        // One direction of each strategy per stratum; the balance
        // heuristic with equal counts weights every sample by
        // `1 / (pdf_cos + pdf_env)`, whichever strategy drew it.
        for k in 0..m * m {
            let cell = Vec2::new((k % m) as f32, (k / m) as f32);
            let x = xs[k as usize % nx];
            let wi = frame.to_world(sample_cosine_hemisphere(
                (cell + uniform2(&mut rng)) / m as f32,
            ));
            sum += self.term(e, x, wi, environment_radiance(self.scene, wi), vis);
            if let Some(s) = self.light.sample((cell + uniform2(&mut rng)) / m as f32) {
                sum += self.term(e, x, s.wi, s.radiance, vis);
            }
        }
        e.rho * sum * (FRAC_1_PI / (m * m) as f32)
    }

    /// One sample's `L cos V / (pdf_cos + pdf_env)` at point `x` of `e`
    /// towards unit direction `wi` of radiance `l`.
    fn term(&self, e: &Element, x: Vec3, wi: Vec3, l: Vec3, vis: &Visibility<'_>) -> Vec3 {
        let cos = wi.dot(e.n);
        if cos <= 0.0 || l == Vec3::ZERO {
            return Vec3::ZERO;
        }
        // cos > 0 here, so the sum is positive unless it is NaN.
        let pdf = cosine_hemisphere_pdf(cos) + self.light.pdf(wi);
        if pdf.is_nan() || pdf <= 0.0 || vis.accel.occluded(&Ray::new(x + e.n * vis.eps, wi)) {
            return Vec3::ZERO;
        }
        l * (cos / pdf)
    }
}

/// The mean of `values` (one per element of `mesh`) over the elements
/// that lie in the sub-triangle `p` of source triangle `source`, `depth`
/// midpoint subdivisions below it (the hierarchical solver's quadtree
/// node): the elements' centres are the node's `m x m` sub-centroids,
/// `m = k / 2^depth`, each found by [`element_at`].
pub(crate) fn node_mean(
    mesh: &ElementMesh,
    values: &[Vec3],
    source: u32,
    p: &[Vec3; 3],
    depth: u32,
) -> Vec3 {
    let s = source as usize;
    let (k, first) = (mesh.k[s], mesh.first[s] as usize);
    let m = (k >> depth.min(31)).max(1);
    let [c0, c1, c2] = p.map(|q| {
        let (u, v) = barycentric(&mesh.sources[s].p, q);
        Vec2::new(u, v)
    });
    let (e1, e2, mf) = (c1 - c0, c2 - c0, m as f32);
    let (mut sum, mut n) = (Vec3::ZERO, 0u32);
    let mut add = |a: f32, b: f32| {
        let uv = c0 + e1 * (a / mf) + e2 * (b / mf);
        if let Some(v) = values.get(first + element_at(k, uv.x, uv.y) as usize) {
            sum += *v;
            n += 1;
        }
    };
    for j in 0..m {
        for i in 0..m - j {
            add(i as f32 + 1.0 / 3.0, j as f32 + 1.0 / 3.0);
            if i + j + 1 < m {
                add(i as f32 + 2.0 / 3.0, j as f32 + 2.0 / 3.0);
            }
        }
    }
    if n > 0 { sum / n as f32 } else { Vec3::ZERO }
}
