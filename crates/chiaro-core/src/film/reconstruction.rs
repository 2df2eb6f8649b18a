//! Pixel reconstruction filters ([`PixelFilter`]) for the techniques that
//! sample the image plane: the weight of each filter and the sampling of
//! film positions from it (filter importance sampling, Ernst et al. 2006).
//!
//! A pixel's value under filter `w` is the weighted mean
//! `∫ w(x - c) L(x) dx / ∫ w(x - c) dx` over the film (the image
//! rectangle, not the plane: samples only fall inside the image, as in
//! Mitsuba's `hdrfilm` and pbrt's film), with `c` the pixel centre. Every
//! filter here is separable, `w(x, y) = w(x) w(y)`, so drawing each axis
//! from `w` restricted to the film makes each sample an unbiased estimate
//! of that mean with weight one.

use crate::scene::PixelFilter;

/// Standard deviation of [`PixelFilter::Gaussian`], in pixels (Mitsuba's
/// default `stddev`).
pub const GAUSSIAN_STDDEV: f64 = 0.5;

impl PixelFilter {
    /// Radius of the filter's support in pixels (the box: half a pixel).
    pub fn radius(self) -> f32 {
        match self {
            PixelFilter::Box => 0.5,
            PixelFilter::Tent => 1.0,
            // Mitsuba's `gaussian` cuts off after four standard deviations.
            PixelFilter::Gaussian => (4.0 * GAUSSIAN_STDDEV) as f32,
        }
    }

    /// The one-dimensional weight at `x` pixels from the pixel centre
    /// (unnormalised; zero outside [`radius`](Self::radius)). The Gaussian
    /// is Mitsuba's windowed one, `max(0, exp(-x²/2σ²) - exp(-r²/2σ²))`
    /// (`src/rfilters/gaussian.cpp`), so it falls to zero at the radius.
    pub fn weight(self, x: f64) -> f64 {
        match self {
            PixelFilter::Box => {
                if x.abs() <= 0.5 {
                    1.0
                } else {
                    0.0
                }
            }
            PixelFilter::Tent => (1.0 - x.abs()).max(0.0),
            PixelFilter::Gaussian => {
                let a = -0.5 / (GAUSSIAN_STDDEV * GAUSSIAN_STDDEV);
                let r = 4.0 * GAUSSIAN_STDDEV;
                ((a * x * x).exp() - (a * r * r).exp()).max(0.0)
            }
        }
    }

    /// `∫_{-r}^{x} weight`, the unnormalised cumulative weight (closed forms;
    /// the Gaussian's through `erf`).
    fn cumulative(self, x: f64) -> f64 {
        let r = f64::from(self.radius());
        let x = x.clamp(-r, r);
        match self {
            PixelFilter::Box => x + 0.5,
            PixelFilter::Tent => {
                if x <= 0.0 {
                    0.5 * (x + 1.0) * (x + 1.0)
                } else {
                    1.0 - 0.5 * (1.0 - x) * (1.0 - x)
                }
            }
            PixelFilter::Gaussian => {
                let s = GAUSSIAN_STDDEV;
                let k = s * std::f64::consts::SQRT_2;
                let bias = (-0.5 * (r / s) * (r / s)).exp();
                0.5 * std::f64::consts::PI.sqrt() * k * (erf(x / k) + erf(r / k)) - bias * (x + r)
            }
        }
    }

    /// A film coordinate (pixels from the film's left or top edge) for
    /// pixel `pixel` of a film `size` pixels wide, drawn with density
    /// proportional to the filter centred on the pixel and restricted to
    /// the film `[0, size]`, from the uniform number `u` in `[0, 1)`.
    ///
    /// The box returns `pixel + u` exactly (the uniform jitter inside the
    /// pixel); the other filters invert their cumulative weight (the
    /// tent in closed form, the Gaussian by safeguarded Newton steps to
    /// double precision).
    pub fn sample_position(self, pixel: u32, size: u32, u: f32) -> f32 {
        if self == PixelFilter::Box {
            return pixel as f32 + u;
        }
        let c = f64::from(pixel) + 0.5;
        let r = f64::from(self.radius());
        // The support around the centre, cut to the film.
        let lo = (-r).max(-c);
        let hi = r.min(f64::from(size) - c);
        let (f_lo, f_hi) = (self.cumulative(lo), self.cumulative(hi));
        let target = f_lo + f64::from(u) * (f_hi - f_lo);
        let x = match self {
            PixelFilter::Box => lo + f64::from(u) * (hi - lo),
            PixelFilter::Tent => {
                if target <= 0.5 {
                    (2.0 * target).sqrt() - 1.0
                } else {
                    1.0 - (2.0 * (1.0 - target)).max(0.0).sqrt()
                }
            }
            PixelFilter::Gaussian => {
                // Newton on the monotone cumulative weight, kept inside the
                // bracket [a, b] and bisecting where a step leaves it.
                let (mut a, mut b) = (lo, hi);
                let mut x = 0.5 * (lo + hi);
                for _ in 0..64 {
                    let f = self.cumulative(x) - target;
                    if f.abs() <= 1e-13 {
                        break;
                    }
                    if f < 0.0 {
                        a = x;
                    } else {
                        b = x;
                    }
                    let d = self.weight(x);
                    let step = if d > 0.0 { x - f / d } else { f64::NAN };
                    x = if step > a && step < b {
                        step
                    } else {
                        0.5 * (a + b)
                    };
                    if b - a <= 1e-12 {
                        break;
                    }
                }
                x
            }
        };
        // Inside the film even after rounding to f32.
        let p = (c + x.clamp(lo, hi)) as f32;
        p.clamp(0.0, (size as f32).next_down().max(0.0))
    }
}

