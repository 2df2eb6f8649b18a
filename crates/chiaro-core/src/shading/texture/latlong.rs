//! The lat-long mapping between unit directions and environment-map
//! coordinates, and the polynomial `atan2` and `sin_cos` it is computed
//! with: one implementation for every technique, the path
//! tracer's scalar loop and its lock-step kernel alike.
//!
//! The functions are plain `f32` arithmetic with selects in place of
//! branches, so that a loop over lane arrays ([`latlong_uv_lanes`])
//! vectorises, and a scalar caller gets the same bits lane by lane (Rust
//! neither fuses nor reorders float operations). Their maximum absolute
//! error against the exact functions is [`MAX_ANGLE_ERROR`] radians, which
//! the tests check on dense grids against `f64` libm.

use glam::{Vec2, Vec3};
use std::f32::consts::{FRAC_2_PI, FRAC_PI_2, FRAC_PI_4, PI, TAU};

/// Largest absolute error (radians) of [`atan2`] and each of
/// [`sin_cos`]'s values (for `|x| <= 8 pi`) against the exact functions:
/// about 4 float ulps at `pi`, far below a texel of any environment map
/// (a 16k-wide map's texel is 4e-4 rad).
pub const MAX_ANGLE_ERROR: f32 = 1e-6;

/// `tan(pi / 8)`: above it, [`atan2`]'s ratio is reduced by
/// `atan(t) = pi/4 + atan((t - 1) / (t + 1))`.
const TAN_PI_8: f32 = 0.414_213_57;

/// `atan(r) - r` over `r^3` for `|r| <= tan(pi / 8)`, in `z = r^2`: Cephes'
/// `atanf` polynomial (Moshier 1989), relative error about 2e-7.
#[inline(always)]
fn atan_poly(r: f32) -> f32 {
    let z = r * r;
    let p = ((8.053_744_5e-2 * z - 1.387_768_6e-1) * z + 1.997_771_1e-1) * z - 3.333_295e-1;
    p * z * r + r
}

/// The angle of `(x, y)` from the `+x` axis in `[-pi, pi]`, as libm's
/// `atan2` (the sign of `y` chooses `+-pi` on the negative `x` axis; 0 at
/// the origin), within [`MAX_ANGLE_ERROR`]. Branch-free: the octant is
/// folded onto `[0, pi/8]` by selects and unfolded after the polynomial.
#[inline(always)]
pub fn atan2(y: f32, x: f32) -> f32 {
    let (ax, ay) = (x.abs(), y.abs());
    // The ratio min / max in [0, 1]; past tan(pi/8) the reduced ratio
    // (min - max) / (min + max), one division either way.
    let swap = ay > ax;
    let (lo, hi) = if swap { (ax, ay) } else { (ay, ax) };
    let big = lo > TAN_PI_8 * hi;
    let num = if big { lo - hi } else { lo };
    let den = if big { lo + hi } else { hi };
    // (At the origin 0 / 0 would be NaN: divide by 1 instead.)
    let den = if den > 0.0 { den } else { 1.0 };
    let p = atan_poly(num / den);
    let a = if big { FRAC_PI_4 + p } else { p };
    let a = if swap { FRAC_PI_2 - a } else { a };
    let a = if x.is_sign_negative() { PI - a } else { a };
    a.copysign(y)
}

/// `(sin x, cos x)` within [`MAX_ANGLE_ERROR`] for `|x| <= 8 pi`
/// (accuracy degrades slowly beyond). Cody-Waite reduction by `pi / 2` in
/// three parts, Cephes' `sinf`/`cosf` polynomials on `[-pi/4, pi/4]`, the
/// quadrant applied by selects.
#[inline(always)]
pub fn sin_cos(x: f32) -> (f32, f32) {
    // pi/2 = P1 + P2 + P3, P1 and P2 short enough that k * P is exact.
    const P1: f32 = 1.570_312_5;
    const P2: f32 = 4.837_513e-4;
    const P3: f32 = 7.549_79e-8;
    let k = (x * FRAC_2_PI).round_ties_even();
    let r = ((x - k * P1) - k * P2) - k * P3;
    let z = r * r;
    let s = ((-1.951_529_6e-4 * z + 8.332_161e-3) * z - 1.666_665_5e-1) * z * r + r;
    let c = ((2.443_315_7e-5 * z - 1.388_731_6e-3) * z + 4.166_664_6e-2) * z * z - 0.5 * z + 1.0;
    // Quadrant q = k mod 4: (s, c), (c, -s), (-s, -c), (-c, s).
    let q = k as i32;
    let (s1, c1) = if q & 1 != 0 { (c, s) } else { (s, c) };
    let s1 = if q & 2 != 0 { -s1 } else { s1 };
    let c1 = if (q + 1) & 2 != 0 { -c1 } else { c1 };
    (s1, c1)
}

