//! Web viewer benchmark: time to first picture and frames per second of the
//! interactive low-resolution preview, measured end to end over the
//! WebSocket (render + PNG encoding + transfer), for the Cornell box and a
//! ~1M-triangle scene (the raster benchmark's 14x14 grid of spheres, here
//! UV spheres of ~5000 triangles).
//!
//! `cargo run --release -p chiaro-serve --example web_bench -- [frames]`
//!
//! `... -- [frames] orbit`: only the Cornell box in phong while orbiting,
//! as the page asks: frames per second of the drafts (one sample per pixel
//! and per area light), against full-quality frames, and the time to the
//! quick pass and to full quality of a refining render once it stops.
//!
//! `... -- [frames] drafts SCENE [TECHNIQUE...]`: any scene file, orbited
//! as the page does while the mouse drags (half the scene's resolution, one
//! sample per pixel and per light, one request in flight): drafts per
//! second of each technique (default: phong and preview), with the median
//! and slowest frame. The first frame after the connection opens (it builds
//! what the session keeps) is timed apart.

use chiaro::Vec3;
use chiaro::scene::{Attenuation, Light, Material, Scene};
use chiaro_core::geometry::primitives::uv_sphere;
use chiaro_serve::{ServeOptions, Server};
use serde_json::{Value, json};
use std::path::Path;
use std::time::Instant;
use tungstenite::Message;

fn grid_scene() -> Scene {
    let mut s = Scene {
        lights: vec![
            Light::Ambient {
                color: Vec3::ONE,
                intensity: 0.2,
            },
            Light::Point {
                position: Vec3::new(5.0, -5.0, 10.0),
                color: Vec3::ONE,
                intensity: 60.0,
                attenuation: Attenuation::default(),
            },
        ],
        ..Scene::default()
    };
    let m = s.add_material(Material {
        diffuse: Vec3::new(0.7, 0.3, 0.2),
        specular: Vec3::ONE,
        shininess: 32.0,
        ..Material::default()
    });
    let mesh = s.add_mesh(uv_sphere(0.45, 72, 36));
    chiaro_testkit::scenes::add_grid_of(&mut s, mesh, m);
    s.render.width = 640;
    s.render.height = 480;
    s
}

type Ws = tungstenite::WebSocket<tungstenite::stream::MaybeTlsStream<std::net::TcpStream>>;

/// Sends `req` and waits for its `done`; returns (ms to first frame, ms to done).
fn round_trip(ws: &mut Ws, req: &Value) -> (f64, f64) {
    let t = Instant::now();
    ws.send(Message::text(req.to_string())).expect("send");
    let mut first = None;
    loop {
        match ws.read().expect("read") {
            Message::Binary(_) => {
                first.get_or_insert(t.elapsed().as_secs_f64() * 1e3);
            }
            Message::Text(txt) => {
                let v: Value = serde_json::from_str(txt.as_str()).expect("json");
                match v["type"].as_str() {
                    Some("done") => {
                        let all = t.elapsed().as_secs_f64() * 1e3;
                        return (first.unwrap_or(all), all);
                    }
                    Some("error") => panic!("{v}"),
                    _ => {}
                }
            }
            _ => {}
        }
    }
}

/// Serves `scene` as `name` on a free loopback port, on a thread of its
/// own; returns the address.
fn serve_on_a_free_port(scene: Scene, name: &str) -> std::net::SocketAddr {
    let opts = ServeOptions {
        port: 0,
        ..ServeOptions::default()
    };
    Server::bind_scene(scene, name, &opts)
        .expect("bind")
        .spawn()
        .expect("addr")
}

