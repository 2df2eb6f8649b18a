//! What every fuzz target shares: a small memory budget for the loaders,
//! the `chiaro info`-level preparation of a loaded scene, and (for the
//! `techniques` target) a tiny render with every technique under a work
//! budget.

use chiaro_core::budget::{ByteSize, MemoryBudget};
use chiaro_io::Loaded;

/// The memory budget the loaders run under while fuzzing: small enough that
/// a file claiming a huge image or accessor is refused by the same checks a
/// user's render meets, well inside libFuzzer's default 2 GB RSS limit.
pub const FUZZ_BUDGET: u64 = 256 << 20;

/// Sets the process budget (idempotent; every target calls it first).
pub fn init() {
    MemoryBudget::set_process(ByteSize(FUZZ_BUDGET));
}

/// What `chiaro info` and the start of `chiaro render` do with a loaded
/// scene short of rendering: the memory estimate against the budget and,
/// when it fits, the prepared scene's bounds (tessellation, welding,
/// crease normals).
pub fn prepare(loaded: &Loaded) {
    let scene = &loaded.scene;
    let _ = scene.validate();
    let estimate = chiaro::memory_estimate(scene, &scene.render);
    if estimate.check(MemoryBudget::new(FUZZ_BUDGET)).is_ok() {
        let b = chiaro::scene_bounds(scene);
        assert!(!b.min.is_nan() && !b.max.is_nan(), "NaN scene bounds");
    }
}

/// Width and height of the renders of [`render_every_technique`].
pub const TINY: (u32, u32) = (8, 6);

/// The radiosity iteration budget of [`render_every_technique`]: a count,
/// so a solve ends at the same point every run, and small, so that a
/// render that does not end shows as a libFuzzer timeout, not a slow run.
pub const RADIOSITY_BUDGET: u32 = 200;

/// Renders `loaded` with every technique at [`TINY`] size, one sample, a
/// radiosity budget of [`RADIOSITY_BUDGET`] iterations and the fuzzing
/// memory budget, when the scene's estimate fits that budget. Errors (a
/// refusal) are fine; a panic, a hang or a NaN-free film turning NaN are
/// what fuzzing looks for.
pub fn render_every_technique(loaded: &Loaded) {
    let scene = &loaded.scene;
    for technique in chiaro::scene::Technique::ALL {
        let mut s = scene.render.clone();
        s.technique = technique;
        (s.width, s.height) = TINY;
        s.samples = 1;
        s.memory_limit = Some(ByteSize(FUZZ_BUDGET));
        s.radiosity.max_iterations = RADIOSITY_BUDGET;
        if chiaro::memory_estimate(scene, &s)
            .check(MemoryBudget::new(FUZZ_BUDGET))
            .is_err()
        {
            continue;
        }
        if let Ok(film) = chiaro::render(scene, &s, &chiaro::NoProgress) {
            assert!(
                film.color.iter().all(|c| !c.is_nan()),
                "{technique:?}: NaN in the film"
            );
        }
    }
}
