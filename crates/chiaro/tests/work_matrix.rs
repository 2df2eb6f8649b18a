//! The technique-by-scene matrix of `benches/matrix.sh` at a tiny size,
//! counting work instead of timing it: rays (ray tracers), elements and
//! form factors (radiosity), rasterized tile triangles, samples,
//! transparent fragments and shadow-volume polygons (scan conversion).
//! A cell fails when a count grows past ten times the figure recorded here,
//! so a technique that becomes pathological on a scene shows up without a
//! timed test. Radiosity solves stop after `MAX_SHOTS` shots. To record new figures, run with `--nocapture` and copy the
//! `work:` lines into `RECORDED`.

use chiaro::scene::Technique;
use chiaro::{NoProgress, RenderSettings, Scene};

const SCENES: [&str; 6] = [
    "cornell-box.toml",
    "mitsuba-cbox.toml",
    "spotlights.toml",
    "teapot.toml",
    "transparency.toml",
    "whitted.toml",
];

/// Radiosity iterations (shots) the test lets a solve take.
const MAX_SHOTS: u32 = 256;

/// `(scene, technique, counter, work)` measured at 32x24 with the scene's
/// other settings.
const RECORDED: &[(&str, &str, &str, u64)] = &[
    ("cornell-box.toml", "preview", "rays", 3072),
    ("cornell-box.toml", "flat", "tile triangles", 22),
    ("cornell-box.toml", "flat", "samples", 3072),
    ("cornell-box.toml", "flat", "fragments", 0),
    ("cornell-box.toml", "flat", "volume polygons", 0),
    ("cornell-box.toml", "gouraud", "tile triangles", 22),
    ("cornell-box.toml", "gouraud", "samples", 3072),
    ("cornell-box.toml", "gouraud", "fragments", 0),
    ("cornell-box.toml", "gouraud", "volume polygons", 0),
    ("cornell-box.toml", "phong", "tile triangles", 22),
    ("cornell-box.toml", "phong", "samples", 3072),
    ("cornell-box.toml", "phong", "fragments", 0),
    ("cornell-box.toml", "phong", "volume polygons", 0),
    ("cornell-box.toml", "whitted", "rays", 51713),
    ("cornell-box.toml", "radiosity", "elements", 3296),
    ("cornell-box.toml", "radiosity", "form factors", 369939),
    ("cornell-box.toml", "hybrid", "elements", 3296),
    ("cornell-box.toml", "hybrid", "form factors", 369939),
    ("cornell-box.toml", "hybrid", "rays", 51713),
    ("cornell-box.toml", "path", "rays", 11383),
    ("mitsuba-cbox.toml", "preview", "rays", 49152),
    ("mitsuba-cbox.toml", "flat", "tile triangles", 22),
    ("mitsuba-cbox.toml", "flat", "samples", 49152),
    ("mitsuba-cbox.toml", "flat", "fragments", 0),
    ("mitsuba-cbox.toml", "flat", "volume polygons", 0),
    ("mitsuba-cbox.toml", "gouraud", "tile triangles", 22),
    ("mitsuba-cbox.toml", "gouraud", "samples", 49152),
    ("mitsuba-cbox.toml", "gouraud", "fragments", 0),
    ("mitsuba-cbox.toml", "gouraud", "volume polygons", 0),
    ("mitsuba-cbox.toml", "phong", "tile triangles", 22),
    ("mitsuba-cbox.toml", "phong", "samples", 49152),
    ("mitsuba-cbox.toml", "phong", "fragments", 0),
    ("mitsuba-cbox.toml", "phong", "volume polygons", 0),
    ("mitsuba-cbox.toml", "whitted", "rays", 834533),
    ("mitsuba-cbox.toml", "radiosity", "elements", 2626),
    ("mitsuba-cbox.toml", "radiosity", "form factors", 672256),
    ("mitsuba-cbox.toml", "hybrid", "elements", 2626),
    ("mitsuba-cbox.toml", "hybrid", "form factors", 672256),
    ("mitsuba-cbox.toml", "hybrid", "rays", 834533),
    ("mitsuba-cbox.toml", "path", "rays", 232032),
    ("spotlights.toml", "preview", "rays", 3072),
    ("spotlights.toml", "flat", "tile triangles", 5564),
    ("spotlights.toml", "flat", "samples", 3072),
    ("spotlights.toml", "flat", "fragments", 0),
    ("spotlights.toml", "flat", "volume polygons", 0),
    ("spotlights.toml", "gouraud", "tile triangles", 5564),
    ("spotlights.toml", "gouraud", "samples", 3072),
    ("spotlights.toml", "gouraud", "fragments", 0),
    ("spotlights.toml", "gouraud", "volume polygons", 0),
    ("spotlights.toml", "phong", "tile triangles", 5564),
    ("spotlights.toml", "phong", "samples", 3072),
    ("spotlights.toml", "phong", "fragments", 0),
    ("spotlights.toml", "phong", "volume polygons", 0),
    ("spotlights.toml", "whitted", "rays", 5583),
    ("spotlights.toml", "radiosity", "elements", 8624),
    ("spotlights.toml", "radiosity", "form factors", 2207744),
    ("spotlights.toml", "hybrid", "elements", 8624),
    ("spotlights.toml", "hybrid", "form factors", 2207744),
    ("spotlights.toml", "hybrid", "rays", 5583),
    ("spotlights.toml", "path", "rays", 5956),
    ("teapot.toml", "preview", "rays", 3072),
    ("teapot.toml", "flat", "tile triangles", 288),
    ("teapot.toml", "flat", "samples", 3072),
    ("teapot.toml", "flat", "fragments", 0),
    ("teapot.toml", "flat", "volume polygons", 0),
    ("teapot.toml", "gouraud", "tile triangles", 288),
    ("teapot.toml", "gouraud", "samples", 3072),
    ("teapot.toml", "gouraud", "fragments", 0),
    ("teapot.toml", "gouraud", "volume polygons", 0),
    ("teapot.toml", "phong", "tile triangles", 288),
    ("teapot.toml", "phong", "samples", 3072),
    ("teapot.toml", "phong", "fragments", 0),
    ("teapot.toml", "phong", "volume polygons", 0),
    ("teapot.toml", "whitted", "rays", 7287),
    ("teapot.toml", "radiosity", "elements", 1072),
    ("teapot.toml", "radiosity", "form factors", 274432),
    ("teapot.toml", "hybrid", "elements", 1072),
    ("teapot.toml", "hybrid", "form factors", 274432),
    ("teapot.toml", "hybrid", "rays", 7287),
    ("teapot.toml", "path", "rays", 8118),
    ("transparency.toml", "preview", "rays", 3072),
    ("transparency.toml", "flat", "tile triangles", 1931),
    ("transparency.toml", "flat", "samples", 3072),
    ("transparency.toml", "flat", "fragments", 797),
    ("transparency.toml", "flat", "volume polygons", 0),
    ("transparency.toml", "gouraud", "tile triangles", 1931),
    ("transparency.toml", "gouraud", "samples", 3072),
    ("transparency.toml", "gouraud", "fragments", 797),
    ("transparency.toml", "gouraud", "volume polygons", 0),
    ("transparency.toml", "phong", "tile triangles", 1931),
    ("transparency.toml", "phong", "samples", 3072),
    ("transparency.toml", "phong", "fragments", 797),
    ("transparency.toml", "phong", "volume polygons", 0),
    ("transparency.toml", "whitted", "rays", 9927),
    ("transparency.toml", "radiosity", "elements", 4592),
    ("transparency.toml", "radiosity", "form factors", 1175552),
    ("transparency.toml", "hybrid", "elements", 4592),
    ("transparency.toml", "hybrid", "form factors", 1175552),
    ("transparency.toml", "hybrid", "rays", 9927),
    ("transparency.toml", "path", "rays", 8635),
    ("whitted.toml", "preview", "rays", 3072),
    ("whitted.toml", "flat", "tile triangles", 3187),
    ("whitted.toml", "flat", "samples", 3072),
    ("whitted.toml", "flat", "fragments", 310),
    ("whitted.toml", "flat", "volume polygons", 0),
    ("whitted.toml", "gouraud", "tile triangles", 3187),
    ("whitted.toml", "gouraud", "samples", 3072),
    ("whitted.toml", "gouraud", "fragments", 310),
    ("whitted.toml", "gouraud", "volume polygons", 0),
    ("whitted.toml", "phong", "tile triangles", 3187),
    ("whitted.toml", "phong", "samples", 3072),
    ("whitted.toml", "phong", "fragments", 310),
    ("whitted.toml", "phong", "volume polygons", 0),
    ("whitted.toml", "whitted", "rays", 11852),
    ("whitted.toml", "radiosity", "elements", 8448),
    ("whitted.toml", "radiosity", "form factors", 2162688),
    ("whitted.toml", "hybrid", "elements", 8448),
    ("whitted.toml", "hybrid", "form factors", 2162688),
    ("whitted.toml", "hybrid", "rays", 11852),
    ("whitted.toml", "path", "rays", 7594),
];

