//! What every fuzz target shares: a small memory budget for the loaders and
//! the `chiaro info`-level preparation of a loaded scene.

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