/// The error function, `erf(x) = 2/√π ∫_0^x exp(-t²) dt`, to double
/// precision for `|x| <= 6` (and ±1 beyond): the series of Abramowitz and
/// Stegun 7.1.6, `erf x = 2/√π exp(-x²) Σ 2ⁿ x²ⁿ⁺¹ / (1·3···(2n+1))`,
/// whose terms are all positive (no cancellation).
fn erf(x: f64) -> f64 {
    if x.abs() > 6.0 {
        return x.signum();
    }
    let x2 = x * x;
    let mut term = x;
    let mut sum = x;
    let mut n = 0.0;
    while term.abs() > 1e-17 * sum.abs() {
        n += 1.0;
        term *= 2.0 * x2 / (2.0 * n + 1.0);
        sum += term;
    }
    2.0 / std::f64::consts::PI.sqrt() * (-x2).exp() * sum
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn erf_closed_forms() {
        assert_eq!(erf(0.0), 0.0);
        // erf(1) and erf(0.5) to 15 digits (Abramowitz and Stegun, table 7.1).
        assert!((erf(1.0) - 0.842_700_792_949_715).abs() < 1e-14);
        assert!((erf(0.5) - 0.520_499_877_813_047).abs() < 1e-14);
        assert!((erf(-2.0) + 0.995_322_265_018_953).abs() < 1e-14);
        assert!((erf(3.0) - 0.999_977_909_503_001).abs() < 1e-14);
    }

    /// The cumulative weight is the integral of the weight (midpoint rule).
    #[test]
    fn cumulative_integrates_the_weight() {
        for f in [PixelFilter::Box, PixelFilter::Tent, PixelFilter::Gaussian] {
            let r = f64::from(f.radius());
            let n = 20_000;
            let mut sum = 0.0;
            for i in 0..n {
                let x = -r + (i as f64 + 0.5) * 2.0 * r / n as f64;
                sum += f.weight(x) * 2.0 * r / n as f64;
                let xe = -r + (i + 1) as f64 * 2.0 * r / n as f64;
                assert!((f.cumulative(xe) - sum).abs() < 1e-6, "{f:?} at {xe}");
            }
        }
    }

    #[test]
    fn box_is_the_uniform_jitter() {
        for u in [0.0, 0.25, 0.999] {
            assert_eq!(PixelFilter::Box.sample_position(7, 32, u), 7.0 + u);
        }
    }

    /// Positions follow the filter restricted to the film: a histogram of
    /// stratified draws matches the normalised weight, in the middle of
    /// the film and at its edge.
    #[test]
    fn positions_follow_the_restricted_filter() {
        for f in [PixelFilter::Tent, PixelFilter::Gaussian] {
            for (pixel, size) in [(10u32, 32u32), (0, 32), (31, 32), (0, 1)] {
                let c = f64::from(pixel) + 0.5;
                let lo = (c - f64::from(f.radius())).max(0.0);
                let hi = (c + f64::from(f.radius())).min(f64::from(size));
                let bins = 40;
                let mut hist = vec![0.0f64; bins];
                let n = 200_000;
                for i in 0..n {
                    let u = (i as f32 + 0.5) / n as f32;
                    let p = f64::from(f.sample_position(pixel, size, u));
                    assert!(p >= 0.0 && p < f64::from(size), "{p}");
                    let b = (((p - lo) / (hi - lo)) * bins as f64) as usize;
                    hist[b.min(bins - 1)] += 1.0 / n as f64;
                }
                let total = f.cumulative(hi - c) - f.cumulative(lo - c);
                for (b, h) in hist.iter().enumerate() {
                    let a = lo + (hi - lo) * b as f64 / bins as f64;
                    let e = a + (hi - lo) / bins as f64;
                    let expect = (f.cumulative(e - c) - f.cumulative(a - c)) / total;
                    assert!(
                        (h - expect).abs() < 1e-4,
                        "{f:?} {pixel}/{size} bin {b}: {h} vs {expect}"
                    );
                }
            }
        }
    }
}
