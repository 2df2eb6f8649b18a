//! A low-discrepancy pixel sampler: shuffled, Owen-scrambled Sobol points,
//! padded two dimensions at a time (Burley 2020, "Practical Hash-based Owen
//! Scrambling", JCGT 9(4); the `ZSobolSampler`/`PaddedSobolSampler` of
//! pbrt-v4 `util/lowdiscrepancy.h` follow the same recipe).
//!
//! The `n` samples of one pixel draw their `k`-th pair of numbers from the
//! first two dimensions of the Sobol sequence, a (0, 2)-sequence: any `2^m`
//! consecutive points put exactly one point in each of the `2^m` elementary
//! rectangles of every shape, so a pixel's samples stratify each pair (the
//! camera jitter, a light sample, a BSDF sample) jointly. Each pair gets its
//! own random permutation of the sample order (the shuffle, so pairs are not
//! correlated with each other) and its own nested uniform (Owen) scrambling
//! of both coordinates, keyed by the pixel, the pair and the scene seed. An
//! Owen-scrambled point is uniformly distributed on the unit square, so
//! every estimate stays unbiased; its variance falls faster than `1 / n`
//! where the integrand is smooth in the pair.

use super::mix64;
use glam::Vec2;

/// Draws the numbers of one sample of one pixel (see the module doc).
/// Results depend only on the seed, the pixel, the sample index, the
/// number of samples and the order of the draws, never on threads or tiles.
/// [`SobolSampler::set_sample`] moves it to another sample of the same
/// pixel, reusing the scramble keys it has hashed (they depend on the pixel
/// and the pair, not on the sample).
#[derive(Debug, Clone)]
pub struct SobolSampler {
    /// The scene seed.
    seed: u64,
    /// Hash of the scene seed and the pixel (the same for all its samples).
    pixel: u64,
    /// The sample's index among the pixel's samples, bit-reversed (the
    /// shuffle's first step, done once).
    index_reversed: u32,
    /// `2^m - 1` for the smallest `2^m >= ` the pixel's sample count: the
    /// shuffle permutes indices within `[0, 2^m)`.
    mask: u32,
    /// Pairs drawn so far.
    dim: u32,
    /// The keys of pairs `0..keys.len()`, hashed on first use.
    keys: Vec<PairKeys>,
}

/// The hash of the scene seed and pixel `(x, y)` that keys its pairs.
#[inline]
fn pixel_hash(seed: u64, x: u32, y: u32) -> u64 {
    mix64(seed ^ mix64((u64::from(x) << 32) | u64::from(y)) ^ 0x5EB0_1D00)
}

/// The scramble keys of one dimension pair of one pixel.
#[derive(Debug, Clone, Copy)]
struct PairKeys {
    /// Seeds the shuffle of the sample index.
    shuffle: u32,
    /// Seed the Owen scrambling of the first and second coordinate.
    x: u32,
    y: u32,
}

impl PairKeys {
    /// The keys of pair `dim` of the pixel hashed to `pixel`.
    fn new(pixel: u64, dim: u32) -> Self {
        let key = mix64(pixel ^ u64::from(dim).wrapping_mul(0x9E37_79B9_7F4A_7C15));
        Self {
            shuffle: key as u32,
            x: (key >> 32) as u32,
            y: mix64(key) as u32,
        }
    }
}

impl SobolSampler {
    /// The sampler of sample `index` of the `count` samples of pixel
    /// `(x, y)` under `seed`.
    pub fn new(seed: u64, x: u32, y: u32, index: u32, count: u32) -> Self {
        Self {
            seed,
            pixel: pixel_hash(seed, x, y),
            index_reversed: index.reverse_bits(),
            mask: count.max(1).next_power_of_two().wrapping_sub(1),
            dim: 0,
            keys: Vec::new(),
        }
    }

    /// Moves to sample 0 of pixel `(x, y)` (same seed and sample count):
    /// the numbers are those of `SobolSampler::new(seed, x, y, 0, count)`;
    /// the key cache keeps its memory.
    #[inline]
    pub fn set_pixel(&mut self, x: u32, y: u32) {
        self.pixel = pixel_hash(self.seed, x, y);
        self.keys.clear();
        self.set_sample(0);
    }

    /// Restarts at the first pair for sample `index` of the same pixel:
    /// the numbers are those of `SobolSampler::new(seed, x, y, index,
    /// count)`, without hashing again the keys of pairs drawn before.
    #[inline]
    pub fn set_sample(&mut self, index: u32) {
        self.index_reversed = index.reverse_bits();
        self.dim = 0;
    }

