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

mod conductor_tests {
    use crate::scene_toml::parse_scene;
    use chiaro_core::Vec3;
    use chiaro_core::scene::ComplexIor;
    use std::path::Path;

    fn conductor_of(value: &str) -> Result<Option<ComplexIor>, String> {
        let text = format!(
            "[material.m]\nconductor = {value}\n[[object]]\nprimitive = \"sphere\"\nmaterial = \"m\"\n[[light]]\ntype = \"point\"\nposition = [0, 4, 0]\n"
        );
        parse_scene(&text, Path::new("."), Path::new("t.toml"))
            .map(|l| l.scene.materials[0].conductor)
            .map_err(|e| e.to_string())
    }

    #[test]
    fn conductor_by_name_or_complex_ior() {
        let au = conductor_of("\"Au\"").expect("named metal").expect("set");
        assert!((au.eta.x - 0.143_119).abs() < 1e-6 && (au.k.z - 1.603_215).abs() < 1e-6);
        let c = conductor_of("{ eta = [0.2, 0.9, 1.1], k = 3 }")
            .expect("explicit ior")
            .expect("set");
        assert_eq!((c.eta, c.k), (Vec3::new(0.2, 0.9, 1.1), Vec3::splat(3.0)));
        let e = conductor_of("\"Unobtainium\"").expect_err("unknown metal");
        assert!(e.contains("t.toml:2:") && e.contains("Au"), "{e}");
        let e = conductor_of("{ eta = 1 }").expect_err("k missing");
        assert!(e.contains('k'), "{e}");
        let e = conductor_of("{ eta = -1, k = 2 }").expect_err("negative eta");
        assert!(e.contains("eta"), "{e}");
        assert_eq!(
            conductor_of("{ eta = 1, k = 2 }").map(|c| c.is_some()),
            Ok(true)
        );
    }
}
