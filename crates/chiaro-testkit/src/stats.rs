//! Sample statistics for the statistical tests (Monte Carlo estimates
//! checked against a closed form within a few standard errors).

use chiaro_core::film::Film;
use glam::Vec3;

/// Channel `c` (0 red, 1 green, 2 blue) of every pixel of `film`.
///
/// # Panics
/// If `c > 2`.
pub fn channel(film: &Film, c: usize) -> Vec<f32> {
    film.color.iter().map(|p| p[c]).collect()
}

/// The mean and the unbiased sample variance (divided by `n - 1`) of
/// `values`, summed in `f32` in order. NaN for fewer than two values.
pub fn mean_and_variance(values: &[f32]) -> (f32, f32) {
    let n = values.len() as f32;
    let mean = values.iter().sum::<f32>() / n;
    let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f32>() / (n - 1.0);
    (mean, var)
}

/// The mean of `values` and the standard error of that mean,
/// `sqrt(variance / n)`.
pub fn mean_and_stderr(values: &[f32]) -> (f32, f32) {
    let (mean, var) = mean_and_variance(values);
    (mean, (var / values.len() as f32).sqrt())
}

/// Per pixel over `films` (the colours of renders of one scene with
/// different seeds, all the same size): the mean and the unbiased sample
/// variance per channel (divided by `n - 1`), summed in `f32` in order.
///
/// # Panics
/// If `films` is empty or the films differ in length.
pub fn pixel_mean_and_variance(films: &[Vec<Vec3>]) -> (Vec<Vec3>, Vec<Vec3>) {
    let n = films.len() as f32;
    let mean: Vec<Vec3> = (0..films[0].len())
        .map(|i| films.iter().map(|f| f[i]).sum::<Vec3>() / n)
        .collect();
    let var = (0..films[0].len())
        .map(|i| {
            films
                .iter()
                .map(|f| (f[i] - mean[i]) * (f[i] - mean[i]))
                .sum::<Vec3>()
                / (n - 1.0)
        })
        .collect();
    (mean, var)
}

/// Where two Monte Carlo estimates of one picture differ most, in
/// standard errors (see [`worst_block`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BlockDifference {
    /// `|mean difference| / standard error` (0 where the difference is 0;
    /// NaN where a value was NaN).
    pub z: f32,
    /// The block, in blocks from the top left.
    pub block: (u32, u32),
    /// The colour channel.
    pub channel: usize,
    /// The difference of the two block means in that channel.
    pub difference: f32,
    /// Its standard error.
    pub stderr: f32,
}

/// Two pictures `a` and `b` of `width` x `height` pixels, each the
/// per-pixel mean of `seeds` renders with the per-pixel variance of one
/// render (`a_var`, `b_var`; see [`pixel_mean_and_variance`]), compared by
/// `block` x `block` blocks: the block and channel whose mean difference
/// is the most standard errors (the pixels of a block taken as
/// independent). The first NaN is returned as it is found.
///
/// # Panics
/// If a slice is shorter than `width * height`.
#[allow(clippy::too_many_arguments)]
pub fn worst_block(
    (a, a_var): (&[Vec3], &[Vec3]),
    (b, b_var): (&[Vec3], &[Vec3]),
    width: u32,
    height: u32,
    block: u32,
    seeds: u64,
) -> BlockDifference {
    let mut worst = BlockDifference {
        z: 0.0,
        block: (0, 0),
        channel: 0,
        difference: 0.0,
        stderr: 0.0,
    };
    for by in 0..height / block {
        for bx in 0..width / block {
            let (mut d, mut var) = (Vec3::ZERO, Vec3::ZERO);
            for y in by * block..by * block + block {
                for x in bx * block..bx * block + block {
                    let i = (y * width + x) as usize;
                    d += a[i] - b[i];
                    var += a_var[i] + b_var[i];
                }
            }
            // Block means of `seeds` renders each: the mean difference and
            // its standard error.
            let n = (block * block) as f32;
            let d = d / n;
            let se = (var / (n * n * seeds as f32)).powf(0.5);
            for c in 0..3 {
                let z = if d[c] == 0.0 {
                    0.0
                } else {
                    d[c].abs() / se[c].max(1e-6)
                };
                if z > worst.z || z.is_nan() {
                    worst = BlockDifference {
                        z,
                        block: (bx, by),
                        channel: c,
                        difference: d[c],
                        stderr: se[c],
                    };
                    if z.is_nan() {
                        return worst;
                    }
                }
            }
        }
    }
    worst
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn variance_of_a_known_sample() {
        // 1, 2, 3, 4: mean 2.5, squared deviations 5 over n - 1 = 3.
        let (m, v) = mean_and_variance(&[1.0, 2.0, 3.0, 4.0]);
        assert_eq!(m, 2.5);
        assert!((v - 5.0 / 3.0).abs() < 1e-6, "{v}");
        let (_, se) = mean_and_stderr(&[1.0, 2.0, 3.0, 4.0]);
        assert!((se - (5.0f32 / 12.0).sqrt()).abs() < 1e-6, "{se}");
        // Per pixel: the same numbers in every channel of pixel 0.
        let films: Vec<Vec<Vec3>> = [1.0, 2.0, 3.0, 4.0]
            .iter()
            .map(|&v| vec![Vec3::splat(v)])
            .collect();
        let (pm, pv) = pixel_mean_and_variance(&films);
        assert_eq!(pm, vec![Vec3::splat(2.5)]);
        assert!((pv[0] - Vec3::splat(5.0 / 3.0)).abs().max_element() < 1e-6);
    }
}

