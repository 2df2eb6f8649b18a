//! Regenerates the gallery: every technique on every scene in `scenes/`
//! (and `scenes/gltf/`) as a PNG in `docs/gallery/`, its manifest, and the
//! README's gallery table. Run from anywhere:
//! `cargo run --release -p chiaro-tools --example gallery`.

use std::process::ExitCode;

fn main() -> ExitCode {
    let root = chiaro_tools::gallery::repository_root();
    let start = std::time::Instant::now();
    match chiaro_tools::gallery::generate(&root, &mut |line| eprintln!("{line}")) {
        Ok(m) => {
            eprintln!(
                "{} pictures in {}, {} and {} updated in {:.0} s",
                m.cells.len(),
                chiaro_tools::gallery::DIR,
                chiaro_tools::gallery::MANIFEST,
                chiaro_tools::gallery::README,
                start.elapsed().as_secs_f64()
            );
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}