    /// The keys of the next dimension pair.
    #[inline]
    fn next_keys(&mut self) -> PairKeys {
        let d = self.dim;
        self.dim += 1;
        self.keys_at(d)
    }

    /// Hashes the keys of every pair up to `dim` not yet known (pairs that
    /// [`Self::skip`] passed over included) and returns those of `dim`.
    #[cold]
    fn hash_keys(&mut self, dim: u32) -> PairKeys {
        while self.keys.len() <= dim as usize {
            let k = PairKeys::new(self.pixel, self.keys.len() as u32);
            self.keys.push(k);
        }
        self.keys[dim as usize]
    }

    /// The shuffled sample index of the next dimension pair, and the keys
    /// that scramble its two coordinates. The shuffle is a nested uniform
    /// scramble of the index: for indices below `2^m` its bits from `m` up
    /// are one constant, so masking them leaves a permutation of `[0, 2^m)`
    /// (and keeps the Sobol loop short).
    #[inline]
    fn next_pair(&mut self) -> (u32, PairKeys) {
        let keys = self.next_keys();
        // Nested uniform (Owen) scrambling of the index as a 32-bit
        // fraction: reverse(LK(reverse(index))), each bit flipped depending
        // on the bits above it (Burley 2020, listing 3); the first reversal
        // is done once per sample.
        (
            shuffled_index(self.index_reversed, keys.shuffle, self.mask),
            keys,
        )
    }

    /// The next pair of numbers in `[0, 1)^2` (one fresh dimension pair).
    #[inline]
    pub fn next_2d(&mut self) -> Vec2 {
        let (i, key) = self.next_pair();
        // Owen scrambling of Sobol's first dimension (the bit reversal of
        // i): reverse(LK(reverse(reverse(i)))) = reverse(LK(i)).
        let x = laine_karras(i, key.x);
        // Below 256 samples the index has one byte: one table look-up.
        let second = if self.mask <= 0xff {
            SECOND_BY_BYTE[0][(i & 0xff) as usize]
        } else {
            sobol_second_reversed(i)
        };
        let y = laine_karras(second, key.y);
        // Both reversals in one: reversing `x << 32 | y` puts reverse(x) in
        // the low half and reverse(y) in the high half.
        let r = ((u64::from(x) << 32) | u64::from(y)).reverse_bits();
        Vec2::new(to_unit(r as u32), to_unit((r >> 32) as u32))
    }

    /// The next number in `[0, 1)` (the first coordinate of a fresh pair:
    /// a scrambled van der Corput sequence, stratified in one dimension).
    #[inline]
    pub fn next_1d(&mut self) -> f32 {
        let (i, key) = self.next_pair();
        to_unit(laine_karras(i, key.x).reverse_bits())
    }

    /// Skips `pairs` dimension pairs exactly as drawing and discarding
    /// them would, without computing them: a caller whose decision needs
    /// no number (a single lobe or light to choose) keeps the numbers of
    /// every later decision unchanged.
    #[inline]
    pub fn skip(&mut self, pairs: u32) {
        self.dim += pairs;
    }

    /// The bit-reversed indices of samples `first..first + LANES` of the
    /// current pixel, for [`Self::lanes_2d`] and [`Self::lanes_1d`].
    #[inline]
    pub fn lane_indices(first: u32) -> [u32; LANES] {
        std::array::from_fn(|i| first.wrapping_add(i as u32).reverse_bits())
    }

    /// Pair `dim` of [`LANES`] samples of the current pixel at once, lane
    /// `i` for the sample whose reversed index is `rev[i]`: exactly what
    /// `set_sample(index); skip(dim); next_2d()` draws for it. The lanes
    /// share the pair's keys, so a pixel's samples traced in lock-step
    /// draw their numbers in one vectorised loop. Leaves the scalar state
    /// (the current sample and its pair count) alone.
    #[inline]
    pub fn lanes_2d(&mut self, dim: u32, rev: &[u32; LANES]) -> [[f32; LANES]; 2] {
        let keys = self.keys_at(dim);
        let index = lane_indices_shuffled(rev, keys.shuffle, self.mask);
        // The second dimension by word operations (a table look-up per
        // lane would not vectorise).
        let second = index.map(second_by_taylor_shift);
        let mut out = [[0.0; LANES]; 2];
        for i in 0..LANES {
            out[0][i] = to_unit(laine_karras(index[i], keys.x).reverse_bits());
            out[1][i] = to_unit(laine_karras(second[i], keys.y).reverse_bits());
        }
        out
    }

