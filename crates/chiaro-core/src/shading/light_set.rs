//! The light layer: each light's power, and the emissive triangles of a
//! scene as one light group chosen by power (an alias table), so that a
//! shading point takes a bounded number of samples from an emissive mesh of
//! any size.

use crate::scene::Light;
use glam::Vec3;
use std::f32::consts::PI;
use std::ops::Range;

/// An emitter group is sampled per triangle (every triangle its own area
/// light, as before grouping) while its triangle count times the samples per
/// area light is at most this: small emitters (a Cornell box's two-triangle
/// light) keep their stratified per-triangle images.
pub const PER_TRIANGLE_BOUND: u32 = 64;

/// Rec. 709 luminance of a linear RGB colour.
#[inline]
pub fn luminance(c: Vec3) -> f32 {
    c.dot(Vec3::new(0.2126, 0.7152, 0.0722))
}

/// A rough power estimate of `light` (luminance times area or solid-angle
/// measure) for choosing lights in proportion to it; `scene_radius` sizes a
/// directional light's footprint. Never negative.
pub fn light_power(light: &Light, scene_radius: f32) -> f32 {
    let p = luminance(light.power_rgb()).max(0.0);
    match light {
        Light::Area {
            shape, two_sided, ..
        } => p * shape.area() * PI * if *two_sided { 2.0 } else { 1.0 },
        Light::Directional { .. } => p * PI * scene_radius * scene_radius,
        _ => p * 4.0 * PI,
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
        if !(total > 0.0) || !total.is_finite() {
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
        let below_one = |v: f64| (v as f32).min(1.0 - f32::EPSILON / 2.0).max(0.0);
        if f < k {
            (b, below_one(f / k))
        } else {
            (self.alias[b] as usize, below_one((f - k) / (1.0 - k)))
        }
    }
}

/// The emissive triangles of a scene (a range of consecutive lights, each an
/// `AreaShape::Triangle` area light) sampled as one light: each sample picks
/// a triangle by power with the alias table.
#[derive(Debug, Clone, PartialEq)]
pub struct EmitterGroup {
    /// The group's lights (indices into the light list).
    pub range: Range<usize>,
    table: AliasTable,
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
        Some(Self { range, table })
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

    /// Picks a light of the group for sample `i` of `count` with the jitter
    /// `j` in `[0,1)^2`: returns the light's index in the light list, its
    /// pick probability and the 2D number to sample a point on it.
    #[inline]
    pub fn pick(&self, i: u32, count: u32, j: glam::Vec2) -> (usize, f32, glam::Vec2) {
        // Stratified in the pick: sample i takes the i-th of `count` strata.
        let t = ((i as f32 + j.x) / count.max(1) as f32).min(1.0 - f32::EPSILON / 2.0);
        let (k, rest) = self.table.sample(t);
        (
            self.range.start + k,
            self.table.pmf(k),
            glam::Vec2::new(rest, j.y),
        )
    }

    /// The pick probability of light `li` (zero outside the group).
    pub fn pick_probability(&self, li: usize) -> f32 {
        if self.range.contains(&li) {
            self.table.pmf(li - self.range.start)
        } else {
            0.0
        }
    }

    /// True if light `li` belongs to the group.
    #[inline]
    pub fn contains(&self, li: usize) -> bool {
        self.range.contains(&li)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
}
