//! Sampling: seeded per-pixel generators and warps from the unit square to
//! the shapes renderers sample, each with its pdf (named in sets:
//! `sample_*` and `*_pdf`).
//!
//! Sources: pbrt-v4 `util/sampling.h`; Shirley and Chiu 1997 for the
//! concentric disk map.

pub mod sobol;

pub use sobol::SobolSampler;

use glam::{Vec2, Vec3, Vec4};
use rand::{RngExt, SeedableRng};
use std::f32::consts::{FRAC_1_PI, FRAC_PI_4, PI};

/// The generator used by every technique: PCG32.
pub type Rng = rand_pcg::Pcg32;

/// SplitMix64 finaliser, used to hash seeds.
#[inline]
pub fn mix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// The generator for pixel `(x, y)`, sample `sample`, under the scene seed:
/// results never depend on the thread count or tile order.
pub fn pixel_rng(seed: u64, x: u32, y: u32, sample: u32) -> Rng {
    let key = mix64(
        seed ^ mix64((u64::from(x) << 32) | u64::from(y))
            ^ mix64(u64::from(sample).wrapping_add(0x51ED_2701)),
    );
    Rng::seed_from_u64(key)
}

/// A uniform number in `[0, 1)`.
#[inline]
pub fn uniform(rng: &mut Rng) -> f32 {
    // 24 random bits: exactly representable, strictly below 1.
    (rng.random::<u32>() >> 8) as f32 * (1.0 / 16_777_216.0)
}

/// A uniform point in `[0, 1)^2`.
#[inline]
pub fn uniform2(rng: &mut Rng) -> Vec2 {
    Vec2::new(uniform(rng), uniform(rng))
}

/// Concentric map from the square to the unit disk (Shirley and Chiu 1997).
///
/// Both wedges (|x| > |y| or not) need the sine and cosine of one angle in
/// `[-pi/4, pi/4]` (the second wedge's angle `pi/2 - a` swaps them),
/// evaluated by `sin_cos_quarter` instead of the library's full-range
/// `sin_cos`. See `concentric_disk_polar` for why it has no branch.
#[inline]
pub fn sample_concentric_disk(u: Vec2) -> Vec2 {
    concentric_disk_polar(u).0
}

/// [`sample_concentric_disk`]'s point and its signed radius `r` (`|r|` is
/// the point's distance from the centre).
///
/// Branch-free: on Sobol points the wedge is a coin flip, so a branch on it
/// mispredicts about half the time. The wedge selects the numerator and
/// the denominator of the one division (`a / r` with `|a| <= |r|`, so only
/// the centre divides 0 by 0, and there the ratio is taken as 0) and which
/// of `(r cos, r sin)` is x. The two selects are SIMD blends on purpose:
/// x86 codegen turns a select of two scalar floats into a branch.
#[inline]
fn concentric_disk_polar(u: Vec2) -> (Vec2, f32) {
    let o = 2.0 * u - Vec2::ONE;
    let x_wedge = Vec4::splat(o.x.abs()).cmpgt(Vec4::splat(o.y.abs()));
    let ra = Vec4::select(
        x_wedge,
        Vec4::new(o.x, o.y, 0.0, 0.0),
        Vec4::new(o.y, o.x, 0.0, 0.0),
    );
    let (r, a) = (ra.x, ra.y);
    let ratio = if r == 0.0 { 0.0 } else { a / r };
    let (s, c) = sin_cos_quarter(FRAC_PI_4 * ratio);
    let (rc, rs) = (r * c, r * s);
    let d = Vec4::select(
        x_wedge,
        Vec4::new(rc, rs, 0.0, 0.0),
        Vec4::new(rs, rc, 0.0, 0.0),
    );
    (Vec2::new(d.x, d.y), r)
}

/// `(sin a, cos a)` for `a` in `[-pi/4, pi/4]`, accurate to about one
/// float ulp: the minimax polynomials of Cephes' `sinf`/`cosf`
/// (Moshier, `cephes/single/sinf.c`) for that range, with no range
/// reduction.
#[inline]
fn sin_cos_quarter(a: f32) -> (f32, f32) {
    let z = a * a;
    let s = ((-1.951_529_6e-4 * z + 8.332_161e-3) * z - 1.666_665_5e-1) * z * a + a;
    let c = (((2.443_315_7e-5 * z - 1.388_731_6e-3) * z + 4.166_664_6e-2) * z * z) - 0.5 * z + 1.0;
    (s, c)
}

