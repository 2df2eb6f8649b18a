//! The light layer: each light's power, and the emissive triangles of a
//! scene as one light group chosen by power (an alias table), so that a
//! shading point takes a bounded number of samples from an emissive mesh of
//! any size.

use super::bsdf::luminance;
use super::light_tree::{AUTO_TREE_LIGHTS, LightBounds, LightTree};
use crate::scene::{Light, LightSelection, RenderSettings};
use std::f32::consts::PI;
use std::ops::Range;

/// An emitter group is sampled per triangle (every triangle its own area
/// light, as before grouping) while its triangle count times the samples per
/// area light is at most this: small emitters (a Cornell box's two-triangle
/// light) keep their stratified per-triangle images.
pub const PER_TRIANGLE_BOUND: u32 = 64;

/// The luminance of the power `light` emits (a spot light's counted as a
/// point light's), for choosing lights in proportion to it: an area light
/// `pi Le A` per side; a point light `4 pi` times its radiant intensity
/// `pi Ip` (it gives irradiance `pi Ip cos / d^2`); a directional light its
/// irradiance `pi Ip` over a disk of radius `scene_radius`. Never negative.
pub fn light_power(light: &Light, scene_radius: f32) -> f32 {
    let p = luminance(light.power_rgb()).max(0.0);
    match light {
        Light::Area {
            shape, two_sided, ..
        } => p * shape.area() * PI * if *two_sided { 2.0 } else { 1.0 },
        Light::Directional { .. } => p * PI * PI * scene_radius * scene_radius,
        _ => p * 4.0 * PI * PI,
    }
}

/// What an environment map of mean luminance `mean_luminance` delivers into
/// a sphere of radius `scene_radius` (pbrt-v4's `ImageInfiniteLight::Phi`):
/// `4 pi^2 r^2` times the mean radiance, comparable with [`light_power`].
pub fn environment_power(scene_radius: f32, mean_luminance: f32) -> f32 {
    4.0 * PI * PI * scene_radius * scene_radius * mean_luminance
}

/// Lights chosen in proportion to their power: the cumulative table that
/// one uniform number is searched in, and each light's probability.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct LightPowerTable {
    /// Cumulative selection probabilities (the last is 1 up to rounding).
    cdf: Vec<f32>,
    /// Selection probability of each light (`cdf[i] - cdf[i - 1]`).
    pmf: Vec<f32>,
}

impl LightPowerTable {
    /// The table over `powers`, one per light; all lights equally likely
    /// when the powers sum to zero.
    pub fn new(powers: &[f32]) -> Self {
        let n = powers.len();
        let total: f32 = powers.iter().sum();
        let mut acc = 0.0;
        let cdf: Vec<f32> = powers
            .iter()
            .map(|&p| {
                acc += if total > 0.0 {
                    p / total
                } else {
                    1.0 / n as f32
                };
                acc
            })
            .collect();
        let pmf = (0..cdf.len())
            .map(|i| {
                let prev = if i == 0 { 0.0 } else { cdf[i - 1] };
                cdf[i] - prev
            })
            .collect();
        Self { cdf, pmf }
    }

    /// The table over `lights` by [`light_power`], followed (as light
    /// `lights.len()`) by an environment map of mean luminance `env`
    /// when there is one, by [`environment_power`].
    pub fn of_lights(lights: &[&Light], scene_radius: f32, env: Option<f32>) -> Self {
        let mut powers: Vec<f32> = lights
            .iter()
            .map(|l| light_power(l, scene_radius))
            .collect();
        if let Some(mean) = env {
            powers.push(environment_power(scene_radius, mean));
        }
        Self::new(&powers)
    }

    /// The light for the uniform number `u` (the first whose cumulative
    /// probability exceeds `u`, the last when rounding leaves none);
    /// `None` without lights.
    #[inline]
    pub fn pick(&self, u: f32) -> Option<usize> {
        if self.cdf.is_empty() {
            return None;
        }
        let i = self.cdf.partition_point(|&c| c <= u);
        Some(i.min(self.cdf.len() - 1))
    }

