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
