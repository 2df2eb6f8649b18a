//! Every technique over one scene, for the importers' tests
//! (`#[path = "common/techniques.rs"] mod techniques;`).

use chiaro::progress::NoProgress;
use chiaro::{Scene, Technique};

/// Renders `scene` (named `what` in failures) at 24x24, one sample, with
/// every technique: each gives a film of that size with finite colours.
pub fn renders_with_every_technique(scene: &Scene, what: &str) {
    for technique in Technique::ALL {
        let mut s = scene.render.clone();
        s.technique = technique;
        s.width = 24;
        s.height = 24;
        s.samples = 1;
        let film = chiaro::render(scene, &s, &NoProgress)
            .unwrap_or_else(|e| panic!("{what} with {}: {e}", technique.name()));
        assert_eq!((film.width, film.height), (24, 24));
        assert!(
            film.color.iter().all(|c| c.is_finite()),
            "{what}: {}",
            technique.name()
        );
    }
}