    /// The first number of pair `dim` for [`LANES`] samples at once (as
    /// [`Self::lanes_2d`]): what `next_1d` draws for each.
    #[inline]
    pub fn lanes_1d(&mut self, dim: u32, rev: &[u32; LANES]) -> [f32; LANES] {
        let keys = self.keys_at(dim);
        let index = lane_indices_shuffled(rev, keys.shuffle, self.mask);
        let mut out = [0.0; LANES];
        for (o, &i) in out.iter_mut().zip(&index) {
            *o = to_unit(laine_karras(i, keys.x).reverse_bits());
        }
        out
    }

    /// [`Self::lanes_2d`] with a pair of its own per lane: lane `i` draws
    /// pair `dims[i]` (what `set_sample(index); skip(dims[i]); next_2d()`
    /// draws for it), for lanes whose paths have drawn different counts of
    /// numbers. Each lane gathers its pair's keys; the rest is the same
    /// lane loop.
    #[inline]
    pub fn lanes_2d_at(&mut self, dims: &[u32; LANES], rev: &[u32; LANES]) -> [[f32; LANES]; 2] {
        let (shuffle, kx, ky) = self.keys_of(dims);
        let mut out = [[0.0; LANES]; 2];
        for i in 0..LANES {
            let index = laine_karras(rev[i], shuffle[i]).reverse_bits() & self.mask;
            let second = second_by_taylor_shift(index);
            out[0][i] = to_unit(laine_karras(index, kx[i]).reverse_bits());
            out[1][i] = to_unit(laine_karras(second, ky[i]).reverse_bits());
        }
        out
    }

    /// The first number of pair `dims[i]` for lane `i` (as
    /// [`Self::lanes_2d_at`]): what `next_1d` draws for each.
    #[inline]
    pub fn lanes_1d_at(&mut self, dims: &[u32; LANES], rev: &[u32; LANES]) -> [f32; LANES] {
        let (shuffle, kx, _) = self.keys_of(dims);
        let mut out = [0.0; LANES];
        for i in 0..LANES {
            let index = laine_karras(rev[i], shuffle[i]).reverse_bits() & self.mask;
            out[i] = to_unit(laine_karras(index, kx[i]).reverse_bits());
        }
        out
    }

    /// The keys of pair `dims[i]` per lane, as three arrays (shuffle, x, y),
    /// every pair up to the largest hashed first.
    #[inline(always)]
    fn keys_of(&mut self, dims: &[u32; LANES]) -> ([u32; LANES], [u32; LANES], [u32; LANES]) {
        let top = dims.iter().copied().max().unwrap_or(0);
        self.keys_at(top);
        let keys = &self.keys;
        let at = |i: usize| keys.get(dims[i] as usize).copied();
        let key = |i: usize| {
            at(i).unwrap_or(PairKeys {
                shuffle: 0,
                x: 0,
                y: 0,
            })
        };
        let ks: [PairKeys; LANES] = std::array::from_fn(key);
        (ks.map(|k| k.shuffle), ks.map(|k| k.x), ks.map(|k| k.y))
    }

    /// The keys of pair `dim` (hashed on first use).
    #[inline]
    fn keys_at(&mut self, dim: u32) -> PairKeys {
        match self.keys.get(dim as usize) {
            Some(&k) => k,
            None => self.hash_keys(dim),
        }
    }
}

/// [`sobol_second_reversed`] in fifteen word operations and no table
/// (which a lane loop can vectorise). The direction numbers are the powers
/// `(1 + t)^k` over GF(2), bit `i` holding the coefficient of `t^i`, so
/// the result is the index read as a polynomial `X(t)` and evaluated at
/// `1 + t`. Splitting a block of `2h` coefficients as `A + t^h B`, with
/// both halves already shifted, `X(1 + t) = A' + (1 + t^h) B'` (`h` a power
/// of two): the high half stays and is added into the low half. (The
/// scalar draws keep the table: one look-up below 256 samples.)
#[inline(always)]
fn second_by_taylor_shift(mut x: u32) -> u32 {
    x ^= (x >> 1) & 0x5555_5555;
    x ^= (x >> 2) & 0x3333_3333;
    x ^= (x >> 4) & 0x0f0f_0f0f;
    x ^= (x >> 8) & 0x00ff_00ff;
    x ^= x >> 16;
    x
}