    /// The probability of choosing light `i` (0 out of range).
    #[inline]
    pub fn pmf(&self, i: usize) -> f32 {
        self.pmf.get(i).copied().unwrap_or(0.0)
    }

    /// The cumulative probabilities, for a caller that counts entries at
    /// or below `u` instead of searching ([`Self::pick`]'s index).
    #[inline]
    pub fn cdf(&self) -> &[f32] {
        &self.cdf
    }

    /// The number of lights.
    #[inline]
    pub fn len(&self) -> usize {
        self.cdf.len()
    }

    /// True without lights.
    #[inline]
    pub fn is_empty(&self) -> bool {
        self.cdf.is_empty()
    }
}

/// Walker's alias table (built by Vose's method): picks index `i` with
/// probability `w_i / sum(w)` from one uniform number in O(1).
#[derive(Debug, Clone, PartialEq)]
pub struct AliasTable {
    /// Probability of keeping bucket `i` rather than taking its alias.
    keep: Vec<f32>,
    alias: Vec<u32>,
    /// The pick probability of each index.
    pmf: Vec<f32>,
}

impl AliasTable {
    /// The table for `weights` (negative and non-finite weights count as
    /// zero); `None` when no weight is positive.
    pub fn new(weights: &[f32]) -> Option<Self> {
        let clean = |w: f32| if w.is_finite() && w > 0.0 { w } else { 0.0 };
        let total: f64 = weights.iter().map(|&w| f64::from(clean(w))).sum();
        if total <= 0.0 || !total.is_finite() {
            return None;
        }
        let n = weights.len();
        let pmf: Vec<f32> = weights
            .iter()
            .map(|&w| (f64::from(clean(w)) / total) as f32)
            .collect();
        let mut scaled: Vec<f64> = weights
            .iter()
            .map(|&w| f64::from(clean(w)) / total * n as f64)
            .collect();
        let mut keep = vec![1.0f32; n];
        let mut alias: Vec<u32> = (0..n as u32).collect();
        let (mut small, mut large): (Vec<usize>, Vec<usize>) =
            (0..n).partition(|&i| scaled[i] < 1.0);
        while let (Some(s), Some(&l)) = (small.pop(), large.last()) {
            keep[s] = scaled[s] as f32;
            alias[s] = l as u32;
            scaled[l] -= 1.0 - scaled[s];
            if scaled[l] < 1.0 {
                large.pop();
                small.push(l);
            }
        }
        // What is left (rounding) keeps its own bucket: keep = 1.
        Some(Self { keep, alias, pmf })
    }

    /// Number of entries.
    pub fn len(&self) -> usize {
        self.pmf.len()
    }

    /// True when the table has no entries (never, for a built table).
    pub fn is_empty(&self) -> bool {
        self.pmf.is_empty()
    }

    /// Probability of picking `i`.
    #[inline]
    pub fn pmf(&self, i: usize) -> f32 {
        self.pmf.get(i).copied().unwrap_or(0.0)
    }

    /// Picks an index with `u` in `[0, 1)`; also returns a fresh uniform
    /// number in `[0, 1)` made of `u`'s remaining precision, so one number
    /// both picks the entry and starts sampling it.
    #[inline]
    pub fn sample(&self, u: f32) -> (usize, f32) {
        let n = self.pmf.len();
        let x = f64::from(u.clamp(0.0, 1.0)) * n as f64;
        let b = (x as usize).min(n - 1);
        let f = (x - b as f64).clamp(0.0, 1.0);
        let k = f64::from(self.keep[b]);
        // Into [0, 1) (NaN, from a bucket kept with certainty, to 0).
        let below_one = |v: f64| {
            if v >= 0.0 {
                (v as f32).min(1.0 - f32::EPSILON / 2.0)
            } else {
                0.0
            }
        };
        if f < k {
            (b, below_one(f / k))
        } else {
            (self.alias[b] as usize, below_one((f - k) / (1.0 - k)))
        }
    }
}

