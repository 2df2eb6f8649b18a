//! Scan-conversion benchmark: the llvmpipe peer's scene (a 14x14 grid of
//! 5120-triangle icospheres, 1,003,520 triangles, 1920x1080, two point
//! lights, as `benches/llvmpipe_raster.py` draws it) rendered with flat, Gouraud
//! and Phong shading, each into one film reused across frames
//! (`ScanConversion::render_into`, as the peer reuses its framebuffer). Prints
//! ms/frame (median of `frames` after one warm-up) and the peak resident
//! memory; writes PNGs of the frames to `$OUT_DIR` or /tmp when given
//! `--png`.
//!
//! Shadows are off (the peer draws none); `--issue4` instead times every
//! shadow method and transparency mode (issue 4). Each line also splits the
//! median frame into the renderer's passes (the `Progress` stages).
//!
//! `--issue8` times the six shadow methods (none, rays, maps, volumes,
//! object-precision, scan-line; Phong, one sample, 640x480) on the shadow
//! test scene and on a 103,682-triangle scene (81 level-3 icospheres over a
//! ground plane, one point light), then one sample + FXAA (`aa = post`)
//! against 4-sample supersampling, and prints a Markdown table with each
//! method's cost relative to shadow maps.
//!
//! `cargo run --release -p chiaro-raster --example raster_bench -- [frames] [--png] [--no-cull] [--issue4 | --issue8] [--crop] [--only NAME]`

use chiaro_core::Vec3;
use chiaro_core::context::RenderContext;
use chiaro_core::prepared::{PrepareOptions, PreparedScene};
use chiaro_core::progress::Progress;
use chiaro_core::scene::{
    AaMode, Attenuation, Camera, Geometry, Light, Material, Object, RenderSettings, Scene,
    ShadowMethod, Technique, Transform, TransparencyMode,
};
use chiaro_raster::{RasterWork, ScanConversion};
use chiaro_testkit::bench::{WordHash, median};
use std::sync::Mutex;
use std::time::Instant;

/// A [`Progress`] that timestamps the start of every stage, so a frame's
/// time splits into the renderer's passes.
#[derive(Default)]
struct PhaseTimer {
    marks: Mutex<Vec<(String, Instant)>>,
}

impl Progress for PhaseTimer {
    fn begin(&self, stage: &str, _total: u64) {
        if let Ok(mut m) = self.marks.lock() {
            m.push((stage.to_owned(), Instant::now()));
        }
    }
    fn advance(&self, _n: u64) {}
}

impl PhaseTimer {
    /// `(stage, ms)` from each stage's start to the next one's (the last
    /// stage ends at `end`).
    fn phases(&self, end: Instant) -> Vec<(String, f64)> {
        let m = self.marks.lock().map(|m| m.clone()).unwrap_or_default();
        m.iter()
            .enumerate()
            .map(|(i, (name, t))| {
                let next = m.get(i + 1).map_or(end, |n| n.1);
                (name.clone(), (next - *t).as_secs_f64() * 1e3)
            })
            .collect()
    }
}

/// CPU time of the whole process so far (user + system, all threads), in
/// ms, from /proc/self/stat (10 ms ticks); NaN where unavailable. Unlike
/// wall time it does not grow when other processes take the cores.
fn cpu_ms() -> f64 {
    std::fs::read_to_string("/proc/self/stat")
        .ok()
        .and_then(|s| {
            // Fields after the parenthesised command name; utime and stime
            // are fields 14 and 15 of the whole line.
            let rest = s.rsplit_once(')')?.1;
            let f: Vec<&str> = rest.split_whitespace().collect();
            let ticks = f.get(11)?.parse::<f64>().ok()? + f.get(12)?.parse::<f64>().ok()?;
            Some(ticks * 10.0)
        })
        .unwrap_or(f64::NAN)
}

fn scene() -> Scene {
    let mut s = Scene::default();
    // The peer's model: 0.1 ambient + per light c (kd N.L + (R.V)^32), no attenuation.
    let m = s.add_material(Material {
        ambient: Vec3::new(1.0 / 7.0, 1.0 / 6.0, 0.25),
        diffuse: Vec3::new(0.7, 0.3, 0.2),
        specular: Vec3::ONE,
        shininess: 32.0,
        ..Material::default()
    });
    let mesh = s.add_mesh(chiaro_core::geometry::primitives::icosphere(0.45, 4));
    chiaro_testkit::scenes::add_grid_of(&mut s, mesh, m);
    s.lights = vec![
        Light::Ambient {
            color: Vec3::ONE,
            intensity: 0.7,
        },
        Light::Point {
            position: Vec3::new(5.0, -5.0, 10.0),
            color: Vec3::ONE,
            intensity: 0.8,
            attenuation: Attenuation::None,
        },
        Light::Point {
            position: Vec3::new(-8.0, 2.0, 6.0),
            color: Vec3::ONE,
            intensity: 0.4,
            attenuation: Attenuation::None,
        },
    ];
    s
}

