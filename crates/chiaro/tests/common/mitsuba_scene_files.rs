//! The seven Mitsuba 3 test scene files of the shared assets, for the
//! test that renders them and the agreement example
//! (`#[path = "..."] mod mitsuba_scene_files;`).

/// Each scene file (under `mitsuba3-test-scenes/tests/scenes/`) and the
/// stem of its reference (`refs/STEM_ref_rgb.exr`).
pub const SCENES: [(&str, &str); 7] = [
    (
        "floating_sphere/test_directional_direct.xml",
        "test_directional",
    ),
    ("infinite_mirrors/scene_path.xml", "scene"),
    ("instancing/test_instancing_path.xml", "test_instancing"),
    (
        "mesh_attributes/test_mesh_attributes_1_face_direct.xml",
        "test_mesh_attributes_1_face",
    ),
    (
        "mesh_attributes/test_mesh_attributes_3_face_direct.xml",
        "test_mesh_attributes_3_face",
    ),
    (
        "mesh_attributes/test_mesh_attributes_3_vertex_direct.xml",
        "test_mesh_attributes_3_vertex",
    ),
    (
        "texture_interp/test_texture_interp_direct.xml",
        "test_texture_interp",
    ),
];