/// The emissive triangles of a scene (a range of consecutive lights, each an
/// `AreaShape::Triangle` area light) sampled as one light: each sample picks
/// a triangle by power with the alias table, or by the light hierarchy as
/// seen from the shading point ([`Self::with_selection`]).
#[derive(Debug, Clone, PartialEq)]
pub struct EmitterGroup {
    /// The group's lights (indices into the light list).
    pub range: Range<usize>,
    table: AliasTable,
    /// The hierarchy over the group's lights, when picks use it.
    tree: Option<LightTree>,
}

impl EmitterGroup {
    /// The group of `lights[range]` when it is to be sampled as a group:
    /// more than [`PER_TRIANGLE_BOUND`] samples per shading point would be
    /// taken triangle by triangle with `area_samples` (the `light_samples`
    /// setting), and some triangle emits. `None` otherwise (the lights are
    /// then sampled one by one).
    pub fn new(lights: &[Light], range: Range<usize>, area_samples: u32) -> Option<Self> {
        let group = lights.get(range.clone())?;
        let first = group.first()?;
        let per_light = super::samples_for_light(first, area_samples);
        if (group.len() as u64) * u64::from(per_light) <= u64::from(PER_TRIANGLE_BOUND) {
            return None;
        }
        // The group's relative powers do not depend on the scene radius.
        let weights: Vec<f32> = group.iter().map(|l| light_power(l, 1.0)).collect();
        let table = AliasTable::new(&weights)?;
        Some(Self {
            range,
            table,
            tree: None,
        })
    }

    /// The group picking by `selection`: by the hierarchy over `lights[range]`
    /// for `Tree`, and for `Auto` over more than [`AUTO_TREE_LIGHTS`]
    /// lights; by power otherwise.
    pub fn with_selection(mut self, lights: &[Light], selection: LightSelection) -> Self {
        let n = self.range.len();
        let use_tree = match selection {
            LightSelection::Power => false,
            LightSelection::Tree => true,
            LightSelection::Auto => n > AUTO_TREE_LIGHTS,
        };
        self.tree = use_tree
            .then(|| {
                let bounds: Vec<Option<LightBounds>> = lights
                    .get(self.range.clone())
                    .unwrap_or_default()
                    .iter()
                    .map(|l| LightBounds::of_light(l, 1.0))
                    .collect();
                LightTree::new(&bounds)
            })
            .flatten();
        self
    }

    /// The group a render with `settings` samples: [`Self::of_scene`] with
    /// its `light_samples`, picking by its `light_selection`.
    pub fn for_render(
        ps: &crate::prepared::PreparedScene<'_>,
        settings: &RenderSettings,
    ) -> Option<Self> {
        Self::of_scene(ps, settings.light_samples.max(1))
            .map(|g| g.with_selection(&ps.lights, settings.light_selection))
    }

    /// The group of `ps`'s emissive-triangle lights, see [`Self::new`].
    pub fn of_scene(ps: &crate::prepared::PreparedScene<'_>, area_samples: u32) -> Option<Self> {
        Self::new(&ps.lights, ps.emissive_lights(), area_samples)
    }

    /// Samples per shading point: `area_samples` (at least 1), stratified
    /// over the pick.
    pub fn samples(area_samples: u32) -> u32 {
        area_samples.max(1)
    }

    /// Picks a light of the group for sample `i` of `count` at the point
    /// `p` of unit normal `n` with the jitter `j` in `[0,1)^2`: returns the
    /// light's index in the light list, its pick probability and the 2D
    /// number to sample a point on it.
    #[inline]
    pub fn pick(
        &self,
        p: glam::Vec3,
        n: glam::Vec3,
        i: u32,
        count: u32,
        j: glam::Vec2,
    ) -> (usize, f32, glam::Vec2) {
        // Stratified in the pick: sample i takes the i-th of `count` strata.
        let t = ((i as f32 + j.x) / count.max(1) as f32).min(1.0 - f32::EPSILON / 2.0);
        if let Some(tree) = &self.tree {
            let (k, pmf, rest) = tree.sample(p, n, t);
            return (self.range.start + k, pmf, glam::Vec2::new(rest, j.y));
        }
        let (k, rest) = self.table.sample(t);
        (
            self.range.start + k,
            self.table.pmf(k),
            glam::Vec2::new(rest, j.y),
        )
    }