fn peak_rss_mib() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmHWM:"))
                .and_then(|l| l.split_whitespace().nth(1)?.parse::<f64>().ok())
        })
        .map_or(f64::NAN, |kb| kb / 1024.0)
}

/// One benchmark case: a name, the scene and settings (whose technique is
/// the shading mode).
struct Case {
    name: String,
    scene: usize,
    settings: RenderSettings,
    /// Apply the FXAA post filter to the frame (what the facade does for
    /// `aa = post`), inside the timed region.
    post: bool,
}

impl Case {
    /// A case without the post filter.
    fn new(name: impl Into<String>, scene: usize, settings: RenderSettings) -> Self {
        Self {
            name: name.into(),
            scene,
            settings,
            post: false,
        }
    }
}

/// The issue-8 large scene: a 9x9 grid of level-3 icospheres (1280
/// triangles each) floating over a 16x16-cell ground plane, lit by one
/// point light above and to the side so every sphere casts a shadow on the
/// plane and on its neighbours: 81 * 1280 + 2 * 16 * 16 = 104,192
/// triangles.
fn hundred_k_scene() -> Scene {
    let mut s = Scene::default();
    let m = s.add_material(Material {
        specular: Vec3::splat(0.4),
        shininess: 40.0,
        ..Material::diffuse("sphere", Vec3::new(0.7, 0.3, 0.2))
    });
    let floor = s.add_material(Material::diffuse("floor", Vec3::splat(0.7)));
    let ball = s.add_mesh(chiaro_core::geometry::primitives::icosphere(0.4, 3));
    let plane = s.add_mesh(chiaro_core::geometry::primitives::plane(6.0, 16));
    s.objects.push(Object {
        geometry: Geometry::Mesh(plane),
        material: floor,
        smooth: false,
        ..Object::default()
    });
    let n = 9;
    for i in 0..n {
        for j in 0..n {
            s.objects.push(Object {
                geometry: Geometry::Mesh(ball),
                material: m,
                transform: Transform {
                    translate: Vec3::new(
                        i as f32 * 1.2 - 4.8,
                        0.6 + 0.25 * ((i + j) % 3) as f32,
                        j as f32 * 1.2 - 4.8,
                    ),
                    ..Transform::default()
                },
                ..Object::default()
            });
        }
    }
    s.lights = vec![
        Light::Ambient {
            color: Vec3::ONE,
            intensity: 0.1,
        },
        Light::Point {
            position: Vec3::new(-4.0, 9.0, -3.0),
            color: Vec3::ONE,
            intensity: 60.0,
            attenuation: Attenuation::InverseSquare,
        },
    ];
    s.camera = Camera {
        eye: Vec3::new(0.0, 9.0, -11.0),
        look_at: Vec3::new(0.0, 0.0, 0.0),
        up: Vec3::Y,
        fov_y_degrees: 50.0,
        near: 0.1,
        far: 100.0,
        ..Default::default()
    };
    s
}

/// The issue-8 cases: every shadow method on scenes 0 (the shadow test
/// scene) and 1 (the 100k-triangle scene), then `aa = post` against
/// 4-sample supersampling on scene 0 with shadow maps.
fn issue8_cases(cull: bool) -> Vec<Case> {
    let base = RenderSettings {
        width: 640,
        height: 480,
        samples: 1,
        ..settings(Technique::Phong, cull)
    };
    let mut cases = Vec::new();
    for (scene, tag) in [(0, "shadow test"), (1, "100k")] {
        for (name, sh) in [
            ("none", ShadowMethod::None),
            ("rays", ShadowMethod::Ray),
            ("maps", ShadowMethod::Map),
            ("volumes", ShadowMethod::Volume),
            ("object", ShadowMethod::Object),
            ("scanline", ShadowMethod::Scanline),
        ] {
            cases.push(Case::new(
                format!("{tag}, shadows {name}"),
                scene,
                RenderSettings {
                    shadows: sh,
                    ..base.clone()
                },
            ));
        }
    }
    for (name, samples, post) in [("aa post (1 + FXAA)", 1, true), ("aa 4 samples", 4, false)] {
        cases.push(Case {
            name: format!("shadow test, shadows maps, {name}"),
            scene: 0,
            settings: RenderSettings {
                shadows: ShadowMethod::Map,
                samples,
                aa: if post {
                    AaMode::Post
                } else {
                    AaMode::Supersample
                },
                ..base.clone()
            },
            post,
        });
    }
    cases
}

