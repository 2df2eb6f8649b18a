//! Delta vertices in the lock-step kernel: ideal mirrors, smooth
//! conductors and smooth (Fresnel or fixed-weight) transmission, the
//! vertices of `MaterialInfo::delta`. Such a lane stays in its batch: its
//! next direction and weight come from `Bsdf::sample` with the numbers
//! the scalar loop's `sample_bsdf` draws, its MIS pdf from [`mis_pdf`]
//! (0: a delta bounce), and its throughput, ray and Russian roulette from
//! the kernel's own loop, as for the glossy lanes. Next-event estimation
//! finds nothing at such a vertex (`MaterialInfo::dark`), so the kernel
//! skips it there.
//!
//! A Fresnel dielectric draws one more number when both reflection and
//! refraction are possible, so from then on that lane's pairs run ahead of
//! the batch's count: [`LanePairs`] keeps each lane's lead and draws each
//! lane's own pair (`SobolSampler::lanes_2d_at`), exactly what the scalar
//! loop draws for that sample.

// A lane loop indexes several arrays by the lane number (as in `lanes`).
#![allow(clippy::needless_range_loop)]

use super::super::integrator::MaterialInfo;
use super::{F, MixtureSamples, PathTracer, V3, Vertices, set_lanes};
use chiaro_core::sampling::SobolSampler;
use chiaro_core::sampling::sobol::LANES;

/// The batch's samples as the sampler sees them: each lane's bit-reversed
/// sample index, and how many pairs each lane has drawn beyond the
/// batch's count (one per Fresnel choice it has made).
pub(super) struct LanePairs {
    rev: [u32; LANES],
    ahead: [u32; LANES],
}

impl LanePairs {
    /// Samples `first..first + LANES`, none ahead.
    #[inline]
    pub(super) fn new(first: u32) -> Self {
        Self {
            rev: SobolSampler::lane_indices(first),
            ahead: [0; LANES],
        }
    }

    /// Lane `i`'s own pair where the batch is at pair `dim`.
    #[inline(always)]
    pub(super) fn dim(&self, i: usize, dim: u32) -> u32 {
        dim + self.ahead[i]
    }

    /// Pair `dim` of the batch for every lane (its own pair where it runs
    /// ahead): `SobolSampler::lanes_2d` when every lane is as far ahead
    /// (the lanes of a pixel often meet the same surfaces), two of them
    /// selected by lane when the leads differ by one, else each lane's own
    /// pair (`SobolSampler::lanes_2d_at`).
    #[inline(always)]
    pub(super) fn lanes_2d(&self, rng: &mut SobolSampler, dim: u32) -> [[f32; LANES]; 2] {
        let (lo, hi) = self.leads();
        if lo == hi {
            return rng.lanes_2d(dim + lo, &self.rev);
        }
        if hi - lo == 1 {
            let (a, b) = (
                rng.lanes_2d(dim + lo, &self.rev),
                rng.lanes_2d(dim + hi, &self.rev),
            );
            return std::array::from_fn(|k| self.pick(hi, &a[k], &b[k]));
        }
        rng.lanes_2d_at(&self.ahead.map(|a| dim + a), &self.rev)
    }

    /// The first number of [`Self::lanes_2d`]'s pair.
    #[inline(always)]
    pub(super) fn lanes_1d(&self, rng: &mut SobolSampler, dim: u32) -> F {
        let (lo, hi) = self.leads();
        if lo == hi {
            return rng.lanes_1d(dim + lo, &self.rev);
        }
        if hi - lo == 1 {
            let (a, b) = (
                rng.lanes_1d(dim + lo, &self.rev),
                rng.lanes_1d(dim + hi, &self.rev),
            );
            return self.pick(hi, &a, &b);
        }
        rng.lanes_1d_at(&self.ahead.map(|a| dim + a), &self.rev)
    }

    /// The least and the greatest lead.
    #[inline(always)]
    fn leads(&self) -> (u32, u32) {
        let lo = self.ahead.iter().fold(u32::MAX, |m, &a| m.min(a));
        let hi = self.ahead.iter().fold(0, |m, &a| m.max(a));
        (lo, hi)
    }

