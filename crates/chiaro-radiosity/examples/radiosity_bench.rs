//! Radiosity benchmark: time to converge the Cornell box (unit size, in
//! code, official RGB albedos) to 1% unshot energy, per solver and
//! form-factor method, at several element counts; prints a Markdown table.
//!
//! `cargo run --release -p chiaro-radiosity --example radiosity_bench -- [max_elements] [solver,...]`
//! (see benches/radiosity_bench.sh). Peak memory is read from
//! `/proc/self/status` (VmHWM, the process's high-water mark, so run one
//! configuration per process for exact figures: the script does).

use chiaro_core::Vec3;
use chiaro_core::progress::NoProgress;
use chiaro_core::scene::RenderSettings;

fn peak_rss_mib() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines().find(|l| l.starts_with("VmHWM:")).and_then(|l| {
                l.split_whitespace()
                    .nth(1)
                    .and_then(|v| v.parse::<f64>().ok())
            })
        })
        .map_or(f64::NAN, |kb| kb / 1024.0)
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    // Usage: radiosity_bench SOLVER FORMFACTOR PATCH_SIZE
    if args.len() != 4 {
        eprintln!("usage: radiosity_bench SOLVER FORMFACTOR PATCH_SIZE");
        std::process::exit(2);
    }
    // The unit Cornell box the radiosity tests use (its camera is unused:
    // solving is view-independent).
    let scene = chiaro_testkit::scenes::unit_cornell_box();
    let mut r = RenderSettings::default();
    let (Some(solver), Some(formfactor)) = (
        chiaro_radiosity::Solver::from_name(&args[1]),
        chiaro_radiosity::Method::from_name(&args[2]),
    ) else {
        eprintln!("unknown solver or form-factor method");
        std::process::exit(2);
    };
    r.radiosity.solver = solver;
    r.radiosity.formfactor = formfactor;
    r.radiosity.patch_size = args[3].parse().unwrap_or(0.1);
    r.radiosity.tolerance = 0.01;
    r.radiosity.hemicube_resolution = 64;
    let t = std::time::Instant::now();
    let solved = chiaro_core::context::RenderContext::new(&scene, &r, &NoProgress)
        .and_then(|ctx| chiaro_radiosity::solve(&ctx));
    match solved {
        Ok(sol) => {
            let st = &sol.stats;
            let ceiling = sol.object_mean_radiance(1).unwrap_or(Vec3::ZERO);
            println!(
                "| {} | {} | {} | {} | {:.2} | {} | {:.1e} | {} | {} | {:.0} | {:.4} {:.4} {:.4} |",
                st.solver,
                st.formfactor,
                st.patch_size,
                st.elements,
                t.elapsed().as_secs_f64(),
                st.iterations,
                st.unshot,
                st.leaves,
                st.links,
                peak_rss_mib(),
                ceiling.x,
                ceiling.y,
                ceiling.z
            );
        }
        Err(e) => println!(
            "| {} | {} | {} | - | - | - | - | - | - | - | {e} |",
            args[1], args[2], args[3]
        ),
    }
}