/// The 1-, 5- and 15-minute load averages from /proc/loadavg.
fn load_average() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .map(|s| s.split_whitespace().take(3).collect::<Vec<_>>().join(" "))
        .unwrap_or_else(|_| "unknown".into())
}

fn settings(technique: Technique, cull: bool) -> RenderSettings {
    RenderSettings {
        technique,
        width: 1920,
        height: 1080,
        cull_backfaces: cull,
        // The peer draws no shadows.
        shadows: ShadowMethod::None,
        ..RenderSettings::default()
    }
}

/// The scene with every third sphere transparent (`kt = 0.6`).
fn transparent_scene() -> Scene {
    let mut s = scene();
    let glass = s.add_material(Material {
        ambient: Vec3::splat(0.1),
        diffuse: Vec3::new(0.2, 0.4, 0.7),
        specular: Vec3::ONE,
        shininess: 32.0,
        transmit: Vec3::splat(0.6),
        ..Material::default()
    });
    for (k, o) in s.objects.iter_mut().enumerate() {
        if k % 3 == 0 {
            o.material = glass;
        }
    }
    s
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let frames: usize = args.iter().find_map(|a| a.parse().ok()).unwrap_or(5).max(1);
    let png = args.iter().any(|a| a == "--png");
    let cull = !args.iter().any(|a| a == "--no-cull");
    let issue4 = args.iter().any(|a| a == "--issue4");
    let issue8 = args.iter().any(|a| a == "--issue8");
    let crop = args.iter().any(|a| a == "--crop");
    let scenes = if issue8 {
        vec![chiaro_testkit::scenes::shadow_test(640), hundred_k_scene()]
    } else {
        vec![scene(), transparent_scene()]
    };
    let t0 = Instant::now();
    let prepared: Vec<PreparedScene<'_>> = scenes
        .iter()
        .map(|s| PreparedScene::new(s, PrepareOptions::default()))
        .collect();
    let prep = t0.elapsed().as_secs_f64() * 1e3 / 2.0;
    for (k, ps) in prepared.iter().enumerate() {
        println!(
            "scene {k}: {} triangles, {} vertices; prepare {prep:.1} ms; threads {}; cull {cull}",
            ps.triangle_count(),
            ps.positions.len(),
            rayon::current_num_threads()
        );
    }
    // The render contexts prepare their own copies; this one only named the sizes.
    drop(prepared);
    println!("load average before: {}", load_average());
    let mut cases = Vec::new();
    if issue8 {
        cases = issue8_cases(cull);
    } else if issue4 {
        for (name, sh) in [
            ("phong, shadows none", ShadowMethod::None),
            ("phong, shadow rays", ShadowMethod::Ray),
            ("phong, shadow maps", ShadowMethod::Map),
            ("phong, shadow volumes", ShadowMethod::Volume),
        ] {
            cases.push(Case::new(
                name,
                0,
                RenderSettings {
                    shadows: sh,
                    ..settings(Technique::Phong, cull)
                },
            ));
        }
        cases.push(Case::new(
            "phong, 1/3 of spheres kt=0.6 drawn opaque",
            0,
            settings(Technique::Phong, cull),
        ));
        for (name, t) in [
            ("screen-door", TransparencyMode::ScreenDoor),
            ("interpolated", TransparencyMode::Interpolated),
            ("filtered", TransparencyMode::Filtered),
        ] {
            cases.push(Case::new(
                format!("phong, 1/3 of spheres kt=0.6, {name}"),
                1,
                RenderSettings {
                    transparency: Some(t),
                    ..settings(Technique::Phong, cull)
                },
            ));
        }
    } else {
        for (name, technique) in [
            ("phong", Technique::Phong),
            ("gouraud", Technique::Gouraud),
            ("flat", Technique::Flat),
        ] {
            cases.push(Case::new(
                name,
                0,
                RenderSettings {
                    crop: crop.then_some([640, 270, 1280, 810]),
                    ..settings(technique, cull)
                },
            ));
        }
    }
    let only: Option<&String> = args
        .iter()
        .position(|a| a == "--only")
        .and_then(|i| args.get(i + 1));
    // (case, median wall ms, median CPU ms, passes) for the Markdown table.
    let mut results: Vec<(&Case, f64, f64, String)> = Vec::new();
    for case in cases
        .iter()
        .filter(|c| only.is_none_or(|o| c.name.starts_with(o.as_str())))
    {
        // One context a case: the scene is prepared in the warm-up frame.
        let timer = PhaseTimer::default();
        let ctx = match RenderContext::new(&scenes[case.scene], &case.settings, &timer) {
            Ok(ctx) => ctx,
            Err(e) => {
                eprintln!("{}: {e}", case.name);
                continue;
            }
        };
        let mut times = Vec::new();
        let mut cpu = Vec::new();
        let mut phases: Vec<(String, Vec<f64>)> = Vec::new();
        let mut film = None;
        // One film reused by every frame, as the peer reuses its framebuffer.
        let mut target = chiaro_core::film::Film::new(0, 0);
        for frame in 0..=frames {
            if let Ok(mut m) = timer.marks.lock() {
                m.clear();
            }
            let c0 = cpu_ms();
            let t = Instant::now();
            let f = ScanConversion::default()
                .render_into(&ctx, &mut target, &RasterWork::default())
                .map(|()| {
                    case.post.then(|| {
                        timer.begin("fxaa", 0);
                        chiaro_core::film::postfilter::fxaa(&target)
                    })
                });
            let end = Instant::now();
            let c1 = cpu_ms();
            film = match f {
                Ok(post) => Some(post),
                Err(e) => {
                    eprintln!("{}: {e}", case.name);
                    None
                }
            };
            if frame == 0 {
                continue; // warm-up
            }
            times.push((end - t).as_secs_f64() * 1e3);
            cpu.push(c1 - c0);
            for (k, (stage, ms)) in timer.phases(end).into_iter().enumerate() {
                if phases.len() <= k {
                    phases.push((stage, Vec::new()));
                }
                phases[k].1.push(ms);
            }
        }
        let Some(post) = film else {
            eprintln!("{}: render failed", case.name);
            continue;
        };
        let film = post.as_ref().unwrap_or(&target);
        let (min, max) = (
            times.iter().copied().fold(f64::INFINITY, f64::min),
            times.iter().copied().fold(0.0, f64::max),
        );
        let covered =
            film.depth.iter().filter(|d| d.is_finite()).count() as f64 / film.depth.len() as f64;
        // FNV-1a over the bits of every colour, depth and normal: equal
        // checksums mean bit-identical pictures.
        let mut hash = WordHash::default();
        for i in 0..film.depth.len() {
            let (c, n) = (film.color[i], film.normal[i]);
            for v in [c.x, c.y, c.z, film.depth[i], n.x, n.y, n.z] {
                hash.eat_f32(v);
            }
        }
        let hash = hash.0;
        let split: Vec<String> = phases
            .iter_mut()
            .map(|(stage, v)| format!("{stage} {:.1}", median(v)))
            .collect();
        let (wall, cpu) = (median(&mut times), median(&mut cpu));
        println!(
            "{}: median {wall:.1} ms/frame (min {min:.1}, max {max:.1}, n={frames}) [{}]; cpu {cpu:.0} ms/frame; covered {:.1}%; film {hash:016x}; peak RSS {:.0} MiB",
            case.name,
            split.join(", "),
            covered * 100.0,
            peak_rss_mib()
        );
        results.push((case, wall, cpu, split.join(", ")));
        if png {
            let dir = std::env::var("OUT_DIR").unwrap_or_else(|_| "/tmp".into());
            let img = image::RgbImage::from_fn(film.width, film.height, |x, y| {
                let c = film.get(x, y);
                let e = |v: f32| (v.clamp(0.0, 1.0).powf(1.0 / 2.2) * 255.0 + 0.5) as u8;
                image::Rgb([e(c.x), e(c.y), e(c.z)])
            });
            let file: String = case
                .name
                .chars()
                .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
                .collect();
            let path = format!("{dir}/raster_{file}.png");
            if let Err(e) = img.save(&path) {
                eprintln!("{path}: {e}");
            }
        }
    }
    println!("load average after: {}", load_average());
    if issue8 {
        print_issue8_table(&results);
    }
}

/// Prints the issue-8 results as a Markdown table, each case's median wall
/// and CPU time also as a multiple of shadow maps' on the same scene.
fn print_issue8_table(results: &[(&Case, f64, f64, String)]) {
    println!();
    println!("| case | wall ms/frame | CPU ms/frame | wall / maps | CPU / maps | passes (ms) |");
    println!("| --- | ---: | ---: | ---: | ---: | --- |");
    for (case, wall, cpu, split) in results {
        let maps = results.iter().find(|(c, ..)| {
            c.scene == case.scene
                && c.settings.shadows == ShadowMethod::Map
                && c.settings.samples == 1
                && !c.post
        });
        let (rw, rc) = maps.map_or((f64::NAN, f64::NAN), |(_, w, c, _)| (wall / w, cpu / c));
        println!(
            "| {} | {wall:.1} | {cpu:.0} | {rw:.2} | {rc:.2} | {split} |",
            case.name
        );
    }
}