/// Lat-long texture coordinates of the unit direction `d`: `+y` maps to the
/// top row (`v = 0`), `-z` to the centre column (`u = 0.5`), `u` increasing
/// towards `+x` (so `+x` is at `u = 0.75`). `u` lies in `[0, 1]`, `v` in
/// `[0, 1]`; within [`MAX_ANGLE_ERROR`] over `2 pi` and `pi` of the exact
/// mapping. The polar angle is `atan2(sqrt(x^2 + z^2), y)` rather than
/// `acos(y)`, which near the poles turns the rounding of `y` into
/// microradians.
#[inline(always)]
pub fn latlong_uv(d: Vec3) -> Vec2 {
    let u = 0.5 + atan2(d.x, -d.z) * (1.0 / TAU);
    let v = atan2((d.x * d.x + d.z * d.z).sqrt(), d.y) * (1.0 / PI);
    Vec2::new(u, v)
}

/// The unit direction at lat-long coordinates `uv` turned by `turns` about
/// `+y` (azimuth `phi = (u - turns - 0.5) 2 pi`, polar angle
/// `theta = v pi` from `+y`), and `sin(theta)`: [`latlong_uv`]'s inverse
/// for `turns = 0`.
#[inline(always)]
pub fn latlong_dir(uv: Vec2, turns: f32) -> (Vec3, f32) {
    let phi = (uv.x - turns - 0.5) * TAU;
    let (sin_t, cos_t) = sin_cos(uv.y * PI);
    let (sin_p, cos_p) = sin_cos(phi);
    (
        Vec3::new(sin_t * sin_p, cos_t, -sin_t * cos_p),
        sin_t.max(0.0),
    )
}

