//! Frames of an interactive session ([`chiaro::render_frame`] through a
//! [`FrameCache`]) are the pictures of fresh renders of the scene with its
//! camera replaced, bit for bit, whatever the cache kept from the frames
//! before; and the cache starts a piece afresh when what it depends on
//! changes (the scene, the spheres' tessellation, the radiosity settings).

use chiaro::scene::{Camera, Technique};
use chiaro::{Film, FrameCache, NoProgress, RenderSettings, Scene, Vec3};
use std::path::Path;

fn load(name: &str) -> Scene {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../scenes")
        .join(name);
    chiaro::io::load_scene(&path).expect("shipped scene").scene
}

/// `cam` turned by `yaw` radians about its up axis around the point it
/// looks at, and moved `zoom` times closer.
fn orbit(cam: &Camera, yaw: f32, zoom: f32) -> Camera {
    let k = cam.up.normalize();
    let v = cam.eye - cam.look_at;
    // Rodrigues' rotation of `v` about the unit axis `k`.
    let (s, c) = yaw.sin_cos();
    let rotated = v * c + k.cross(v) * s + k * k.dot(v) * (1.0 - c);
    Camera {
        eye: cam.look_at + rotated / zoom,
        ..*cam
    }
}

/// A small draft of `technique`: the page's while orbiting.
fn draft(scene: &Scene, technique: Technique) -> RenderSettings {
    RenderSettings {
        technique,
        width: 40,
        height: 30,
        samples: 1,
        light_samples: 1,
        ..scene.render.clone()
    }
}

/// A fresh render of `scene` seen through `camera`, as the CLI renders it.
fn fresh(scene: &Scene, settings: &RenderSettings, camera: &Camera) -> Film {
    let mut s = scene.clone();
    s.camera = *camera;
    chiaro::render(&s, settings, &NoProgress).expect("fresh render")
}

fn frame<'a>(
    scene: &'a Scene,
    settings: &RenderSettings,
    camera: &Camera,
    cache: &mut FrameCache<'a>,
) -> Film {
    chiaro::render_frame(scene, settings, camera, &NoProgress, cache)
        .expect("frame")
        .0
}

#[test]
fn frames_through_the_cache_are_fresh_renders() {
    let cases: [(&str, &[Technique]); 3] = [
        (
            "cornell-box.toml",
            &[
                Technique::Phong,
                Technique::Preview,
                Technique::Whitted,
                Technique::Path,
                Technique::Radiosity,
            ],
        ),
        // Spheres: tessellated by their size in the view for scan conversion.
        (
            "whitted.toml",
            &[Technique::Gouraud, Technique::Phong, Technique::Whitted],
        ),
        // Image textures (mip-maps kept with the prepared scene).
        (
            "gltf/BoxTextured.glb",
            &[Technique::Phong, Technique::Preview],
        ),
    ];
    for (name, techniques) in cases {
        let scene = load(name);
        let a = scene.camera;
        let b = orbit(&a, 0.5, 1.2);
        for &technique in techniques {
            let settings = draft(&scene, technique);
            let mut cache = FrameCache::new();
            // A, B, then A again: the third frame reuses what the first two built.
            for (i, cam) in [a, b, a].iter().enumerate() {
                let film = frame(&scene, &settings, cam, &mut cache);
                assert!(
                    film == fresh(&scene, &settings, cam),
                    "{name} {technique:?}: frame {i} differs from a fresh render"
                );
            }
        }
    }
}