fn shipped(name: &str) -> Scene {
    let path = format!("{}/../../scenes/{name}", env!("CARGO_MANIFEST_DIR"));
    chiaro::io::load_scene(std::path::Path::new(&path))
        .expect("the shipped scene loads")
        .scene
}

/// Form factors a radiosity solve computed: a column of `elements` per
/// shot (progressive), the matrix (Jacobi, Gauss-Seidel), or the links
/// (hierarchical).
fn form_factors(s: &chiaro::SolveStats) -> u64 {
    let n = s.elements as u64;
    match s.solver.as_str() {
        "progressive" => n * u64::from(s.iterations),
        "hierarchical" => s.links as u64,
        _ => n * n,
    }
}

fn work(scene: &Scene, technique: Technique) -> Vec<(&'static str, u64)> {
    let mut settings = RenderSettings {
        technique,
        width: 32,
        height: 24,
        ..scene.render.clone()
    };
    // Radiosity's shots are capped so the test stays fast: the counts then
    // catch a mesh or a shot that grows, not a solve that needs more shots.
    settings.radiosity.max_iterations = settings.radiosity.max_iterations.min(MAX_SHOTS);
    match technique {
        Technique::Flat | Technique::Gouraud | Technique::Phong => {
            let w = chiaro_raster::RasterWork::default();
            let ctx = chiaro::RenderContext::new(scene, &settings, &NoProgress).expect("valid");
            chiaro_raster::ScanConversion::DEFAULT
                .render_into(&ctx, &mut chiaro::Film::new(0, 0), &w)
                .expect("renders");
            let get =
                |a: &std::sync::atomic::AtomicU64| a.load(std::sync::atomic::Ordering::Relaxed);
            vec![
                ("tile triangles", get(&w.tile_triangles)),
                ("samples", get(&w.samples)),
                ("fragments", get(&w.fragments)),
                ("volume polygons", get(&w.volume_tile_polygons)),
            ]
        }
        Technique::Radiosity | Technique::Hybrid => {
            let ctx = chiaro::RenderContext::new(scene, &settings, &NoProgress).expect("valid");
            let solution = chiaro::radiosity_solution(&ctx).expect("solves");
            let s = solution.stats.clone();
            let mut out = vec![
                ("elements", s.elements as u64),
                ("form factors", form_factors(&s)),
            ];
            if technique == Technique::Hybrid {
                // The context keeps the solution: the render does not solve again.
                let (_, stats) =
                    chiaro::render_with(&ctx, chiaro::renderer(technique)).expect("renders");
                out.push(("rays", stats.rays));
            }
            out
        }
        Technique::Preview | Technique::Whitted | Technique::Path => {
            let (_, stats) =
                chiaro::render_with_stats(scene, &settings, &NoProgress).expect("renders");
            vec![("rays", stats.rays)]
        }
    }
}

