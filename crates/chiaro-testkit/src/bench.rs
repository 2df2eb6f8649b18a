//! What the benchmark examples share: process CPU time, medians, a
//! checksum of results, and the
//! ray workload of the BVH benchmarks (a pinhole camera over the icosphere
//! grid, as the Embree comparison traces it, and uniformly random rays),
//! and a film's pixels as 8-bit sRGB.

use chiaro_core::film::Film;
use chiaro_core::film::tonemap::linear_to_srgb8;
use chiaro_core::geometry::{Aabb, Ray};
use chiaro_core::sampling::{pixel_rng, sample_uniform_sphere, uniform, uniform2};
use glam::Vec3;

/// CPU time of this process so far, seconds: the sum of the run times in
/// `/proc/self/task/*/schedstat` (Linux). Unlike wall-clock time it does not
/// count time spent descheduled by other processes, so it is the steadier
/// figure on a shared machine. `None` where the files are unavailable.
pub fn cpu_seconds() -> Option<f64> {
    let mut total = 0u64;
    for e in std::fs::read_dir("/proc/self/task").ok()? {
        let s = std::fs::read_to_string(e.ok()?.path().join("schedstat")).ok()?;
        total += s.split_whitespace().next()?.parse::<u64>().ok()?;
    }
    Some(total as f64 * 1e-9)
}

/// Median of `v` (sorted in place); 0 for an empty slice.
pub fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(0.0)
}

/// `, cpu Cs -> R Mrays/s cpu-normalised` for `rays` rays that took `cpu`
/// CPU seconds (shown to `digits` decimals) on `threads` threads: the rate
/// had every thread had a core. Empty without a CPU time.
pub fn cpu_normalised_note(rays: usize, cpu: Option<f64>, threads: usize, digits: usize) -> String {
    cpu.map_or(String::new(), |c| {
        format!(
            ", cpu {c:.digits$}s -> {:.2} Mrays/s cpu-normalised",
            rays as f64 / (c / threads as f64) / 1e6
        )
    })
}

/// The BVH benchmarks' rays, `w * h` of each kind: coherent pinhole rays
/// from `(0, 0, 20)` looking down `-z` with `tan_half` the tangent of the
/// half field of view, row by row; and incoherent rays from uniform points
/// of `bounds` in uniform directions (seeded, the same on every run).
pub fn bvh_rays(w: usize, h: usize, tan_half: f32, bounds: &Aabb) -> (Vec<Ray>, Vec<Ray>) {
    let coherent = (0..w * h)
        .map(|k| {
            let (x, y) = (k % w, k / w);
            let sx = ((x as f32 + 0.5) / w as f32 * 2.0 - 1.0) * tan_half;
            let sy = -((y as f32 + 0.5) / h as f32 * 2.0 - 1.0) * tan_half;
            Ray::new(
                Vec3::new(0.0, 0.0, 20.0),
                Vec3::new(sx, sy, -1.0).normalize(),
            )
        })
        .collect();
    let (lo, hi) = (bounds.min, bounds.max);
    let incoherent = (0..(w * h) as u32)
        .map(|k| {
            let mut rng = pixel_rng(1, k, 0, 0);
            let u = Vec3::new(uniform(&mut rng), uniform(&mut rng), uniform(&mut rng));
            Ray::new(
                lo + u * (hi - lo),
                sample_uniform_sphere(uniform2(&mut rng)),
            )
        })
        .collect();
    (coherent, incoherent)
}

/// The value after `--name` among command-line `args` (`None` when the
/// flag is absent or last).
pub fn flag_value(args: &[String], name: &str) -> Option<String> {
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1))
        .cloned()
}

/// FNV-1a (64-bit) over 32-bit words: the checksum the benchmarks print so
/// that equal checksums show a change left a picture or a tree bit for bit
/// as it was.
#[derive(Debug, Clone, Copy)]
pub struct WordHash(pub u64);

impl Default for WordHash {
    fn default() -> Self {
        Self(0xcbf2_9ce4_8422_2325)
    }
}

impl WordHash {
    /// Mixes in one word.
    pub fn eat(&mut self, word: u32) {
        self.0 = (self.0 ^ u64::from(word)).wrapping_mul(0x100_0000_01b3);
    }

    /// Mixes in the bits of one float.
    pub fn eat_f32(&mut self, v: f32) {
        self.eat(v.to_bits());
    }
}

/// The film's colours as 8-bit sRGB, row by row, three bytes a pixel
/// (clamped to `[0, 1]`, no tone map): what the examples write as PNG.
pub fn srgb8_pixels(film: &Film) -> Vec<u8> {
    film.color
        .iter()
        .flat_map(|c| [c.x, c.y, c.z].map(linear_to_srgb8))
        .collect()
}
