//! Run-time choice of the traversal kernel. The build targets x86-64-v3
//! (AVX2, FMA; `.cargo/config.toml`); [`SceneBvh`]'s single-ray closest-hit
//! and occlusion queries are also compiled for x86-64-v4 (AVX-512 F, BW,
//! CD, DQ, VL), and [`kernel`] picks one once per process from the CPU at
//! hand. `multiversion` writes the clones and the feature check, so the
//! `unsafe` call of a `#[target_feature]` function stays inside that crate
//! (decision 0051). Both kernels run the same Rust with no fused
//! multiply-adds of their own, so they return bit-identical hits.

use super::SceneBvh;
use crate::accel::Hit;
use crate::geometry::Ray;
use std::sync::OnceLock;

/// A compiled variant of the hot loops.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kernel {
    /// What the build targets (x86-64-v3 on x86-64 unless `RUSTFLAGS`
    /// says otherwise).
    Baseline,
    /// The x86-64-v4 (AVX-512) clones.
    #[cfg(target_arch = "x86_64")]
    X86_64V4,
}

/// The environment variable that caps the kernel: `baseline` keeps the
/// build's target on any CPU (to compare kernels on one host); other
/// values, or none, pick the best kernel the CPU runs.
pub const KERNEL_ENV: &str = "CHIARO_KERNEL";

impl Kernel {
    /// Its name, with the instruction sets it uses.
    pub fn name(self) -> &'static str {
        match self {
            #[cfg(target_arch = "x86_64")]
            Kernel::X86_64V4 => "x86-64-v4 (AVX-512)",
            Kernel::Baseline => BASELINE_NAME,
        }
    }

    /// The kernels this CPU can run, best first (the baseline always).
    pub fn available() -> Vec<Kernel> {
        let mut k = Vec::new();
        #[cfg(target_arch = "x86_64")]
        if has_v4() {
            k.push(Kernel::X86_64V4);
        }
        k.push(Kernel::Baseline);
        k
    }
}

#[cfg(all(target_arch = "x86_64", target_feature = "avx2"))]
const BASELINE_NAME: &str = "build target (x86-64-v3: AVX2, FMA)";
#[cfg(not(all(target_arch = "x86_64", target_feature = "avx2")))]
const BASELINE_NAME: &str = "build target";

/// Whether the CPU has every feature of the x86-64-v4 clones.
#[cfg(target_arch = "x86_64")]
fn has_v4() -> bool {
    std::arch::is_x86_feature_detected!("avx512f")
        && std::arch::is_x86_feature_detected!("avx512bw")
        && std::arch::is_x86_feature_detected!("avx512cd")
        && std::arch::is_x86_feature_detected!("avx512dq")
        && std::arch::is_x86_feature_detected!("avx512vl")
        && std::arch::is_x86_feature_detected!("avx2")
        && std::arch::is_x86_feature_detected!("fma")
}

/// The kernel that [`SceneBvh`]'s single-ray queries run: the first of
/// [`Kernel::available`], or the baseline where [`KERNEL_ENV`] is
/// `baseline`. Chosen at the first call and kept for the process.
pub fn kernel() -> Kernel {
    static CHOSEN: OnceLock<Kernel> = OnceLock::new();
    *CHOSEN.get_or_init(|| {
        let capped = std::env::var(KERNEL_ENV).is_ok_and(|v| v.eq_ignore_ascii_case("baseline"));
        if capped {
            Kernel::Baseline
        } else {
            Kernel::available()[0]
        }
    })
}

/// [`SceneBvh::closest_hit`] compiled for x86-64-v4; on a CPU without it,
/// multiversion's fallback runs the baseline build of the same code.
#[cfg(target_arch = "x86_64")]
#[multiversion::multiversion(targets(
    "x86_64+avx2+fma+avx512f+avx512bw+avx512cd+avx512dq+avx512vl"
))]
pub(super) fn closest_hit_v4(bvh: &SceneBvh, ray: &Ray) -> Option<Hit> {
    bvh.closest_hit(ray)
}

/// [`SceneBvh::any_hit`] compiled for x86-64-v4, as [`closest_hit_v4`].
#[cfg(target_arch = "x86_64")]
#[multiversion::multiversion(targets(
    "x86_64+avx2+fma+avx512f+avx512bw+avx512cd+avx512dq+avx512vl"
))]
pub(super) fn any_hit_v4(bvh: &SceneBvh, ray: &Ray) -> bool {
    bvh.any_hit(ray)
}