#[test]
fn the_cache_starts_afresh_when_its_inputs_change() {
    let scene = load("whitted.toml");
    let mut changed = scene.clone();
    changed.materials[0].diffuse = Vec3::new(0.1, 0.9, 0.2);
    let settings = draft(&scene, Technique::Phong);
    let cam = scene.camera;
    let mut cache = FrameCache::new();
    frame(&scene, &settings, &cam, &mut cache);
    let built = cache.misses();
    assert!(built > 0);
    // The same frame again builds nothing.
    frame(&scene, &settings, &cam, &mut cache);
    assert_eq!(cache.misses(), built);
    // Closer, the spheres are cut into more segments: the tessellated scene
    // is prepared again, and the picture is the fresh one.
    let near = orbit(&cam, 0.0, 3.0);
    let film = frame(&scene, &settings, &near, &mut cache);
    assert!(cache.misses() > built);
    assert!(film == fresh(&scene, &settings, &near));
    // Another scene (a material changed) is prepared afresh: its picture,
    // not the kept one.
    let before = cache.misses();
    let film = frame(&changed, &settings, &cam, &mut cache);
    assert!(cache.misses() > before);
    assert!(film == fresh(&changed, &settings, &cam));
    assert!(film != fresh(&scene, &settings, &cam));
    // Radiosity: the solution is kept for its settings and solved again
    // when they change.
    let cornell = load("cornell-box.toml");
    let mut cache = FrameCache::new();
    let mut radiosity = draft(&cornell, Technique::Radiosity);
    frame(&cornell, &radiosity, &cornell.camera, &mut cache);
    assert!(cache.holds_solution(&radiosity.radiosity));
    let solved = radiosity.radiosity.clone();
    radiosity.radiosity.tolerance *= 0.5;
    assert!(!cache.holds_solution(&radiosity.radiosity));
    let film = frame(&cornell, &radiosity, &cornell.camera, &mut cache);
    assert!(cache.holds_solution(&radiosity.radiosity));
    assert!(!cache.holds_solution(&solved));
    assert!(film == fresh(&cornell, &radiosity, &cornell.camera));
}

/// Records the warnings a render gives.
#[derive(Default)]
struct Warnings(std::sync::Mutex<Vec<String>>);

impl chiaro::Progress for Warnings {
    fn begin(&self, _stage: &str, _total: u64) {}
    fn advance(&self, _n: u64) {}
    fn warning(&self, text: &str) {
        self.0.lock().expect("lock").push(text.to_owned());
    }
}

#[test]
fn what_the_cache_keeps_counts_against_the_memory_budget() {
    use chiaro::CachedPiece;
    use chiaro::budget::ByteSize;
    let scene = load("cornell-box.toml");
    let cam = scene.camera;
    let radiosity = draft(&scene, Technique::Radiosity);
    let mut cache = FrameCache::new();
    frame(&scene, &radiosity, &cam, &mut cache);
    // The radiosity frame left its prepared scenes and its solution, each
    // counted by its size.
    let held = cache.held(chiaro::solution_bytes);
    let pieces: Vec<CachedPiece> = held.iter().map(|(p, _)| *p).collect();
    assert!(pieces.contains(&CachedPiece::Tessellated), "{held:?}");
    assert!(pieces.contains(&CachedPiece::Solution), "{held:?}");
    assert!(held.iter().all(|(_, b)| *b > 1000), "{held:?}");
    // A path frame within a budget that holds it and what the cache keeps:
    // nothing is dropped, and the solution stays for the next radiosity frame.
    let mut path = draft(&scene, Technique::Path);
    let own = chiaro::memory_estimate(&scene, &path).total();
    let kept: u64 = held.iter().map(|(_, b)| b).sum();
    path.memory_limit = Some(ByteSize(own + kept + (1 << 20)));
    let warnings = Warnings::default();
    let (film, _) = chiaro::render_frame(&scene, &path, &cam, &warnings, &mut cache).expect("fits");
    assert!(film == fresh(&scene, &path, &cam));
    assert!(cache.holds_solution(&radiosity.radiosity));
    let said = warnings.0.lock().expect("lock").join("\n");
    assert!(!said.contains("viewer's cache"), "{said}");
    // A budget that holds the frame but not the pieces it does not read:
    // those are dropped, said in a warning, and the picture is unchanged.
    path.memory_limit = Some(ByteSize(own + 1));
    let warnings = Warnings::default();
    let (film, _) =
        chiaro::render_frame(&scene, &path, &cam, &warnings, &mut cache).expect("fits alone");
    assert!(film == fresh(&scene, &path, &cam));
    assert!(!cache.holds_solution(&radiosity.radiosity));
    let left: Vec<CachedPiece> = cache
        .held(chiaro::solution_bytes)
        .iter()
        .map(|(p, _)| *p)
        .collect();
    assert_eq!(left, [CachedPiece::Analytic]);
    let said = warnings.0.lock().expect("lock").join("\n");
    assert!(
        said.contains("the viewer's cache dropped its radiosity solution")
            && said.contains("memory limit"),
        "{said}"
    );
    // A frame that does not fit by itself is refused, naming the limit.
    path.memory_limit = Some(ByteSize(own / 2));
    let err = chiaro::render_frame(&scene, &path, &cam, &NoProgress, &mut cache)
        .expect_err("over the budget");
    assert!(err.to_string().contains("memory limit"), "{err}");
}