fn bench(name: &str, scene: Scene, frames: usize) {
    let (w, h) = (scene.render.width, scene.render.height);
    let tris = scene.triangle_count();
    let addr = serve_on_a_free_port(scene, name);
    let (mut ws, _) = tungstenite::connect(format!("ws://{addr}/ws")).expect("connect");
    for technique in ["phong", "preview"] {
        let view = json!([{"technique": technique, "samples": 1}]);
        // Time to first picture: the page's first request (low resolution),
        // then the full-resolution progressive one.
        let low =
            json!({"type": "render", "id": 1, "width": w / 4, "height": h / 4, "views": view});
        let (first_low, _) = round_trip(&mut ws, &low);
        let full = json!({"type": "render", "id": 2, "width": w, "height": h, "progressive": true, "views": view});
        let (first_band, full_ms) = round_trip(&mut ws, &full);
        // Interactive preview: successive low-resolution frames while orbiting.
        let t = Instant::now();
        for i in 0..frames {
            let req = json!({"type": "render", "id": 10 + i, "width": w / 4, "height": h / 4,
                "orbit": {"yaw": i as f32 * 0.05, "pitch": 0.0, "zoom": 1.0}, "views": view});
            round_trip(&mut ws, &req);
        }
        let fps = frames as f64 / t.elapsed().as_secs_f64();
        println!(
            "| {name} ({tris} triangles) | {technique} | {:.0} ms ({}x{}) | {:.0} ms / {:.0} ms ({w}x{h}) | {fps:.1} fps ({}x{}) |",
            first_low,
            w / 4,
            h / 4,
            first_band,
            full_ms,
            w / 4,
            h / 4
        );
    }
}

/// Frames per second of orbiting frames of `views` at `w`x`h`.
fn orbit_fps(ws: &mut Ws, w: u32, h: u32, views: &Value, frames: usize) -> f64 {
    round_trip(
        ws,
        &json!({"type": "render", "id": 1, "width": w, "height": h, "views": views}),
    );
    let t = Instant::now();
    for i in 0..frames {
        let req = json!({"type": "render", "id": 10 + i, "width": w, "height": h,
            "orbit": {"yaw": i as f32 * 0.05, "pitch": 0.0, "zoom": 1.0}, "views": views});
        round_trip(ws, &req);
    }
    frames as f64 / t.elapsed().as_secs_f64()
}

/// Sends a refining request and returns (ms to the end of pass 1, ms to done).
fn refine_times(ws: &mut Ws, w: u32, h: u32, views: &Value) -> (f64, f64) {
    let t = Instant::now();
    let req = json!({"type": "render", "id": 999, "width": w, "height": h,
        "refine": true, "progressive": true, "views": views});
    ws.send(Message::text(req.to_string())).expect("send");
    let mut pass1 = None;
    loop {
        if let Message::Text(txt) = ws.read().expect("read") {
            let v: Value = serde_json::from_str(txt.as_str()).expect("json");
            match v["type"].as_str() {
                Some("pass") if v["pass"] == 2 => {
                    pass1 = Some(t.elapsed().as_secs_f64() * 1e3);
                }
                Some("done") => {
                    let all = t.elapsed().as_secs_f64() * 1e3;
                    return (pass1.unwrap_or(all), all);
                }
                Some("error") => panic!("{v}"),
                _ => {}
            }
        }
    }
}

fn orbit_bench(scene: Scene, frames: usize) {
    let (w, h, spp, ls) = (
        scene.render.width,
        scene.render.height,
        scene.render.samples,
        scene.render.light_samples,
    );
    let addr = serve_on_a_free_port(scene, "cornell-box");
    let (mut ws, _) = tungstenite::connect(format!("ws://{addr}/ws")).expect("connect");
    println!("| frames | size | samples per pixel / per area light | frames per second |");
    println!("| --- | --- | --- | --- |");
    let full = json!([{"technique": "phong", "samples": 1}]);
    let fps = orbit_fps(&mut ws, w, h, &full, frames.min(5));
    println!("| whole frames (before) | {w}x{h} | 1 / {ls} | {fps:.1} |");
    let draft = json!([{"technique": "phong", "samples": 1, "light_samples": 1}]);
    let fps = orbit_fps(&mut ws, w, h, &draft, frames);
    println!("| drafts | {w}x{h} | 1 / 1 | {fps:.1} |");
    let fps = orbit_fps(&mut ws, w / 2, h / 2, &draft, frames);
    println!(
        "| drafts (the page's, half size) | {}x{} | 1 / 1 | {fps:.1} |",
        w / 2,
        h / 2
    );
    let scene_quality = json!([{"technique": "phong", "samples": spp}]);
    let (pass1, done) = refine_times(&mut ws, w, h, &scene_quality);
    println!(
        "\nRefining at {w}x{h} once the camera stops: quick pass (1 / 1) after {pass1:.0} ms, full quality ({spp} / {ls}) after {done:.0} ms"
    );
}

