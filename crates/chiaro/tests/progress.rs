//! Progress and cancellation of every technique: each stage reports as many
//! units as the total it announced, and a render asked to stop returns
//! `Cancelled` after at most a few more units (units are counted, not time).

use chiaro::scene::Technique;
use chiaro::{Error, Progress, RenderSettings, Scene};
use chiaro_core::error::CoreError;
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

fn shipped(name: &str) -> Scene {
    let path = format!("{}/../../scenes/{name}", env!("CARGO_MANIFEST_DIR"));
    chiaro::io::load_scene(std::path::Path::new(&path))
        .expect("the shipped scene loads")
        .scene
}

fn small(scene: &Scene, technique: Technique) -> RenderSettings {
    RenderSettings {
        technique,
        width: 48,
        height: 36,
        samples: 1,
        ..scene.render.clone()
    }
}

/// Records each stage's announced total and reported units; cancels once
/// `cancel_after` units are reported in all.
#[derive(Default)]
struct Recorder {
    stages: Mutex<Vec<(String, u64, u64)>>,
    done: AtomicU64,
    cancel_after: Option<u64>,
    /// `advance` calls after the cancel was first seen by the renderer.
    after_cancel: AtomicU64,
    cancelled: AtomicBool,
}

impl Progress for Recorder {
    fn begin(&self, stage: &str, total: u64) {
        let mut s = self.stages.lock().expect("not poisoned");
        s.push((stage.to_string(), total, 0));
    }
    fn advance(&self, n: u64) {
        let mut s = self.stages.lock().expect("not poisoned");
        if let Some(last) = s.last_mut() {
            last.2 += n;
        }
        self.done.fetch_add(n, Ordering::Relaxed);
        if self.cancelled.load(Ordering::Relaxed) {
            self.after_cancel.fetch_add(1, Ordering::Relaxed);
        }
    }
    fn cancelled(&self) -> bool {
        let done = self.done.load(Ordering::Relaxed);
        let stop = self.cancel_after.is_some_and(|n| done >= n);
        if stop {
            self.cancelled.store(true, Ordering::Relaxed);
        }
        stop
    }
}

// Scenes whose radiosity solves take well under a second.
const SCENES: [&str; 2] = ["cornell-box.toml", "teapot.toml"];

#[test]
fn every_stage_reports_its_announced_total() {
    for name in SCENES {
        let scene = shipped(name);
        for technique in chiaro::Technique::ALL {
            let rec = Recorder::default();
            chiaro::render(&scene, &small(&scene, technique), &rec).expect("renders");
            let stages = rec.stages.into_inner().expect("not poisoned");
            assert!(
                !stages.is_empty(),
                "{name} {technique:?}: no progress at all"
            );
            for (stage, total, done) in stages {
                assert!(
                    total > 0,
                    "{name} {technique:?}: stage `{stage}` announced no work"
                );
                assert_eq!(
                    done, total,
                    "{name} {technique:?}: stage `{stage}` reported {done} of {total} units"
                );
            }
        }
    }
}

#[test]
fn every_technique_stops_soon_after_cancel() {
    // A pool of known size bounds the units in flight at the cancel.
    let threads = 2;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .expect("a pool");
    for name in SCENES {
        let scene = shipped(name);
        for technique in chiaro::Technique::ALL {
            // Units of the whole render, then cancel a third of the way in.
            let full = Recorder::default();
            let settings = small(&scene, technique);
            pool.install(|| chiaro::render(&scene, &settings, &full))
                .expect("renders");
            let total = full.done.load(Ordering::Relaxed);
            let at = (total / 3).max(1);
            let rec = Recorder {
                cancel_after: Some(at),
                ..Recorder::default()
            };
            let result = pool.install(|| chiaro::render(&scene, &settings, &rec));
            assert!(
                matches!(result, Err(Error::Core(CoreError::Cancelled))),
                "{name} {technique:?}: cancel after {at} of {total} units did not return Cancelled"
            );
            let done = rec.done.load(Ordering::Relaxed);
            let late = rec.after_cancel.load(Ordering::Relaxed);
            // Each worker finishes at most the unit it is in.
            assert!(
                late <= threads as u64,
                "{name} {technique:?}: {late} units reported after the cancel was seen"
            );
            assert!(
                done < total,
                "{name} {technique:?}: did all its {total} units before stopping"
            );
        }
    }
}
