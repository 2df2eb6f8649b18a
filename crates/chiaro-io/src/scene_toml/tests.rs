//! Unit tests of the `.toml` scene reader.

mod filter_tests {
    use crate::scene_toml::parse_scene;
    use chiaro_core::scene::PixelFilter;
    use std::path::Path;

    fn filter_of(text: &str) -> Result<PixelFilter, String> {
        parse_scene(text, Path::new("."), Path::new("t.toml"))
            .map(|l| l.scene.render.filter)
            .map_err(|e| e.to_string())
    }

    #[test]
    fn render_filter_parses_box_and_tent_and_defaults_to_box() {
        assert_eq!(filter_of("[render]\nwidth = 8\n"), Ok(PixelFilter::Box));
        assert_eq!(
            filter_of("[render]\nfilter = \"box\"\n"),
            Ok(PixelFilter::Box)
        );
        assert_eq!(
            filter_of("[render]\nfilter = \"tent\"\n"),
            Ok(PixelFilter::Tent)
        );
        let e = filter_of("[render]\nfilter = \"gauss\"\n").expect_err("unknown filter");
        assert!(e.contains("tent"), "{e}");
    }
}

mod instancing_tests {
    use crate::scene_toml::parse_scene;
    use chiaro_core::scene::Geometry;
    use std::path::Path;

    /// Objects with the same tessellated primitive and parameters share one
    /// mesh (instances); other parameters, or analytic spheres, do not.
    #[test]
    fn identical_primitives_share_one_mesh() {
        let text = r#"
[[object]]
primitive = "box"
size = [1, 2, 3]
[[object]]
primitive = "box"
size = [1, 2, 3]
transform = { translate = [4, 0, 0] }
[[object]]
primitive = "box"
size = [1, 2, 4]
[[object]]
primitive = "cylinder"
radius = 0.5
[[object]]
primitive = "cylinder"
radius = 0.5
transform = { rotate = [0, 90, 0] }
[[object]]
primitive = "sphere"
radius = 1
"#;
        let scene = parse_scene(text, Path::new("."), Path::new("t.toml"))
            .expect("parses")
            .scene;
        let meshes: Vec<Option<usize>> = scene
            .objects
            .iter()
            .map(|o| match o.geometry {
                Geometry::Mesh(m) => Some(m.index()),
                _ => None,
            })
            .collect();
        assert_eq!(meshes[0], meshes[1]);
        assert_ne!(meshes[0], meshes[2]);
        assert_eq!(meshes[3], meshes[4]);
        assert_ne!(meshes[0], meshes[3]);
        assert_eq!(meshes[5], None);
        assert_eq!(scene.meshes.len(), 3);
    }
}
