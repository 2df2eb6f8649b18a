//! Unit tests of `compare`: reference specs, seeds, the cache key,
//! progress labels and errors.

use super::*;

#[test]
fn parses_reference_specs() {
    assert_eq!(
        ReferenceSpec::parse("path:64").expect("valid"),
        ReferenceSpec::fixed(Technique::Path, 64)
    );
    assert_eq!(
        ReferenceSpec::parse("32").expect("valid").samples,
        ReferenceSamples::Fixed(32)
    );
    assert_eq!(
        ReferenceSpec::parse("whitted").expect("valid"),
        ReferenceSpec::fixed(Technique::Whitted, DEFAULT_REFERENCE_SPP)
    );
    for auto in ["path", "path:auto", "PATH:Auto"] {
        assert_eq!(
            ReferenceSpec::parse(auto).expect("valid"),
            ReferenceSpec::default(),
            "{auto}"
        );
    }
    assert_eq!(
        ReferenceSpec::parse("path:auto:512")
            .expect("valid")
            .samples,
        ReferenceSamples::Auto {
            fraction: DEFAULT_NOISE_FRACTION,
            cap: 512
        }
    );
    for bad in [
        "path:0",
        "path:-3",
        "path:x",
        "pth:4",
        "",
        "raytrace:4",
        "path:auto:0",
        "path:auto:x",
    ] {
        let e = ReferenceSpec::parse(bad);
        assert!(
            matches!(e, Err(CoreError::BadSetting { .. })),
            "{bad}: {e:?}"
        );
    }
}

#[test]
fn reference_seed_differs_and_is_stable() {
    assert_ne!(reference_seed(0), 0);
    assert_ne!(reference_seed(1), reference_seed(2));
    assert_eq!(reference_seed(7), reference_seed(7));
    assert!(reference_seed(u64::MAX) < 1 << 53);
}

#[test]
fn cache_key_tracks_scene_and_settings() {
    let scene = Scene::default();
    let s = RenderSettings::default();
    let k = cache_key(&scene, &s);
    assert_eq!(k.len(), 16);
    assert_eq!(k, cache_key(&scene, &s));
    let more = RenderSettings {
        samples: s.samples + 1,
        ..s.clone()
    };
    assert_ne!(k, cache_key(&scene, &more));
    let mut other = scene.clone();
    other.background = chiaro_core::Vec3::splat(0.5);
    assert_ne!(k, cache_key(&other, &s));
}

#[test]
fn labelled_progress_names_the_technique_and_forwards_cancel() {
    use std::sync::Mutex;
    #[derive(Default)]
    struct Record(Mutex<Vec<String>>, std::sync::atomic::AtomicBool);
    impl Progress for Record {
        fn begin(&self, stage: &str, total: u64) {
            if let Ok(mut v) = self.0.lock() {
                v.push(format!("{stage}/{total}"));
            }
        }
        fn advance(&self, _n: u64) {}
        fn cancelled(&self) -> bool {
            self.1.load(std::sync::atomic::Ordering::Relaxed)
        }
    }
    let rec = Record::default();
    let l = Labelled {
        inner: &rec,
        label: "phong",
    };
    l.begin("tiles", 9);
    assert!(!l.cancelled());
    rec.1.store(true, std::sync::atomic::Ordering::Relaxed);
    assert!(l.cancelled());
    assert_eq!(*rec.0.lock().expect("not poisoned"), ["phong: tiles/9"]);
}

#[test]
fn empty_technique_list_is_an_error() {
    let r = compare(
        &Scene::default(),
        &RenderSettings::default(),
        &[],
        &ReferenceSpec::default(),
        None,
        &chiaro_core::progress::NoProgress,
    );
    assert!(matches!(r, Err(Error::Core(CoreError::BadSetting { .. }))));
}