    /// `b` in the lanes `hi` ahead, `a` in the others.
    #[inline(always)]
    fn pick(&self, hi: u32, a: &F, b: &F) -> F {
        std::array::from_fn(|i| if self.ahead[i] == hi { b[i] } else { a[i] })
    }

    /// Gives the lanes not in `alive` (whose numbers are no longer read)
    /// the lead of a live one, so that they do not widen the leads' range.
    #[inline(always)]
    pub(super) fn retire(&mut self, alive: &[bool; LANES]) {
        let Some(k) = alive.iter().position(|&a| a) else {
            return;
        };
        let lead = self.ahead[k];
        for i in 0..LANES {
            self.ahead[i] = if alive[i] { self.ahead[i] } else { lead };
        }
    }
}

/// The lanes of `shade` whose vertex is a delta one (`MaterialInfo::delta`).
#[inline(always)]
pub(super) fn delta_lanes(
    info: &[Option<&MaterialInfo>; LANES],
    shade: &[bool; LANES],
) -> [bool; LANES] {
    std::array::from_fn(|i| shade[i] && info[i].is_some_and(|m| m.delta))
}

/// `a` without the lanes of `b`.
#[inline(always)]
pub(super) fn without(a: &[bool; LANES], b: &[bool; LANES]) -> [bool; LANES] {
    std::array::from_fn(|i| a[i] & !b[i])
}

impl PathTracer<'_, '_> {
    /// The next direction of each lane in `delta` into `g` (direction,
    /// weight, MIS pdf 0, `ok`), as the scalar loop's `sample_bsdf` draws
    /// it: the lobe choice's number from pair `dim` (drawn only when some
    /// lane needs one), the direction's pair `u` (which delta lobes do not
    /// read), the Fresnel choice's number from pair `dim + 2` only where
    /// [`Bsdf::sample`] asks for it, that lane then running one pair ahead.
    ///
    /// [`Bsdf::sample`]: chiaro_core::shading::Bsdf::sample
    #[allow(clippy::too_many_arguments)]
    #[inline(never)]
    pub(super) fn sample_deltas(
        &self,
        g: &mut MixtureSamples,
        vx: &Vertices,
        info: &[Option<&MaterialInfo>; LANES],
        delta: &[bool; LANES],
        dir: &V3,
        u: [[f32; LANES]; 2],
        dim: u32,
        pairs: &mut LanePairs,
        rng: &mut SobolSampler,
    ) {
        if !delta.iter().any(|&d| d) {
            return;
        }
        let needs = set_lanes(delta).any(|i| info[i].is_some_and(|m| m.bsdf.needs_lobe_number()));
        let u_lobe = if needs {
            pairs.lanes_1d(rng, dim)
        } else {
            [0.0; LANES]
        };
        // (Drawn for every lane when some lane's glass may ask for it; read
        // only where the choice is made.)
        let glass = set_lanes(delta)
            .any(|i| info[i].is_some_and(|m| m.bsdf.fresnel && m.bsdf.lobes.weights[3] > 0.0));
        let u_fresnel = if glass {
            pairs.lanes_1d(rng, dim + 2)
        } else {
            [0.0; LANES]
        };
        for i in set_lanes(delta) {
            let Some(m) = info[i] else { continue };
            let mut drew = false;
            g.sample_lane(i, &m.bsdf, (vx, dir), (&u_lobe, &u), || {
                drew = true;
                u_fresnel[i]
            });
            pairs.ahead[i] += u32::from(drew);
            #[cfg(test)]
            KERNEL_DELTAS.with(|c| c.set(c.get() + 1));
        }
    }
}

#[cfg(test)]
thread_local! {
    /// Delta vertices sampled in the kernel by this thread (for the tests:
    /// that the kernel, not the scalar loop, shaded them).
    pub(in crate::path) static KERNEL_DELTAS: std::cell::Cell<u64> = const { std::cell::Cell::new(0) };
}