/// The failure message of a measured count against `recorded`, if any.
fn verdict(
    recorded: &[(&str, &str, &str, u64)],
    cell: (&str, &str, &str),
    n: u64,
) -> Option<String> {
    let (name, t, counter) = cell;
    match recorded
        .iter()
        .find(|r| r.0 == name && r.1 == t && r.2 == counter)
    {
        None => Some(format!(
            "{name} {t}: no recorded figure for `{counter}` (measured {n})"
        )),
        Some(r) if n > 10 * r.3.max(1) => Some(format!(
            "{name} {t}: `{counter}` is {n}, more than 10x the recorded {} ({:.1}x): \
             this cell's work grew out of proportion",
            r.3,
            n as f64 / r.3.max(1) as f64
        )),
        Some(_) => None,
    }
}

#[test]
fn no_cell_does_ten_times_its_recorded_work() {
    let mut failures = Vec::new();
    for name in SCENES {
        let scene = shipped(name);
        for technique in chiaro::Technique::ALL {
            for (counter, n) in work(&scene, technique) {
                let t = technique.name();
                println!("work: (\"{name}\", \"{t}\", \"{counter}\", {n}),");
                failures.extend(verdict(RECORDED, (name, t, counter), n));
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// The guard itself: sixteen times the samples per pixel of Phong on the
/// Cornell box is caught against the one-sample figures, and the same
/// render is not.
#[test]
fn ten_times_the_work_is_caught() {
    let mut scene = shipped("cornell-box.toml");
    scene.render.samples = 1;
    let base: Vec<(&str, &str, &str, u64)> = work(&scene, Technique::Phong)
        .into_iter()
        .map(|(c, n)| ("cornell", "phong", c, n))
        .collect();
    for (c, n) in work(&scene, Technique::Phong) {
        assert_eq!(verdict(&base, ("cornell", "phong", c), n), None);
    }
    scene.render.samples = 16;
    let grown = work(&scene, Technique::Phong);
    let caught: Vec<String> = grown
        .iter()
        .filter_map(|&(c, n)| verdict(&base, ("cornell", "phong", c), n))
        .collect();
    assert!(
        caught.iter().any(|m| m.contains("`samples`")),
        "16x the samples not caught: {grown:?}"
    );
}