/// Cosine-weighted direction about +z (local frame): Malley's method, the
/// concentric disk point lifted to the hemisphere (pbrt-v4
/// `SampleCosineHemisphere`). Its pdf is [`cosine_hemisphere_pdf`].
///
/// The height is `sqrt(1 - r^2)` from the disk point's radius `r`, which
/// equals `sqrt(1 - |d|^2)` up to rounding (`|d| = |r| (cos^2 + sin^2)^(1/2)`)
/// and does not wait for the sine and cosine.
#[inline]
pub fn sample_cosine_hemisphere(u: Vec2) -> Vec3 {
    let (d, r) = concentric_disk_polar(u);
    let z = (1.0 - r * r).max(0.0).sqrt();
    Vec3::new(d.x, d.y, z)
}

/// [`sample_cosine_hemisphere`] on plain `f32`s with plain selects: the
/// same numbers, bit for bit, in a form that a loop over lanes
/// vectorises (the lock-step path tracer draws eight at once).
#[inline(always)]
pub fn sample_cosine_hemisphere_xyz(ux: f32, uy: f32) -> [f32; 3] {
    let (ox, oy) = (2.0 * ux - 1.0, 2.0 * uy - 1.0);
    let x_wedge = ox.abs() > oy.abs();
    let (r, a) = if x_wedge { (ox, oy) } else { (oy, ox) };
    let ratio = if r == 0.0 { 0.0 } else { a / r };
    let (s, c) = sin_cos_quarter(FRAC_PI_4 * ratio);
    let (rc, rs) = (r * c, r * s);
    let (dx, dy) = if x_wedge { (rc, rs) } else { (rs, rc) };
    [dx, dy, (1.0 - r * r).max(0.0).sqrt()]
}

/// [`sample_uniform_triangle`] on plain `f32`s, as
/// [`sample_cosine_hemisphere_xyz`] is to its vector form.
#[inline(always)]
pub fn sample_uniform_triangle_xy(ux: f32, uy: f32) -> [f32; 2] {
    let half = if ux < uy { ux } else { uy } * 0.5;
    [
        if ux < uy { half } else { ux - half },
        if uy < ux { half } else { uy - half },
    ]
}

/// Pdf (per solid angle) of [`sample_cosine_hemisphere`]: `cos_theta / pi`.
#[inline]
pub fn cosine_hemisphere_pdf(cos_theta: f32) -> f32 {
    cos_theta.max(0.0) * FRAC_1_PI
}

/// Uniform direction on the unit sphere.
pub fn sample_uniform_sphere(u: Vec2) -> Vec3 {
    unit_vector_at_height(1.0 - 2.0 * u.x, u.y)
}

