//! Times the OBJ loader: `cargo run --release -p chiaro-io --example obj_load -- FILE.obj [RUNS]`
//! prints the median and the spread of `obj::load_obj_meshes` over RUNS loads (default 7).

use std::path::PathBuf;
use std::time::Instant;

fn main() {
    let mut args = std::env::args().skip(1);
    let Some(path) = args.next().map(PathBuf::from) else {
        eprintln!("usage: obj_load FILE.obj [RUNS]");
        std::process::exit(2);
    };
    let runs: usize = args.next().and_then(|r| r.parse().ok()).unwrap_or(7).max(1);
    let mut times = Vec::with_capacity(runs);
    let mut triangles = 0;
    for _ in 0..runs {
        let t = Instant::now();
        match chiaro_io::obj::load_obj_meshes(&path) {
            Ok(imp) => triangles = imp.meshes.iter().map(|m| m.indices.len()).sum::<usize>(),
            Err(e) => {
                eprintln!("error: {e}");
                std::process::exit(1);
            }
        }
        times.push(t.elapsed().as_secs_f64());
    }
    times.sort_by(f64::total_cmp);
    println!(
        "{}: {triangles} triangles, median {:.1} ms over {runs} loads (min {:.1}, max {:.1})",
        path.display(),
        times[runs / 2] * 1e3,
        times[0] * 1e3,
        times[runs - 1] * 1e3
    );
}