/// Milliseconds of each of `frames` orbiting drafts of `views` at
/// `w`x`h`, one request in flight (the page's pace while dragging).
fn draft_times(ws: &mut Ws, w: u32, h: u32, views: &Value, frames: usize) -> Vec<f64> {
    (0..frames)
        .map(|i| {
            let req = json!({"type": "render", "id": 10 + i, "width": w, "height": h,
                "orbit": {"yaw": i as f32 * 0.05, "pitch": (i % 7) as f32 * 0.02, "zoom": 1.0},
                "views": views});
            round_trip(ws, &req).1
        })
        .collect()
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n == 0 {
        f64::NAN
    } else if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

fn drafts_bench(path: &Path, techniques: &[String], frames: usize) {
    let scene = chiaro::io::load_scene(path).expect("scene").scene;
    let (w, h) = (
        (scene.render.width / 2).max(8),
        (scene.render.height / 2).max(8),
    );
    let tris = scene.triangle_count();
    let name = path
        .file_stem()
        .map_or("scene".into(), |s| s.to_string_lossy().into_owned());
    let addr = serve_on_a_free_port(scene, &name);
    println!(
        "| scene | technique | drafts | first draft | median draft | slowest | drafts per second |"
    );
    println!("| --- | --- | --- | --- | --- | --- | --- |");
    for technique in techniques {
        // A connection of its own per technique, as a page opened anew.
        let (mut ws, _) = tungstenite::connect(format!("ws://{addr}/ws")).expect("connect");
        let views = json!([{"technique": technique, "samples": 1, "light_samples": 1}]);
        let first = draft_times(&mut ws, w, h, &views, 1)[0];
        let t = Instant::now();
        let mut ms = draft_times(&mut ws, w, h, &views, frames);
        let fps = frames as f64 / t.elapsed().as_secs_f64();
        let slowest = ms.iter().copied().fold(0.0, f64::max);
        let med = median(&mut ms);
        println!(
            "| {name} ({tris} triangles) | {technique} | {frames} at {w}x{h} | {first:.0} ms | {med:.1} ms | {slowest:.0} ms | {fps:.2} |"
        );
    }
}

fn main() {
    let frames = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(20);
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/cornell-box.toml");
    let cornell = chiaro::io::load_scene(&root).expect("cornell box").scene;
    if std::env::args().nth(2).as_deref() == Some("drafts") {
        let args: Vec<String> = std::env::args().skip(3).collect();
        let Some(path) = args.first() else {
            eprintln!("usage: web_bench FRAMES drafts SCENE [TECHNIQUE...]");
            std::process::exit(2);
        };
        let mut techniques = args[1..].to_vec();
        if techniques.is_empty() {
            techniques = vec!["phong".into(), "preview".into()];
        }
        drafts_bench(Path::new(path), &techniques, frames);
        return;
    }
    if std::env::args().nth(2).as_deref() == Some("orbit") {
        orbit_bench(cornell, frames);
        return;
    }
    println!(
        "| scene | technique | first picture (low res) | first band / whole (full res) | interactive preview |"
    );
    println!("| --- | --- | --- | --- | --- |");
    bench("cornell-box", cornell, frames);
    bench("sphere-grid", grid_scene(), frames);
}