    /// The pick probability of light `li` at the point `p` of normal `n`
    /// (zero outside the group).
    pub fn pick_probability(&self, p: glam::Vec3, n: glam::Vec3, li: usize) -> f32 {
        if !self.range.contains(&li) {
            return 0.0;
        }
        let k = li - self.range.start;
        match &self.tree {
            Some(tree) => tree.pmf(p, n, k),
            None => self.table.pmf(k),
        }
    }

    /// True if light `li` belongs to the group.
    #[inline]
    pub fn contains(&self, li: usize) -> bool {
        self.range.contains(&li)
    }
}

/// What an emitter group's light samples are keyed by (see
/// [`group_jitter`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SampleKey {
    /// A pixel-centre shading point: the scan converter's and Whitted's
    /// one sample per pixel, keyed alike so that both pick the same lights.
    Pixel(u32, u32),
    /// Any other shading point (a vertex, a polygon centre, a sub-sample, a
    /// reflected hit), keyed by its position.
    Point(glam::Vec3),
}

/// The jitter in `[0,1)^2` of emitter-group sample `i` at the shading point
/// `key`, for [`EmitterGroup::pick`]: hashed from the render's `seed`, the
/// key and `i`, so that every pixel picks its own triangles (fixed strata
/// centres gave every pixel the same picks: blotches) and the scan
/// converter and Whitted, which both call this, pick the same ones at a
/// pixel. Deterministic: a vertex gets the same picks whichever triangle
/// lights it.
#[inline]
pub fn group_jitter(seed: u64, key: SampleKey, i: u32) -> glam::Vec2 {
    // Salts separating these streams from the techniques' own pixel_rng use.
    let (x, y, salt) = match key {
        SampleKey::Pixel(x, y) => (x, y, 0x6A09_E667_F3BC_C908u64),
        SampleKey::Point(p) => (
            p.x.to_bits() ^ p.z.to_bits().rotate_left(16),
            p.y.to_bits() ^ p.z.to_bits(),
            0xBB67_AE85_84CA_A73Bu64,
        ),
    };
    let mut rng = crate::sampling::pixel_rng(seed ^ salt, x, y, i);
    crate::sampling::uniform2(&mut rng)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::AreaShape;
    use crate::shading::{LocalLighting, ShadingPoint, SurfaceMaterial, shade_local};
    use glam::{Vec2, Vec3};

    /// The square `[-a, a]^2` at height `h`, facing down, as `n x n` cells
    /// of two triangle lights each; cell `(i, j)` emits `le(i, j)`.
    fn emitting_square(a: f32, h: f32, n: u32, le: impl Fn(u32, u32) -> Vec3) -> Vec<Light> {
        let mut lights = Vec::new();
        let step = 2.0 * a / n as f32;
        for j in 0..n {
            for i in 0..n {
                let p = |di: u32, dj: u32| {
                    Vec3::new(-a + (i + di) as f32 * step, h, -a + (j + dj) as f32 * step)
                };
                // (p00, p10, p11) winds clockwise seen from below: normal -y.
                for [x, y, z] in [[p(0, 0), p(1, 0), p(1, 1)], [p(0, 0), p(1, 1), p(0, 1)]] {
                    lights.push(Light::Area {
                        shape: AreaShape::Triangle { a: x, b: y, c: z },
                        color: le(i, j),
                        intensity: 1.0,
                        two_sided: false,
                    });
                }
            }
        }
        lights
    }

    /// Irradiance at `p` (normal +y) from a uniformly emitting polygon of
    /// radiance `le` with vertices `v` (Lambert's formula), in f64.
    fn polygon_irradiance(p: Vec3, v: &[Vec3], le: f64) -> f64 {
        type V = [f64; 3];
        let norm = |d: V| {
            let l = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            [d[0] / l, d[1] / l, d[2] / l]
        };
        let r: Vec<V> = v
            .iter()
            .map(|q| {
                let d = *q - p;
                norm([f64::from(d.x), f64::from(d.y), f64::from(d.z)])
            })
            .collect();
        let mut sum = 0.0f64;
        for (&a, &b) in r.iter().zip(r.iter().cycle().skip(1)) {
            let cross = [
                a[1] * b[2] - a[2] * b[1],
                a[2] * b[0] - a[0] * b[2],
                a[0] * b[1] - a[1] * b[0],
            ];
            let dot = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
            sum += dot.clamp(-1.0, 1.0).acos() * norm(cross)[1];
        }
        le * 0.5 * sum.abs()
    }

    /// xorshift64* numbers in `[0, 1)^2`.
    fn rng2(state: &mut u64) -> Vec2 {
        let mut next = || {
            *state ^= *state >> 12;
            *state ^= *state << 25;
            *state ^= *state >> 27;
            ((state.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 40) as f32) / (1u64 << 24) as f32
        };
        Vec2::new(next(), next())
    }

    /// Mean and standard error of `k` grouped estimates at `sp`.
    fn grouped_estimate(
        lights: &[Light],
        group: &EmitterGroup,
        samples: u32,
        sp: &ShadingPoint,
        k: u32,
    ) -> (f64, f64) {
        let m = SurfaceMaterial {
            kd: Vec3::ONE,
            ..SurfaceMaterial::default()
        };
        let env = LocalLighting {
            lights,
            area_samples: samples,
            ambient: false,
            group: Some(group),
            share: crate::shading::SampleShare::WHOLE,
        };
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let (mut s1, mut s2) = (0.0f64, 0.0f64);
        for _ in 0..k {
            let c = shade_local(&m, sp, &env, |_, _| rng2(&mut state), |_, _| Vec3::ONE);
            let x = f64::from(c.x);
            s1 += x;
            s2 += x * x;
        }
        let mean = s1 / f64::from(k);
        let var = (s2 / f64::from(k) - mean * mean).max(0.0);
        (mean, (var / f64::from(k)).sqrt())
    }

    fn point(p: Vec3) -> ShadingPoint {
        ShadingPoint {
            p,
            n: Vec3::Y,
            ng: Vec3::Y,
            wo: Vec3::Y,
        }
    }

    #[test]
    fn grouped_emitters_match_the_closed_form_irradiance() {
        // 512 small triangles of radiance 2 over a white Lambertian point:
        // the reflected radiance is E / pi, E from Lambert's polygon formula.
        let (a, h) = (1.0f32, 1.5f32);
        let lights = emitting_square(a, h, 16, |_, _| Vec3::splat(2.0));
        let group = EmitterGroup::new(&lights, 0..lights.len(), 16).expect("grouped");
        for p in [
            Vec3::ZERO,
            Vec3::new(0.7, 0.0, -0.4),
            Vec3::new(2.0, 0.0, 1.0),
        ] {
            let corners = [
                Vec3::new(-a, h, -a),
                Vec3::new(a, h, -a),
                Vec3::new(a, h, a),
                Vec3::new(-a, h, a),
            ];
            let exact = polygon_irradiance(p, &corners, 2.0) / std::f64::consts::PI;
            let (mean, se) = grouped_estimate(&lights, &group, 16, &point(p), 4000);
            // Five standard errors (the estimate's own noise) and f32 rounding.
            assert!(
                (mean - exact).abs() <= 5.0 * se + 1e-4 * exact,
                "{p}: {mean} +- {se} vs {exact}"
            );
            assert!(se < 0.01 * exact, "{p}: noisy {se}");
        }
    }

    #[test]
    fn grouped_emitters_match_the_per_triangle_sum() {
        // Unequal emitters (a pattern from 0 to 3, some dark): the grouped
        // estimate's mean equals the per-triangle sum, here computed with 64
        // strata per triangle.
        let le = |i: u32, j: u32| {
            let x = ((i * 7 + j * 3) % 5) as f32 * 0.75;
            Vec3::new(x, 0.5 * x, 0.25)
        };
        let lights = emitting_square(1.0, 1.0, 12, le);
        let group = EmitterGroup::new(&lights, 0..lights.len(), 9).expect("grouped");
        let m = SurfaceMaterial {
            kd: Vec3::ONE,
            ..SurfaceMaterial::default()
        };
        for p in [Vec3::new(0.1, 0.0, 0.2), Vec3::new(-1.5, 0.0, 0.5)] {
            let sp = point(p);
            let per_triangle = LocalLighting {
                lights: &lights,
                area_samples: 64,
                ambient: false,
                group: None,
                share: crate::shading::SampleShare::WHOLE,
            };
            let exact = f64::from(
                shade_local(
                    &m,
                    &sp,
                    &per_triangle,
                    |_, _| Vec2::splat(0.5),
                    |_, _| Vec3::ONE,
                )
                .x,
            );
            let (mean, se) = grouped_estimate(&lights, &group, 9, &sp, 4000);
            assert!(
                (mean - exact).abs() <= 5.0 * se + 1e-4 * exact,
                "{p}: {mean} +- {se} vs {exact}"
            );
        }
    }

    #[test]
    fn a_grouped_mesh_takes_light_samples_samples_per_point() {
        // 5,000 emitting triangles, 16 samples: at most 16 visibility queries
        // (shadow rays) per shading point, however many triangles emit.
        let lights = emitting_square(1.0, 1.0, 50, |_, _| Vec3::ONE);
        assert_eq!(lights.len(), 5000);
        for samples in [1u32, 5, 16] {
            let group = EmitterGroup::new(&lights, 0..lights.len(), samples).expect("grouped");
            let env = LocalLighting {
                lights: &lights,
                area_samples: samples,
                ambient: false,
                group: Some(&group),
                share: crate::shading::SampleShare::WHOLE,
            };
            let mut queries = 0u32;
            let c = shade_local(
                &SurfaceMaterial::default(),
                &point(Vec3::ZERO),
                &env,
                |_, _| Vec2::splat(0.5),
                |_, _| {
                    queries += 1;
                    Vec3::ONE
                },
            );
            assert!(c.x > 0.0);
            assert_eq!(queries, samples, "{samples} samples");
        }
    }

    #[test]
    fn two_pixels_draw_different_group_picks() {
        // 16 x 16 cells of two triangles at 16 samples: a group. Sample i of
        // two neighbouring pixels picks different triangles, the same pixel
        // picks the same ones again, and over many pixels every cell is
        // picked (strata centres picked the same 16 everywhere).
        let lights = emitting_square(1.0, 2.0, 16, |_, _| Vec3::ONE);
        let g = EmitterGroup::new(&lights, 0..lights.len(), 16).expect("a group");
        let picks = |key: SampleKey| -> Vec<usize> {
            (0..16)
                .map(|i| {
                    g.pick(Vec3::ZERO, Vec3::Y, i, 16, group_jitter(7, key, i))
                        .0
                })
                .collect()
        };
        let a = picks(SampleKey::Pixel(10, 20));
        let b = picks(SampleKey::Pixel(11, 20));
        assert_ne!(a, b);
        assert_eq!(a, picks(SampleKey::Pixel(10, 20)));
        assert_ne!(
            picks(SampleKey::Point(Vec3::X)),
            picks(SampleKey::Point(Vec3::Y))
        );
        let mut seen = vec![false; lights.len()];
        for x in 0..256 {
            for li in picks(SampleKey::Pixel(x, 0)) {
                seen[li] = true;
            }
        }
        let n = seen.iter().filter(|&&s| s).count();
        assert!(
            n > lights.len() * 99 / 100,
            "{n} of {} picked",
            lights.len()
        );
    }

    #[test]
    fn small_emitters_stay_per_triangle() {
        // The Cornell box's two-triangle light at 16 samples: 32 <= 64.
        let lights = emitting_square(0.5, 1.0, 1, |_, _| Vec3::ONE);
        assert!(EmitterGroup::new(&lights, 0..2, 16).is_none());
        let lights = emitting_square(0.5, 1.0, 3, |_, _| Vec3::ONE);
        assert!(EmitterGroup::new(&lights, 0..18, 16).is_some());
        // Nothing emits: no group.
        let dark = emitting_square(0.5, 1.0, 3, |_, _| Vec3::ZERO);
        assert!(EmitterGroup::new(&dark, 0..18, 16).is_none());
    }

    #[test]
    fn alias_table_picks_in_proportion_to_weight() {
        let w = [1.0f32, 0.0, 3.0, 0.5, 2.5, f32::NAN, -1.0];
        let t = AliasTable::new(&w).expect("positive weights");
        let total = 7.0f32;
        let n = 70_000;
        let mut counts = [0u32; 7];
        let mut rest_sum = 0.0f64;
        for i in 0..n {
            let (k, r) = t.sample((i as f32 + 0.5) / n as f32);
            counts[k] += 1;
            assert!((0.0..1.0).contains(&r), "{r}");
            rest_sum += f64::from(r);
        }
        for (k, &c) in counts.iter().enumerate() {
            let want = if w[k].is_finite() {
                w[k].max(0.0) / total
            } else {
                0.0
            };
            assert!((t.pmf(k) - want).abs() < 1e-6, "pmf {k}");
            // Stratified input: the frequencies are exact up to bucket edges.
            assert!(
                (c as f32 / n as f32 - want).abs() < 1e-3,
                "{k}: {c} vs {want}"
            );
        }
        // The remaining number is uniform: mean 1/2.
        assert!((rest_sum / f64::from(n) - 0.5).abs() < 1e-3);
        assert!(AliasTable::new(&[0.0, -2.0]).is_none());
        assert!(AliasTable::new(&[]).is_none());
    }

    #[test]
    fn power_table_picks_by_power_and_its_pmf_sums_to_one() {
        let t = LightPowerTable::new(&[1.0, 0.0, 3.0]);
        assert_eq!(t.len(), 3);
        assert_eq!(t.pmf(0), 0.25);
        assert_eq!(t.pmf(1), 0.0);
        assert_eq!(t.pmf(2), 0.75);
        assert_eq!(t.pmf(3), 0.0);
        assert_eq!(t.pick(0.0), Some(0));
        assert_eq!(t.pick(0.2499), Some(0));
        // A light of zero power is never picked: 0.25 lands on light 2.
        assert_eq!(t.pick(0.25), Some(2));
        assert_eq!(t.pick(0.9999), Some(2));
        // Past the last entry (rounding): the last light.
        assert_eq!(t.pick(1.5), Some(2));
        let even = LightPowerTable::new(&[0.0, 0.0]);
        assert_eq!((even.pmf(0), even.pmf(1)), (0.5, 0.5));
        assert_eq!(LightPowerTable::new(&[]).pick(0.5), None);
        // The environment follows the lights.
        let point = Light::Point {
            position: Vec3::ZERO,
            color: Vec3::ONE,
            intensity: 1.0,
            attenuation: crate::scene::Attenuation::None,
        };
        // Its power is what crosses a sphere around it: the irradiance the
        // local model gives at distance d (`pi I / d^2`) times `4 pi d^2`.
        let d = 3.0;
        let i = crate::shading::sample_light(&point, Vec3::new(0.0, 0.0, d), Vec2::ZERO)
            .expect("lit")
            .intensity;
        let crossing = PI * luminance(i) / (d * d) * 4.0 * PI * d * d;
        assert!((light_power(&point, 1.0) - crossing).abs() < 1e-4 * crossing);
        let t = LightPowerTable::of_lights(&[&point], 1.0, Some(1.0 / PI));
        let (pl, pe) = (light_power(&point, 1.0), environment_power(1.0, 1.0 / PI));
        assert_eq!(t.len(), 2);
        assert!((t.pmf(0) - pl / (pl + pe)).abs() < 1e-6);
    }
}