/// Samples drawn together by [`SobolSampler::lanes_2d`], and so the path
/// tracer's lock-step batch. Sixteen: an AVX-512 build that allows 512-bit
/// vectors (`-C target-feature=-prefer-256-bit`; ARCHITECTURE.md, "Target
/// CPU") runs each lane loop as one instruction; on AVX2 the loops are two
/// 256-bit halves, no slower than eight lanes (BENCHMARKS.md, "Path tracing
/// vs Mitsuba 3").
pub const LANES: usize = 16;

/// [`shuffled_index`] per lane, with the full reversal (which vectorises;
/// the byte table gives the same low bits).
#[inline(always)]
fn lane_indices_shuffled(rev: &[u32; LANES], shuffle: u32, mask: u32) -> [u32; LANES] {
    let mut out = [0u32; LANES];
    for (o, &r) in out.iter_mut().zip(rev) {
        *o = laine_karras(r, shuffle).reverse_bits() & mask;
    }
    out
}

/// The shuffled sample index of [`SobolSampler::next_pair`]: the sample's
/// reversed index `rev` scrambled with `shuffle`, reduced by `mask`.
#[inline(always)]
fn shuffled_index(rev: u32, shuffle: u32, mask: u32) -> u32 {
    let z = laine_karras(rev, shuffle);
    // Only the low m bits of reverse(z) are kept: for m <= 8 they are
    // the top byte of z reversed, one table look-up.
    let shuffled = if mask <= 0xff {
        u32::from(REVERSED_BYTE[(z >> 24) as usize])
    } else {
        z.reverse_bits()
    };
    shuffled & mask
}

/// The top 24 bits of `x` as a number in `[0, 1)` (exact, never 1).
#[inline]
fn to_unit(x: u32) -> f32 {
    (x >> 8) as f32 * (1.0 / 16_777_216.0)
}

/// `REVERSED_BYTE[b] = b.reverse_bits()`.
static REVERSED_BYTE: [u8; 256] = {
    let mut t = [0u8; 256];
    let mut b = 0;
    while b < 256 {
        t[b] = (b as u8).reverse_bits();
        b += 1;
    }
    t
};

/// Direction numbers of the second dimension of the Sobol sequence,
/// bit-reversed (so bit `k` is the coefficient of `2^-(k+1)`): `v_1 = 1`,
/// `v_{k+1} = v_k ^ (v_k << 1)` in reversed order (the primitive
/// polynomial `x + 1`; the first dimension is the index itself reversed).
const fn second_directions() -> [u32; 32] {
    let mut v = [0u32; 32];
    let mut d = 1u32;
    let mut k = 0;
    while k < 32 {
        v[k] = d;
        d ^= d << 1;
        k += 1;
    }
    v
}

/// [`sobol_second_reversed`] by bytes of the index: entry `[b][x]` is the
/// XOR of the direction numbers of the set bits of byte value `x` in
/// byte `b` (4 KiB, built at compile time).
static SECOND_BY_BYTE: [[u32; 256]; 4] = {
    let v = second_directions();
    let mut t = [[0u32; 256]; 4];
    let mut b = 0;
    while b < 4 {
        let mut x = 0;
        while x < 256 {
            let mut r = 0u32;
            let mut j = 0;
            while j < 8 {
                if (x >> j) & 1 == 1 {
                    r ^= v[8 * b + j];
                }
                j += 1;
            }
            t[b][x] = r;
            x += 1;
        }
        b += 1;
    }
    t
};

/// The second dimension of the Sobol sequence at `index`, bit-reversed: the
/// XOR of the direction numbers of the index's set bits, four table
/// look-ups (the same value as the bit-by-bit loop of the tests'
/// `second_by_bits`).
#[inline]
fn sobol_second_reversed(index: u32) -> u32 {
    let t = &SECOND_BY_BYTE;
    let byte = |b: u32| ((index >> (8 * b)) & 0xff) as usize;
    t[0][byte(0)] ^ t[1][byte(1)] ^ t[2][byte(2)] ^ t[3][byte(3)]
}