/// The unit vector at height `z` (in `[-1, 1]`) and azimuth `2 pi v`.
#[inline]
fn unit_vector_at_height(z: f32, v: f32) -> Vec3 {
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = 2.0 * PI * v;
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

/// Pdf (per solid angle) of [`sample_uniform_sphere`]: `1 / (4 pi)`.
#[inline]
pub fn uniform_sphere_pdf() -> f32 {
    0.25 * FRAC_1_PI
}

/// Uniform direction on the hemisphere about +z.
pub fn sample_uniform_hemisphere(u: Vec2) -> Vec3 {
    unit_vector_at_height(u.x, u.y)
}

/// Pdf (per solid angle) of [`sample_uniform_hemisphere`]: `1 / (2 pi)`.
#[inline]
pub fn uniform_hemisphere_pdf() -> f32 {
    0.5 * FRAC_1_PI
}

/// Uniform barycentrics `(b0, b1)` on a triangle (b2 = 1 - b0 - b1),
/// Heitz 2019's low-distortion map: the smaller coordinate is halved and
/// the other reduced by that half (`x < y`: `(x / 2, y - x / 2)`, else
/// `(x - y / 2, y / 2)`).
///
/// Branch-free, as [`sample_concentric_disk`] and for the same reason (the
/// comparison is a coin flip): each lane picks the half or the reduced
/// coordinate by its own comparison, through SIMD blends. At `x == y` both
/// lanes take the reduced value, `x - x / 2 = x / 2` exactly.
#[inline]
pub fn sample_uniform_triangle(u: Vec2) -> Vec2 {
    let x_smaller = Vec4::splat(u.x).cmplt(Vec4::splat(u.y));
    let half = Vec4::select(x_smaller, Vec4::splat(u.x), Vec4::splat(u.y)) * 0.5;
    let xy = Vec4::new(u.x, u.y, 0.0, 0.0);
    let smaller = xy.cmplt(Vec4::new(u.y, u.x, 0.0, 0.0));
    let b = Vec4::select(smaller, half, xy - half);
    Vec2::new(b.x, b.y)
}

/// Direction about +z distributed as the Phong lobe `(cos)^n`:
/// pdf `(n + 1) / (2 pi) cos^n`.
pub fn sample_phong_lobe(u: Vec2, n: f32) -> Vec3 {
    let cos_t = u.x.powf(1.0 / (n + 1.0));
    let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
    let phi = 2.0 * PI * u.y;
    Vec3::new(sin_t * phi.cos(), sin_t * phi.sin(), cos_t)
}

/// Pdf (per solid angle) of [`sample_phong_lobe`].
#[inline]
pub fn phong_lobe_pdf(cos_t: f32, n: f32) -> f32 {
    if cos_t <= 0.0 {
        0.0
    } else {
        (n + 1.0) * 0.5 * FRAC_1_PI * cos_t.powf(n)
    }
}

/// The power heuristic with beta = 2 (Veach 1997) for MIS.
#[inline]
pub fn power_heuristic(pdf_f: f32, pdf_g: f32) -> f32 {
    let (f, g) = (pdf_f * pdf_f, pdf_g * pdf_g);
    if f + g == 0.0 { 0.0 } else { f / (f + g) }
}

/// A piecewise-constant density on `[0, 1)` over `n` equal cells (pbrt-v4's
/// `PiecewiseConstant1D`): cell `i` is drawn with probability
/// `f_i / sum(f)`, uniformly within it. Negative and non-finite values
/// count as zero; all zero (or none) is `None`.
#[derive(Debug, Clone, PartialEq)]
pub struct PiecewiseConstant1D {
    /// The (cleaned) values.
    func: Vec<f32>,
    /// `n + 1` entries from 0 to 1.
    cdf: Vec<f32>,
    /// `n + 1` entries: `guide[b]` counts the cdf entries at most `b / n`,
    /// which brackets the search of a `u` near `b / n` (a guide table,
    /// Chen and Asau 1974; Devroye 1986, ch. III.2.4).
    guide: Vec<u32>,
    /// `sum(f) / n`, the function's integral over `[0, 1)`.
    integral: f32,
}

impl PiecewiseConstant1D {
    /// The distribution proportional to `func`.
    pub fn new(func: &[f32]) -> Option<Self> {
        let func: Vec<f32> = func
            .iter()
            .map(|&f| if f.is_finite() && f > 0.0 { f } else { 0.0 })
            .collect();
        let n = func.len();
        // Accumulated in f64: a 1k-wide row of small values keeps its ratios.
        let mut acc = 0.0f64;
        let mut sums = Vec::with_capacity(n + 1);
        sums.push(0.0f64);
        for &f in &func {
            acc += f64::from(f);
            sums.push(acc);
        }
        if !(acc > 0.0 && acc.is_finite()) {
            return None;
        }
        let mut cdf: Vec<f32> = sums.iter().map(|&c| (c / acc) as f32).collect();
        cdf[n] = 1.0;
        let guide = (0..=n)
            .map(|b| cdf.partition_point(|&c| c <= b as f32 / n as f32) as u32)
            .collect();
        Some(Self {
            func,
            cdf,
            guide,
            integral: (acc / n as f64) as f32,
        })
    }

    /// Number of cells.
    pub fn len(&self) -> usize {
        self.func.len()
    }

    /// True when there are no cells (never: `new` refuses them).
    pub fn is_empty(&self) -> bool {
        self.func.is_empty()
    }

    /// The integral of the function over `[0, 1)`.
    pub fn integral(&self) -> f32 {
        self.integral
    }

    /// A point for the uniform number `u` in `[0, 1)`: `(x, pdf, cell)`,
    /// `x` in `[0, 1]`, and its density `f_cell / integral`. The cell found
    /// is the last one whose cdf is at most `u`, so it has positive
    /// probability.
    #[inline]
    pub fn sample(&self, u: f32) -> (f32, f32, usize) {
        let n = self.func.len();
        let i = self.count_at_most(u).saturating_sub(1).min(n - 1);
        let width = self.cdf[i + 1] - self.cdf[i];
        let du = if width > 0.0 {
            ((u - self.cdf[i]) / width).clamp(0.0, 1.0)
        } else {
            0.5
        };
        let x = ((i as f32 + du) / n as f32).min(1.0);
        (x, self.func[i] / self.integral, i)
    }

    /// The number of cdf entries at most `u` (`partition_point`), searched
    /// between the guide entries two buckets either side of `u`'s: `u` lies
    /// strictly between those buckets' bounds whatever the rounding of
    /// `u n` and `b / n`, so the count is the same as the full search's.
    #[inline]
    fn count_at_most(&self, u: f32) -> usize {
        let n = self.func.len();
        if u.is_nan() || u < 0.0 {
            // (Below 0 or NaN: no entry, as the full search finds.)
            return self.cdf.partition_point(|&c| c <= u);
        }
        let b = (u * n as f32) as usize;
        let lo = self.guide[b.saturating_sub(2).min(n)] as usize;
        let hi = self.guide[(b + 2).min(n)] as usize;
        lo + self.cdf[lo..hi].partition_point(|&c| c <= u)
    }

    /// The density at `x` (`x` outside `[0, 1]` is clamped to its cell).
    #[inline]
    pub fn pdf(&self, x: f32) -> f32 {
        self.func[self.cell(x)] / self.integral
    }

    /// The cell holding `x`.
    #[inline]
    pub fn cell(&self, x: f32) -> usize {
        cell(x, self.func.len())
    }
}

/// The cell of `n` equal cells on `[0, 1)` holding `x` (`x` outside is
/// clamped to the first or last).
#[inline(always)]
fn cell(x: f32, n: usize) -> usize {
    let i = (x * n as f32).floor();
    if i.is_nan() || i < 0.0 {
        0
    } else {
        (i as usize).min(n - 1)
    }
}

/// A piecewise-constant density on `[0, 1)^2` over a `width x height`
/// grid (pbrt-v4's `PiecewiseConstant2D`): a row by the marginal of the
/// row sums, then a column by that row's conditional distribution.
#[derive(Debug, Clone, PartialEq)]
pub struct PiecewiseConstant2D {
    /// One distribution per row that has positive values (`None` for the others).
    rows: Vec<Option<PiecewiseConstant1D>>,
    marginal: PiecewiseConstant1D,
    /// [`Self::pdf`] of each cell, row-major: one read where the row's
    /// and the marginal's tables would be read one after the other.
    cell_pdf: Vec<f32>,
}

impl PiecewiseConstant2D {
    /// The distribution proportional to `func` (row-major, `width` values
    /// per row, `func.len() / width` rows); `None` when nothing is positive.
    pub fn new(func: &[f32], width: usize) -> Option<Self> {
        if width == 0 || func.is_empty() || !func.len().is_multiple_of(width) {
            return None;
        }
        let rows: Vec<Option<PiecewiseConstant1D>> = func
            .chunks_exact(width)
            .map(PiecewiseConstant1D::new)
            .collect();
        let sums: Vec<f32> = rows
            .iter()
            .map(|r| r.as_ref().map_or(0.0, PiecewiseConstant1D::integral))
            .collect();
        let marginal = PiecewiseConstant1D::new(&sums)?;
        // The row's density times the row's, as `pdf` multiplies them.
        let cell_pdf = rows
            .iter()
            .enumerate()
            .flat_map(|(y, r)| {
                let pdf_y = marginal.func[y] / marginal.integral;
                (0..width).map(move |x| match r {
                    Some(r) => r.func[x] / r.integral * pdf_y,
                    None => 0.0,
                })
            })
            .collect();
        Some(Self {
            rows,
            marginal,
            cell_pdf,
        })
    }

    /// A point `(x, y)` for the uniform pair `u` and its density on the
    /// unit square.
    #[inline]
    pub fn sample(&self, u: Vec2) -> (Vec2, f32) {
        let (x, y, pdf) = self.sample_lanes(&[u.x], &[u.y], &[true]);
        (Vec2::new(x[0], y[0]), pdf[0])
    }

    /// [`Self::sample`] of the pairs `(u0[i], u1[i])` of the lanes set in
    /// `m` (zeros in the others) as `(x, y, pdf)`: every lane's row first,
    /// then every lane's column, so that the lanes' searches overlap
    /// rather than wait on one another; each lane's bits what one lane
    /// alone gets.
    #[inline(always)]
    pub fn sample_lanes<const N: usize>(
        &self,
        u0: &[f32; N],
        u1: &[f32; N],
        m: &[bool; N],
    ) -> ([f32; N], [f32; N], [f32; N]) {
        let (mut x, mut y, mut pdf) = ([0.0; N], [0.0; N], [0.0; N]);
        let mut row = [0usize; N];
        for i in 0..N {
            if m[i] {
                (y[i], pdf[i], row[i]) = self.marginal.sample(u1[i]);
            }
        }
        for i in 0..N {
            if !m[i] {
                continue;
            }
            // (The marginal never picks a row of zeros.)
            match &self.rows[row[i]] {
                Some(r) => {
                    let (xi, pdf_x, _) = r.sample(u0[i]);
                    (x[i], pdf[i]) = (xi, pdf_x * pdf[i]);
                }
                None => (x[i], pdf[i]) = (u0[i], 0.0),
            }
        }
        (x, y, pdf)
    }

    /// The density at `p` on the unit square: the row's density times the
    /// marginal's, read from one table.
    #[inline]
    pub fn pdf(&self, p: Vec2) -> f32 {
        let row = self.marginal.cell(p.y);
        let width = self.cell_pdf.len() / self.marginal.len();
        self.cell_pdf[row * width + cell(p.x, width)]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The 1D and 2D piecewise-constant densities integrate to 1, give a
    /// cell its share, agree between `sample` and `pdf`, and skip zeros.
    #[test]
    fn the_guided_search_counts_what_the_full_search_counts() {
        // Spiky, flat, zero-padded and tiny distributions; numbers on a
        // dense grid, at every cdf entry and its neighbours, and outside.
        let mut rng = pixel_rng(4, 3, 2, 1);
        let spiky: Vec<f32> = (0..257)
            .map(|i| {
                if i % 61 == 3 {
                    1e4
                } else {
                    rng.random::<f32>() * 1e-3
                }
            })
            .collect();
        let funcs = [
            spiky,
            vec![1.0; 100],
            vec![0.0, 0.0, 5.0, 0.0, 0.0, 0.0, 1.0, 0.0],
            vec![2.0],
            (0..1000).map(|i| ((i * 37) % 11) as f32).collect(),
        ];
        for f in &funcs {
            let d = PiecewiseConstant1D::new(f).expect("positive");
            let full = |u: f32| d.cdf.partition_point(|&c| c <= u);
            let mut us: Vec<f32> = (0..=100_000).map(|k| k as f32 / 100_000.0).collect();
            for &c in &d.cdf {
                us.extend([c, c.next_down(), c.next_up()]);
            }
            us.extend([-1.0, -0.0, 1.0, 2.0, f32::NAN, 1.0f32.next_down()]);
            for u in us {
                assert_eq!(d.count_at_most(u), full(u), "u = {u}, {} cells", f.len());
            }
        }
    }

    #[test]
    fn the_cell_table_holds_the_row_times_the_marginal_and_lanes_sample_alike() {
        // `PiecewiseConstant2D::pdf` reads the product the two densities
        // give, bit for bit (zero rows, points outside the square); its
        // lanes sample what one lane samples.
        let mut rng = pixel_rng(1, 2, 3, 4);
        let func: Vec<f32> = (0..37 * 11)
            .map(|i| {
                if (i / 37) % 4 == 2 {
                    0.0
                } else {
                    rng.random::<f32>()
                }
            })
            .collect();
        let d = PiecewiseConstant2D::new(&func, 37).expect("positive");
        for k in 0..20_000 {
            let p = Vec2::new(rng.random::<f32>(), rng.random::<f32>()) * 1.2 - 0.1;
            let p = if k == 0 { Vec2::NAN } else { p };
            let row = d.marginal.cell(p.y);
            let want = match &d.rows[row] {
                Some(r) => r.pdf(p.x) * d.marginal.pdf(p.y),
                None => 0.0,
            };
            assert_eq!(d.pdf(p).to_bits(), want.to_bits(), "{p}");
        }
        let u0: [f32; 16] = std::array::from_fn(|_| rng.random());
        let u1: [f32; 16] = std::array::from_fn(|_| rng.random());
        let m: [bool; 16] = std::array::from_fn(|i| i % 3 != 1);
        let (x, y, pdf) = d.sample_lanes(&u0, &u1, &m);
        for i in 0..16 {
            let (uv, p) = if m[i] {
                d.sample(Vec2::new(u0[i], u1[i]))
            } else {
                (Vec2::ZERO, 0.0)
            };
            assert_eq!(
                [x[i], y[i], pdf[i]].map(f32::to_bits),
                [uv.x, uv.y, p].map(f32::to_bits)
            );
        }
    }

    #[test]
    fn piecewise_constant_densities() {
        assert!(PiecewiseConstant1D::new(&[0.0, -1.0, f32::NAN]).is_none());
        let d = PiecewiseConstant1D::new(&[1.0, 0.0, 3.0, 0.0]).expect("positive");
        assert!((d.integral() - 1.0).abs() < 1e-6);
        // Cell 2 holds 3/4 of the mass: u in [0.25, 1) lands there.
        let (x, pdf, i) = d.sample(0.5);
        assert_eq!(i, 2);
        assert!((x - (2.0 + 1.0 / 3.0) / 4.0).abs() < 1e-6, "{x}");
        assert!((pdf - 3.0).abs() < 1e-6 && (d.pdf(x) - pdf).abs() < 1e-6);
        // u at a cdf step shared by an empty cell skips the empty cell.
        assert_eq!(d.sample(0.25).2, 2);
        assert_eq!(d.sample(0.0).2, 0);
        assert_eq!(d.sample(0.999_999_9).2, 2);
        let func: Vec<f32> = (0..6 * 4).map(|i| ((i * 7) % 5) as f32).collect();
        let d2 = PiecewiseConstant2D::new(&func, 6).expect("positive");
        // The pdf's midpoint integral over the cells, and sample's pdf.
        let mut total = 0.0;
        for y in 0..4 {
            for x in 0..6 {
                let p = Vec2::new((x as f32 + 0.5) / 6.0, (y as f32 + 0.5) / 4.0);
                let pdf = d2.pdf(p);
                total += pdf / 24.0;
                let sum: f32 = func.iter().sum();
                assert!((pdf - func[y * 6 + x] * 24.0 / sum).abs() < 1e-5);
            }
        }
        assert!((total - 1.0).abs() < 1e-5, "{total}");
        let mut rng = pixel_rng(1, 2, 3, 4);
        for _ in 0..1000 {
            let (p, pdf) = d2.sample(uniform2(&mut rng));
            assert!(
                pdf > 0.0 && (d2.pdf(p) - pdf).abs() <= 1e-4 * pdf,
                "{p} {pdf}"
            );
        }
    }

    #[test]
    fn rng_is_deterministic_per_pixel() {
        let a: Vec<f32> = {
            let mut r = pixel_rng(7, 3, 4, 0);
            (0..4).map(|_| uniform(&mut r)).collect()
        };
        let b: Vec<f32> = {
            let mut r = pixel_rng(7, 3, 4, 0);
            (0..4).map(|_| uniform(&mut r)).collect()
        };
        let c: Vec<f32> = {
            let mut r = pixel_rng(7, 4, 3, 0);
            (0..4).map(|_| uniform(&mut r)).collect()
        };
        assert_eq!(a, b);
        assert_ne!(a, c);
        assert!(a.iter().all(|&x| (0.0..1.0).contains(&x)));
    }

    #[test]
    fn warps_land_on_their_shapes() {
        let mut r = pixel_rng(1, 0, 0, 0);
        for _ in 0..1000 {
            let u = uniform2(&mut r);
            assert!(sample_concentric_disk(u).length() <= 1.0 + 1e-6);
            let h = sample_cosine_hemisphere(u);
            assert!(h.z >= 0.0 && (h.length() - 1.0).abs() < 1e-5);
            assert!((sample_uniform_sphere(u).length() - 1.0).abs() < 1e-5);
            let b = sample_uniform_triangle(u);
            assert!(b.x >= 0.0 && b.y >= 0.0 && b.x + b.y <= 1.0 + 1e-6);
        }
    }

    #[test]
    fn plain_float_warps_equal_the_vector_ones() {
        let mut r = pixel_rng(4, 0, 0, 0);
        let edges = [0.0, 0.25, 0.5, 0.75, 1.0 - f32::EPSILON];
        let grid = edges
            .iter()
            .flat_map(|&x| edges.iter().map(move |&y| Vec2::new(x, y)));
        for u in (0..100_000).map(|_| uniform2(&mut r)).chain(grid) {
            let h = sample_cosine_hemisphere(u);
            assert_eq!(sample_cosine_hemisphere_xyz(u.x, u.y), h.to_array(), "{u}");
            let b = sample_uniform_triangle(u);
            assert_eq!(sample_uniform_triangle_xy(u.x, u.y), b.to_array(), "{u}");
        }
    }

    #[test]
    fn quarter_sin_cos_matches_the_library() {
        for i in -1000..=1000 {
            let a = FRAC_PI_4 * i as f32 / 1000.0;
            let (s, c) = sin_cos_quarter(a);
            let (s0, c0) = a.sin_cos();
            assert!(
                (s - s0).abs() <= 2.0 * f32::EPSILON * s0.abs().max(0.1),
                "sin {a}: {s} vs {s0}"
            );
            assert!((c - c0).abs() <= 2.0 * f32::EPSILON, "cos {a}: {c} vs {c0}");
        }
    }

    #[test]
    fn concentric_disk_matches_its_polar_definition() {
        // Shirley and Chiu's map with the library's sin/cos, both wedges.
        let reference = |u: Vec2| {
            let o = 2.0 * u - Vec2::ONE;
            let (r, theta) = if o.x.abs() > o.y.abs() {
                (o.x, FRAC_PI_4 * (o.y / o.x))
            } else {
                (o.y, std::f32::consts::FRAC_PI_2 - FRAC_PI_4 * (o.x / o.y))
            };
            Vec2::new(r * theta.cos(), r * theta.sin())
        };
        let mut r = pixel_rng(2, 0, 0, 0);
        for _ in 0..10_000 {
            let u = uniform2(&mut r);
            let (a, b) = (sample_concentric_disk(u), reference(u));
            assert!((a - b).abs().max_element() < 4e-7, "{u}: {a} vs {b}");
        }
        assert_eq!(sample_concentric_disk(Vec2::splat(0.5)), Vec2::ZERO);
    }

    #[test]
    fn uniform_triangle_matches_heitz_map() {
        // The branching form of Heitz 2019's map, bit for bit (ties included).
        let reference = |u: Vec2| {
            if u.x < u.y {
                let b0 = u.x / 2.0;
                Vec2::new(b0, u.y - b0)
            } else {
                let b1 = u.y / 2.0;
                Vec2::new(u.x - b1, b1)
            }
        };
        let mut r = pixel_rng(3, 0, 0, 0);
        let ties = [
            Vec2::ZERO,
            Vec2::splat(0.5),
            Vec2::splat(0.75),
            Vec2::new(0.0, 0.5),
        ];
        for u in (0..10_000).map(|_| uniform2(&mut r)).chain(ties) {
            assert_eq!(sample_uniform_triangle(u), reference(u), "{u}");
        }
    }

    #[test]
    fn cosine_hemisphere_mean_cos_is_two_thirds() {
        // E[cos] under pdf cos/pi is 2/3.
        let k = 256;
        let mut s = 0.0;
        for i in 0..k {
            for j in 0..k {
                let u = Vec2::new((i as f32 + 0.5) / k as f32, (j as f32 + 0.5) / k as f32);
                s += sample_cosine_hemisphere(u).z;
            }
        }
        assert!((s / (k * k) as f32 - 2.0 / 3.0).abs() < 1e-3);
    }
}