/// [`latlong_uv`] of `N` directions given as component arrays: the same
/// bits as the scalar function lane by lane, in a loop that vectorises.
#[inline(always)]
pub fn latlong_uv_lanes<const N: usize>(
    x: &[f32; N],
    y: &[f32; N],
    z: &[f32; N],
) -> ([f32; N], [f32; N]) {
    let (mut u, mut v) = ([0.0; N], [0.0; N]);
    for i in 0..N {
        let uv = latlong_uv(Vec3::new(x[i], y[i], z[i]));
        (u[i], v[i]) = (uv.x, uv.y);
    }
    (u, v)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Largest |approximation - exact| over `n` points of `[lo, hi]`.
    fn max_err(lo: f64, hi: f64, n: u32, f: impl Fn(f32) -> (f32, f64)) -> f64 {
        (0..=n)
            .map(|i| {
                let x = (lo + (hi - lo) * f64::from(i) / f64::from(n)) as f32;
                let (a, e) = f(x);
                (f64::from(a) - e).abs()
            })
            .fold(0.0, f64::max)
    }

    #[test]
    fn atan2_is_within_its_bound_over_the_circle_and_at_the_axes() {
        let bound = f64::from(MAX_ANGLE_ERROR);
        // A dense ring and rays of several lengths, every octant.
        let mut worst = 0.0f64;
        for i in 0..=400_000u32 {
            let t = -std::f64::consts::PI + std::f64::consts::TAU * f64::from(i) / 400_000.0;
            for r in [1.0f64, 1e-3, 37.0] {
                let (y, x) = ((r * t.sin()) as f32, (r * t.cos()) as f32);
                let e = f64::from(y).atan2(f64::from(x));
                worst = worst.max((f64::from(atan2(y, x)) - e).abs());
            }
        }
        assert!(worst <= bound, "atan2 error {worst:e} > {bound:e}");
        // The axes and the origin, signs as libm gives them.
        for (y, x) in [
            (0.0f32, 1.0f32),
            (1.0, 0.0),
            (0.0, -1.0),
            (-0.0, -1.0),
            (-1.0, 0.0),
            (0.0, 0.0),
            (-0.0, 0.0),
        ] {
            let (a, e) = (atan2(y, x), y.atan2(x));
            assert!(
                (a - e).abs() <= MAX_ANGLE_ERROR,
                "atan2({y}, {x}) = {a}, libm {e}"
            );
            assert_eq!(
                a.is_sign_negative(),
                e.is_sign_negative(),
                "atan2({y}, {x})"
            );
        }
    }

    #[test]
    fn sin_cos_is_within_its_bound() {
        let bound = f64::from(MAX_ANGLE_ERROR);
        let lim = 8.0 * std::f64::consts::PI;
        let es = max_err(-lim, lim, 2_000_000, |x| (sin_cos(x).0, f64::from(x).sin()));
        let ec = max_err(-lim, lim, 2_000_000, |x| (sin_cos(x).1, f64::from(x).cos()));
        assert!(
            es <= bound && ec <= bound,
            "sin {es:e}, cos {ec:e} > {bound:e}"
        );
        assert_eq!(sin_cos(0.0), (0.0, 1.0));
    }

    #[test]
    fn latlong_uv_is_within_its_bound_of_libm() {
        // Directions on a dense grid of the sphere, poles included; the
        // exact mapping of the same f32 components in f64.
        let (mut eu, mut ev) = (0.0f64, 0.0f64);
        for i in 0..=1000u32 {
            let theta = std::f64::consts::PI * f64::from(i) / 1000.0;
            for j in 0..2000u32 {
                let phi = std::f64::consts::TAU * f64::from(j) / 2000.0;
                let d = Vec3::new(
                    (theta.sin() * phi.sin()) as f32,
                    theta.cos() as f32,
                    (-theta.sin() * phi.cos()) as f32,
                );
                let (x, y, z) = (f64::from(d.x), f64::from(d.y), f64::from(d.z));
                let u = 0.5 + x.atan2(-z) / std::f64::consts::TAU;
                let v = (x * x + z * z).sqrt().atan2(y) / std::f64::consts::PI;
                let uv = latlong_uv(d);
                let du = (f64::from(uv.x) - u).abs();
                eu = eu.max(du.min(1.0 - du));
                ev = ev.max((f64::from(uv.y) - v).abs());
            }
        }
        let bound = f64::from(MAX_ANGLE_ERROR);
        assert!(
            eu * std::f64::consts::TAU <= bound && ev * std::f64::consts::PI <= bound,
            "u error {eu:e}, v error {ev:e}"
        );
    }

    #[test]
    fn latlong_dir_inverts_latlong_uv() {
        for i in 1..400u32 {
            for j in 0..400u32 {
                let uv = Vec2::new(j as f32 / 400.0, i as f32 / 400.0);
                let (d, sin_t) = latlong_dir(uv, 0.0);
                assert!((d.length() - 1.0).abs() < 1e-6);
                assert!((sin_t - (d.x * d.x + d.z * d.z).sqrt()).abs() < 1e-6);
                let back = latlong_uv(d);
                // (u = 0 and u = 1 are one column; an error in u is an
                // arc of 2 pi sin(theta) times it, ill-conditioned at the
                // poles.)
                let du = (back.x - uv.x).abs();
                let arc = du.min(1.0 - du) * TAU * sin_t;
                let dv = (back.y - uv.y).abs();
                assert!(arc < 1e-6 && dv < 1e-6, "{uv}: back {back}");
            }
        }
    }

    #[test]
    fn lanes_give_the_scalar_bits() {
        let mut rng = crate::sampling::pixel_rng(1, 2, 3, 4);
        for _ in 0..1000 {
            let d: [Vec3; 16] = std::array::from_fn(|_| {
                let u = crate::sampling::uniform2(&mut rng);
                crate::sampling::sample_uniform_sphere(u)
            });
            let (u, v) = latlong_uv_lanes(&d.map(|d| d.x), &d.map(|d| d.y), &d.map(|d| d.z));
            for i in 0..16 {
                let s = latlong_uv(d[i]);
                assert_eq!(
                    (u[i].to_bits(), v[i].to_bits()),
                    (s.x.to_bits(), s.y.to_bits())
                );
            }
        }
    }
}