/// The complementary error function, with fractional error below 1.2e-7
/// everywhere (Numerical Recipes in C, 2nd ed., section 6.2, `erfcc`: a
/// Chebyshev fit of `erfc(z) exp(z^2)`).
pub fn erfc(x: f64) -> f64 {
    let z = x.abs();
    let t = 1.0 / (1.0 + 0.5 * z);
    let poly = -z * z - 1.265_512_23
        + t * (1.000_023_68
            + t * (0.374_091_96
                + t * (0.096_784_18
                    + t * (-0.186_288_06
                        + t * (0.278_868_07
                            + t * (-1.135_203_98
                                + t * (1.488_515_87 + t * (-0.822_152_23 + t * 0.170_872_77))))))));
    let r = t * poly.exp();
    if x >= 0.0 { r } else { 2.0 - r }
}

/// The outcome of Mitsuba's per-pixel z-test of a render against a
/// reference mean and its per-sample variance.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ZTest {
    /// Pixels compared.
    pub pixels: usize,
    /// Pixels with at least one channel whose p-value is below the
    /// Bonferroni-corrected level `1 - 0.99^(1 / pixels)`.
    pub failed: usize,
}

impl ZTest {
    /// The fraction of pixels that pass (Mitsuba's scene passes at 0.9975).
    pub fn pass_fraction(&self) -> f64 {
        if self.pixels == 0 {
            return 1.0;
        }
        1.0 - self.failed as f64 / self.pixels as f64
    }
}

/// Linear sRGB (Rec. 709 primaries, D65) to CIE XYZ (IEC 61966-2-1).
pub fn srgb_to_xyz(c: [f64; 3]) -> [f64; 3] {
    let [r, g, b] = c;
    [
        0.412_456_4 * r + 0.357_576_1 * g + 0.180_437_5 * b,
        0.212_672_9 * r + 0.715_152_2 * g + 0.072_175_0 * b,
        0.019_333_9 * r + 0.119_192_0 * g + 0.950_304_1 * b,
    ]
}

/// Mitsuba's render test (`src/render/tests/test_renders.py`): per pixel
/// and channel, in XYZ, `z = |mean - ref| sqrt(spp / max(var, 1e-4))` and
/// `p = erfc(z / sqrt 2)`; a pixel fails when a channel's `p` is below
/// `1 - 0.99^(1 / pixels)`. `mean`, `reference` and `variance` are linear
/// RGB per pixel (the variance file's RGB is converted to XYZ by the same
/// linear map it was converted from); `spp` is the render's samples per
/// pixel.
///
/// # Panics
/// If the three slices differ in length.
pub fn mitsuba_z_test(
    mean: &[[f64; 3]],
    reference: &[[f64; 3]],
    variance: &[[f64; 3]],
    spp: f64,
) -> ZTest {
    let fails = mitsuba_z_failures(mean, reference, variance, spp);
    ZTest {
        pixels: fails.len(),
        failed: fails.iter().filter(|f| **f).count(),
    }
}

/// Which pixels fail [`mitsuba_z_test`] (to map where a render disagrees).
///
/// # Panics
/// If the three slices differ in length.
pub fn mitsuba_z_failures(
    mean: &[[f64; 3]],
    reference: &[[f64; 3]],
    variance: &[[f64; 3]],
    spp: f64,
) -> Vec<bool> {
    assert!(mean.len() == reference.len() && mean.len() == variance.len());
    let pixels = mean.len();
    let alpha = 1.0 - 0.99f64.powf(1.0 / pixels.max(1) as f64);
    (0..pixels)
        .map(|i| {
            let (m, r, v) = (
                srgb_to_xyz(mean[i]),
                srgb_to_xyz(reference[i]),
                srgb_to_xyz(variance[i]),
            );
            (0..3).any(|c| {
                let z = (m[c] - r[c]).abs() * (spp / v[c].max(1e-4)).sqrt();
                let p = erfc(z / std::f64::consts::SQRT_2);
                // NaN fails too.
                p.partial_cmp(&alpha).is_none_or(|o| o.is_lt())
            })
        })
        .collect()
}

#[cfg(test)]
mod z_tests {
    use super::*;

    #[test]
    fn erfc_closed_forms() {
        assert!((erfc(0.0) - 1.0).abs() < 1e-7);
        // erfc(1) = 0.157299207050285, erfc(-1) = 2 - erfc(1).
        assert!((erfc(1.0) / 0.157_299_207_050_285 - 1.0).abs() < 2e-7);
        assert!((erfc(-1.0) - (2.0 - 0.157_299_207_050_285)).abs() < 1e-7);
        // erfc(4) = 1.541725790028e-8: the tail keeps its relative precision.
        assert!((erfc(4.0) / 1.541_725_790_028e-8 - 1.0).abs() < 2e-7);
    }

    #[test]
    fn z_test_passes_equal_and_fails_far() {
        let ref_ = vec![[0.5, 0.5, 0.5]; 100];
        let var = vec![[0.01, 0.01, 0.01]; 100];
        assert_eq!(mitsuba_z_test(&ref_, &ref_, &var, 64.0).failed, 0);
        let mut off = ref_.clone();
        off[3] = [0.9, 0.5, 0.5];
        let t = mitsuba_z_test(&off, &ref_, &var, 64.0);
        assert_eq!(t.failed, 1);
        assert!((t.pass_fraction() - 0.99).abs() < 1e-12);
    }
}