/// Burley's hash-based Laine-Karras permutation: a random permutation of
/// 32-bit integers in which each bit depends only on the bits below it.
/// Applied to a bit-reversed fraction and reversed back, it is a nested
/// uniform (Owen) scramble of that fraction.
#[inline]
fn laine_karras(mut x: u32, seed: u32) -> u32 {
    x = x.wrapping_add(seed);
    x ^= x.wrapping_mul(0x6c50_b47c);
    x ^= x.wrapping_mul(0xb82f_1e52);
    x ^= x.wrapping_mul(0xc7af_e638);
    x ^= x.wrapping_mul(0x8d22_f6e6);
    x
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The second Sobol dimension, bit-reversed, one index bit at a time
    /// (the definition [`sobol_second_reversed`]'s tables tabulate).
    fn second_by_bits(mut index: u32) -> u32 {
        let (mut v, mut r) = (1u32, 0u32);
        while index != 0 {
            if index & 1 == 1 {
                r ^= v;
            }
            index >>= 1;
            v ^= v << 1;
        }
        r
    }

    #[test]
    fn taylor_shift_is_the_second_dimension() {
        // Every index below 2^20, then a spread of larger ones.
        let mut x = 0x9e37_79b9u32;
        let large = (0..100_000).map(|_| {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            x
        });
        for i in (0..1u32 << 20).chain(large).chain([u32::MAX, 1 << 31]) {
            let want = second_by_bits(i);
            assert_eq!(second_by_taylor_shift(i), want, "index {i:#x}");
            assert_eq!(sobol_second_reversed(i), want, "index {i:#x}");
        }
    }

    #[test]
    fn shuffle_by_byte_table_matches_the_full_reversal() {
        // Sample counts up to 256 take the table, larger ones the full
        // reversal: both must be the masked reverse(LK(reverse(index))).
        for count in [1u32, 3, 64, 200, 256, 257, 5000] {
            let mask = count.next_power_of_two() - 1;
            for index in (0..count).step_by(7) {
                let mut s = SobolSampler::new(5, 2, 8, index, count);
                for dim in 0..4 {
                    let k = PairKeys::new(s.pixel, dim);
                    let want = laine_karras(index.reverse_bits(), k.shuffle).reverse_bits() & mask;
                    assert_eq!(
                        s.next_pair().0,
                        want,
                        "count {count} index {index} dim {dim}"
                    );
                }
            }
        }
    }

    #[test]
    fn lanes_draw_what_each_sample_draws() {
        // Sample counts on both sides of the one-byte shortcuts, and indices
        // of one, two and three bytes.
        for count in [1, 5, 64, 256, 257, 300, 65_536, 70_000] {
            let mut lanes = SobolSampler::new(9, 4, 7, 0, count);
            lanes.set_pixel(4, 7);
            for first in [0, LANES as u32, count.saturating_sub(3), count / 2 + 1] {
                let rev = SobolSampler::lane_indices(first);
                for dim in [0, 1, 5, 17] {
                    let two = lanes.lanes_2d(dim, &rev);
                    let one = lanes.lanes_1d(dim, &rev);
                    for i in 0..LANES {
                        let mut s = SobolSampler::new(9, 4, 7, first + i as u32, count);
                        s.skip(dim);
                        let mut t = s.clone();
                        assert_eq!(s.next_2d(), glam::Vec2::new(two[0][i], two[1][i]));
                        assert_eq!(t.next_1d(), one[i]);
                    }
                }
            }
        }
    }

    #[test]
    fn lanes_at_their_own_pairs_draw_what_each_sample_draws() {
        for count in [5, 64, 300, 70_000] {
            let mut lanes = SobolSampler::new(9, 4, 7, 0, count);
            lanes.set_pixel(4, 7);
            for first in [0, LANES as u32, count / 2 + 1] {
                let rev = SobolSampler::lane_indices(first);
                for base in [0, 3, 17] {
                    let dims: [u32; LANES] = std::array::from_fn(|i| base + (i as u32 * 7) % 5);
                    let two = lanes.lanes_2d_at(&dims, &rev);
                    let one = lanes.lanes_1d_at(&dims, &rev);
                    for i in 0..LANES {
                        let mut s = SobolSampler::new(9, 4, 7, first + i as u32, count);
                        s.skip(dims[i]);
                        let mut t = s.clone();
                        assert_eq!(s.next_2d(), glam::Vec2::new(two[0][i], two[1][i]));
                        assert_eq!(t.next_1d(), one[i]);
                    }
                }
            }
        }
    }

    #[test]
    fn set_sample_draws_what_a_new_sampler_draws() {
        let mut reused = SobolSampler::new(4, 3, 1, 0, 16);
        reused.next_2d();
        reused.set_pixel(7, 9);
        for i in 0..16 {
            reused.set_sample(i);
            let mut fresh = SobolSampler::new(4, 7, 9, i, 16);
            // Skips of different lengths leave gaps in the key cache.
            for k in 0..12 {
                if (i + k) % 5 == 0 {
                    reused.skip(1 + k % 3);
                    fresh.skip(1 + k % 3);
                }
                assert_eq!(reused.next_2d(), fresh.next_2d(), "sample {i} draw {k}");
                assert_eq!(reused.next_1d(), fresh.next_1d(), "sample {i} draw {k}");
            }
        }
    }

    #[test]
    fn second_dimension_tables_match_the_definition() {
        let mut x = 0x1234_5678u32;
        for i in (0..70_000u32).chain((0..10_000).map(|_| {
            x = x.wrapping_mul(747_796_405).wrapping_add(2_891_336_453);
            x
        })) {
            assert_eq!(sobol_second_reversed(i), second_by_bits(i), "index {i}");
        }
    }

    /// Sobol's first two dimensions form a (0, 2)-sequence, and Owen
    /// scrambling keeps it one: every 2^m points of a pixel put one point
    /// in each elementary rectangle of area 2^-m, for every pair drawn.
    #[test]
    fn every_pair_is_a_zero_two_net() {
        for m in [2u32, 4, 6] {
            let n = 1u32 << m;
            for pair in 0..5 {
                let pts: Vec<Vec2> = (0..n)
                    .map(|i| {
                        let mut s = SobolSampler::new(9, 3, 5, i, n);
                        for _ in 0..pair {
                            s.next_2d();
                        }
                        s.next_2d()
                    })
                    .collect();
                for a in 0..=m {
                    let (nx, ny) = (1u32 << a, 1u32 << (m - a));
                    let mut cells = vec![0u32; n as usize];
                    for p in &pts {
                        let cx = (p.x * nx as f32) as u32;
                        let cy = (p.y * ny as f32) as u32;
                        cells[(cy * nx + cx) as usize] += 1;
                    }
                    assert!(
                        cells.iter().all(|&c| c == 1),
                        "m {m} pair {pair} cells {nx}x{ny}: {cells:?}"
                    );
                }
            }
        }
    }

    /// Over many pixels the draws are uniform: the mean of each coordinate
    /// is 1/2 and of its square 1/3, within a few standard errors, and
    /// different pairs are uncorrelated.
    #[test]
    fn draws_are_uniform_and_pairs_uncorrelated() {
        let (mut s1, mut s2, mut sxy, mut sab) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
        let mut count = 0.0f64;
        for px in 0..64 {
            for i in 0..16 {
                let mut s = SobolSampler::new(1, px, 7, i, 16);
                let a = s.next_2d();
                let b = s.next_2d();
                let c = s.next_1d();
                for v in [a.x, a.y, b.x, b.y, c] {
                    s1 += f64::from(v);
                    s2 += f64::from(v) * f64::from(v);
                    count += 1.0;
                }
                sxy += f64::from(a.x) * f64::from(a.y);
                sab += f64::from(a.x) * f64::from(b.x);
            }
        }
        let n = 64.0 * 16.0;
        assert!((s1 / count - 0.5).abs() < 0.01, "mean {}", s1 / count);
        assert!(
            (s2 / count - 1.0 / 3.0).abs() < 0.01,
            "second moment {}",
            s2 / count
        );
        // E[xy] = 1/4 for independent uniforms (sd of the mean ~ 0.0045).
        assert!((sxy / n - 0.25).abs() < 0.02, "x-y {}", sxy / n);
        assert!((sab / n - 0.25).abs() < 0.02, "pair-pair {}", sab / n);
    }

    /// Stratification pays: the error of estimating a smooth integral over
    /// the square with 64 points is far below independent sampling's.
    #[test]
    fn smooth_integral_converges_faster_than_random() {
        // f(x, y) = x y, integral 1/4; independent sampling's RMSE with 64
        // points is sqrt(7/144 / 64) ~ 0.0276.
        let mut err2 = 0.0f64;
        let pixels = 200u32;
        for px in 0..pixels {
            let mean: f64 = (0..64)
                .map(|i| {
                    let p = SobolSampler::new(3, px, 0, i, 64).next_2d();
                    f64::from(p.x) * f64::from(p.y)
                })
                .sum::<f64>()
                / 64.0;
            err2 += (mean - 0.25) * (mean - 0.25);
        }
        let rmse = (err2 / f64::from(pixels)).sqrt();
        assert!(rmse < 0.0276 / 5.0, "rmse {rmse}");
    }
}
