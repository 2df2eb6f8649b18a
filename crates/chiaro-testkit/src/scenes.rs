//! Small scenes shared by tests across crates: built in code from a few
//! parts (a quad, a point light, a camera), the shadow test scene, and,
//! with the `io` feature, the shipped scenes (the Cornell box from
//! `scenes/cornell-box.toml`) and scene text written by a test.

use chiaro_core::geometry::primitives;
use chiaro_core::scene::{
    AreaShape, Attenuation, Camera, Environment, Geometry, ImageTexture, Light, Material,
    MaterialId, Mesh, MeshId, Object, RenderSettings, Scene, ShadowMethod, Technique, Texture,
    Transform, WrapMode,
};
use glam::{Vec2, Vec3};

/// A white point light of `intensity` at `position`, falling off with the
/// inverse square of the distance.
pub fn point_light(position: Vec3, intensity: f32) -> Light {
    Light::Point {
        position,
        color: Vec3::ONE,
        intensity,
        attenuation: Attenuation::InverseSquare,
    }
}

/// `scene`'s own render settings with `technique` at `width` x `height`
/// pixels and `samples` samples a pixel.
pub fn settings(
    scene: &Scene,
    technique: Technique,
    width: u32,
    height: u32,
    samples: u32,
) -> RenderSettings {
    RenderSettings {
        technique,
        width,
        height,
        samples,
        ..scene.render.clone()
    }
}

/// A unit sphere of white (0.8 grey diffuse) at the origin, seen by the
/// default camera with the default settings and no lights.
pub fn white_sphere() -> Scene {
    let mut s = Scene::default();
    let white = s.add_material(Material::diffuse("white", Vec3::splat(0.8)));
    s.objects.push(Object {
        geometry: Geometry::Sphere { radius: 1.0 },
        material: white,
        ..Object::default()
    });
    s
}

/// Removes `s`'s ambient lights: what is left is direct light that
/// casts shadows, which every technique computes alike.
pub fn drop_ambient(s: &mut Scene) {
    s.lights.retain(|l| !matches!(l, Light::Ambient { .. }));
}

/// A camera at `eye` looking at `look_at` with a vertical field of view of
/// `fov_y_degrees`, the rest (up +y, clip planes) as [`Camera::default`].
pub fn camera(eye: Vec3, look_at: Vec3, fov_y_degrees: f32) -> Camera {
    Camera {
        eye,
        look_at,
        fov_y_degrees,
        ..Camera::default()
    }
}

/// The square `|x|, |y| <= half` in the plane `z`, facing +z, two
/// triangles, with uv (0, 0) at its lower left corner and (1, 1) at its
/// upper right.
pub fn square_mesh(half: f32, z: f32) -> Mesh {
    let r = half;
    Mesh {
        positions: vec![
            Vec3::new(-r, -r, z),
            Vec3::new(r, -r, z),
            Vec3::new(r, r, z),
            Vec3::new(-r, r, z),
        ],
        uvs: vec![
            Vec2::new(0.0, 0.0),
            Vec2::new(1.0, 0.0),
            Vec2::new(1.0, 1.0),
            Vec2::new(0.0, 1.0),
        ],
        indices: vec![[0, 1, 2], [0, 2, 3]],
        ..Mesh::default()
    }
}

/// Adds the parallelogram `corner + s edge_u + t edge_v` (`s, t` in
/// `[0, 1]`, facing `edge_u x edge_v`) as a faceted object of `material`;
/// returns its object index.
pub fn add_quad(
    s: &mut Scene,
    corner: Vec3,
    edge_u: Vec3,
    edge_v: Vec3,
    material: MaterialId,
) -> usize {
    let m = s.add_mesh(primitives::quad(corner, edge_u, edge_v));
    add_object(s, Geometry::Mesh(m), material, Transform::default())
}

/// Adds a faceted object (`smooth = false`) of `geometry` and `material`
/// placed by `transform`; returns its index.
pub fn add_object(
    s: &mut Scene,
    geometry: Geometry,
    material: MaterialId,
    transform: Transform,
) -> usize {
    add_named(s, "", (geometry, material), transform, false)
}

/// Adds the object `name` of `(geometry, material)` placed by `transform`,
/// with interpolated normals (`smooth`) or faceted, the rest as
/// [`Object::default`]; returns its index.
pub fn add_named(
    s: &mut Scene,
    name: &str,
    (geometry, material): (Geometry, MaterialId),
    transform: Transform,
    smooth: bool,
) -> usize {
    s.objects.push(Object {
        name: name.into(),
        geometry,
        material,
        smooth,
        transform,
        ..Object::default()
    });
    s.objects.len() - 1
}

/// The placement that moves an object by `offset` (no rotation or scale).
pub fn translate(offset: Vec3) -> Transform {
    Transform {
        translate: offset,
        ..Transform::default()
    }
}

/// An 8 x 4 latitude-longitude environment image named "env": blue, its
/// green rising by 0.1 a row from 0.4 at the top; wraps around.
pub fn sky_image() -> ImageTexture {
    ImageTexture {
        source: "env".into(),
        width: 8,
        height: 4,
        texels: (0..32)
            .map(|i| [0.2, 0.4 + (i / 8) as f32 * 0.1, 0.9, 1.0])
            .collect(),
        wrap: WrapMode::Repeat,
        ..Default::default()
    }
}

/// Lights `s` by the latitude-longitude `image` (added as a texture) as
/// its environment: radiance times `intensity`, turned by
/// `rotate_y_degrees` about +y, and seen as the background where
/// `as_background`.
pub fn set_environment(
    s: &mut Scene,
    image: ImageTexture,
    intensity: f32,
    rotate_y_degrees: f32,
    as_background: bool,
) {
    let texture = s.add_texture(Texture::Image(image));
    s.environment = Some(Environment {
        texture,
        intensity,
        rotate_y_degrees,
        as_background,
    });
}

/// Adds a 14 x 14 grid of `mesh` objects of `material`, one unit apart in
/// the plane z = 0 and centred on the origin, and the camera that frames
/// it (from (0, -4.5, 8), z up, 60 degrees): the scene of the scan
/// converter's and the web viewer's grid benchmarks.
pub fn add_grid_of(s: &mut Scene, mesh: MeshId, material: MaterialId) {
    for i in 0..14 {
        for j in 0..14 {
            s.objects.push(Object {
                geometry: Geometry::Mesh(mesh),
                material,
                transform: translate(Vec3::new(i as f32 - 6.5, j as f32 - 6.5, 0.0)),
                ..Object::default()
            });
        }
    }
    s.camera = Camera {
        up: Vec3::Z,
        near: 0.1,
        far: 100.0,
        ..camera(Vec3::new(0.0, -4.5, 8.0), Vec3::ZERO, 60.0)
    };
}

/// The six faces of a box as quads of its corners (corner `k` takes the
/// high end on x, y, z where bit 1, 2, 4 of `k` is set), wound outwards.
pub const BOX_FACES: [[usize; 4]; 6] = [
    [0, 4, 6, 2],
    [1, 3, 7, 5],
    [0, 1, 5, 4],
    [2, 6, 7, 3],
    [0, 2, 3, 1],
    [4, 5, 7, 6],
];

/// Corner `k` (0..8, bits as in [`BOX_FACES`]) of the box from `lo` to `hi`.
pub fn box_corner(lo: Vec3, hi: Vec3, k: usize) -> Vec3 {
    Vec3::new(
        if k & 1 == 0 { lo.x } else { hi.x },
        if k & 2 == 0 { lo.y } else { hi.y },
        if k & 4 == 0 { lo.z } else { hi.z },
    )
}

/// Appends to OBJ text the box from `lo` to `hi` (faces wound outwards, or
/// inwards) as 8 vertices and 6 quads, after the `base` vertices before it.
pub fn obj_box(obj: &mut String, base: usize, lo: Vec3, hi: Vec3, inward: bool) {
    for k in 0..8 {
        let p = box_corner(lo, hi, k);
        obj.push_str(&format!("v {} {} {}\n", p.x, p.y, p.z));
    }
    for f in BOX_FACES {
        let f = if inward { [f[0], f[3], f[2], f[1]] } else { f };
        let [a, b, c, d] = f.map(|i| base + i + 1);
        obj.push_str(&format!("f {a} {b} {c} {d}\n"));
    }
}

/// The Cornell box's white albedo (Cornell's measured data as the
/// community's RGB, as in `scenes/cornell-box.toml`).
pub const CORNELL_WHITE: Vec3 = Vec3::new(0.725, 0.71, 0.68);
/// The Cornell box's red (left wall) albedo.
pub const CORNELL_RED: Vec3 = Vec3::new(0.63, 0.065, 0.05);
/// The Cornell box's green (right wall) albedo.
pub const CORNELL_GREEN: Vec3 = Vec3::new(0.14, 0.45, 0.091);

/// Adds the unit box's walls, all facing inwards, with materials `mats`:
/// floor, ceiling, back, left, right, and (if `closed`) front, as the
/// next five (six) objects.
pub fn add_unit_box(s: &mut Scene, mats: [MaterialId; 6], closed: bool) {
    let (x, y, z) = (Vec3::X, Vec3::Y, Vec3::Z);
    add_quad(s, Vec3::ZERO, z, x, mats[0]);
    add_quad(s, y, x, z, mats[1]);
    add_quad(s, Vec3::ZERO, x, y, mats[2]);
    add_quad(s, Vec3::ZERO, y, z, mats[3]);
    add_quad(s, x, z, y, mats[4]);
    if closed {
        add_quad(s, z, y, x, mats[5]);
    }
}

/// The Cornell box at unit size, built in code: the shipped box's albedos
/// and light radiance (17, 12, 4), with the light a one-sided quad area
/// light just under the ceiling and two blocks of the same proportions.
/// For tests whose settings are in scene units of a unit box (radiosity
/// patch sizes) and for the radiosity benchmark; `cornell_box` (feature
/// `io`) is the shipped one. Objects: 0 floor, 1 ceiling, 2 back, 3 left
/// (red), 4 right (green), 5 short block, 6 tall block; materials 0 white,
/// 1 red, 2 green.
pub fn unit_cornell_box() -> Scene {
    let mut s = Scene::default();
    let white = s.add_material(Material::diffuse("white", CORNELL_WHITE));
    let red = s.add_material(Material::diffuse("red", CORNELL_RED));
    let green = s.add_material(Material::diffuse("green", CORNELL_GREEN));
    add_unit_box(&mut s, [white, white, white, red, green, white], false);
    for (half, at, rot) in [
        (Vec3::splat(0.15), Vec3::new(0.34, 0.15, 0.62), -17.0f32),
        (Vec3::new(0.15, 0.3, 0.15), Vec3::new(0.66, 0.3, 0.36), 17.0),
    ] {
        let m = s.add_mesh(primitives::box_mesh(half));
        let place = Transform {
            translate: at,
            rotate_degrees: Vec3::new(0.0, rot, 0.0),
            ..Default::default()
        };
        add_object(&mut s, Geometry::Mesh(m), white, place);
    }
    s.lights.push(Light::Area {
        shape: AreaShape::Quad {
            corner: Vec3::new(0.375, 0.999, 0.4),
            edge_u: Vec3::new(0.25, 0.0, 0.0),
            edge_v: Vec3::new(0.0, 0.0, 0.2),
        },
        color: Vec3::new(17.0, 12.0, 4.0),
        intensity: 1.0,
        two_sided: false,
    });
    s.camera = Camera {
        far: 100.0,
        ..camera(Vec3::new(0.5, 0.5, 2.3), Vec3::new(0.5, 0.5, 0.0), 32.0)
    };
    s
}

/// A sphere and a box on a plane, lit by one point light with inverse-square
/// attenuation, seen from above at an angle: the shadow test scene. All
/// geometry is triangles (the sphere tessellated), so every technique sees
/// the same surfaces. `size` is the image side in pixels.
pub fn shadow_test(size: u32) -> Scene {
    let mut s = Scene::default();
    let white = s.add_material(Material {
        specular: Vec3::splat(0.3),
        shininess: 30.0,
        ..Material::diffuse("white", Vec3::splat(0.7))
    });
    let red = s.add_material(Material {
        specular: Vec3::splat(0.5),
        shininess: 60.0,
        ..Material::diffuse("red", Vec3::new(0.7, 0.15, 0.1))
    });
    let blue = s.add_material(Material::diffuse("blue", Vec3::new(0.15, 0.2, 0.7)));
    let plane = s.add_mesh(primitives::plane(4.0, 8));
    let sphere = s.add_mesh(primitives::uv_sphere(0.8, 32, 16));
    let cube = s.add_mesh(primitives::cube());
    let part = (Geometry::Mesh(plane), white);
    add_named(&mut s, "floor", part, Transform::default(), false);
    let ball = translate(Vec3::new(-0.9, 0.8, 0.3));
    add_named(&mut s, "ball", (Geometry::Mesh(sphere), red), ball, true);
    let placed = Transform {
        translate: Vec3::new(1.2, 0.5, -0.4),
        rotate_degrees: Vec3::new(0.0, 25.0, 0.0),
        scale: Vec3::splat(0.5),
        ..Default::default()
    };
    add_named(&mut s, "box", (Geometry::Mesh(cube), blue), placed, false);
    s.lights.push(Light::Ambient {
        color: Vec3::ONE,
        intensity: 0.1,
    });
    s.lights.push(point_light(Vec3::new(-1.5, 5.0, -2.0), 20.0));
    s.camera = camera(Vec3::new(0.0, 4.5, -6.0), Vec3::new(0.0, 0.3, 0.0), 45.0);
    s.render.width = size;
    s.render.height = size;
    s.render.samples = 1;
    s.render.shadows = ShadowMethod::None;
    s
}

/// The scene file `relative` to the repository root, loaded as the CLI
/// loads it, at `size` x `size` pixels.
///
/// # Panics
/// If the file does not load (the repository's own scenes must).
#[cfg(feature = "io")]
pub fn repo_scene(relative: &str, size: u32) -> Scene {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../..")
        .join(relative);
    let mut s = chiaro_io::load_scene(&path)
        .unwrap_or_else(|e| panic!("{relative} loads: {e}"))
        .scene;
    s.render.width = size;
    s.render.height = size;
    s
}

/// The shipped scene `scenes/NAME.toml` at `size` x `size` pixels.
///
/// # Panics
/// If it does not load.
#[cfg(feature = "io")]
pub fn shipped(name: &str, size: u32) -> Scene {
    repo_scene(&format!("scenes/{name}.toml"), size)
}

/// The Cornell box as shipped (`scenes/cornell-box.toml`: Cornell's
/// measured geometry in millimetres, the emissive light quad, the
/// published camera) at `size` x `size` pixels. Objects: 0 floor,
/// 1 ceiling, 2 back wall, 3 left (red), 4 right (green), 5 light, 6 short
/// block, 7 tall block.
///
/// # Panics
/// If it does not load.
#[cfg(feature = "io")]
pub fn cornell_box(size: u32) -> Scene {
    shipped("cornell-box", size)
}

/// Loads the scene `text` as a file named `name` (its extension picks the
/// importer: `.toml`, `.gltf`, `.obj`) written to a fresh temporary folder,
/// which is removed again.
///
/// # Panics
/// If the folder cannot be written or the scene does not load.
#[cfg(feature = "io")]
pub fn load_text(name: &str, text: &str) -> Scene {
    use std::sync::atomic::{AtomicU32, Ordering};
    static NEXT: AtomicU32 = AtomicU32::new(0);
    let dir = std::env::temp_dir().join(format!(
        "chiaro-testkit-{}-{}",
        std::process::id(),
        NEXT.fetch_add(1, Ordering::Relaxed)
    ));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let path = dir.join(name);
    std::fs::write(&path, text).expect("writes the scene");
    let loaded = chiaro_io::load_scene(&path);
    let _ = std::fs::remove_dir_all(&dir);
    loaded.unwrap_or_else(|e| panic!("{name} loads: {e}")).scene
}

/// The scene file at `path`, loaded as the CLI loads it, its warnings
/// printed to stderr, and its settings with `technique`: for the examples,
/// which take a scene on the command line.
///
/// # Errors
/// The importer's error when the file does not load.
#[cfg(feature = "io")]
pub fn load_for(
    path: &std::path::Path,
    technique: chiaro_core::scene::Technique,
) -> Result<(Scene, chiaro_core::scene::RenderSettings), chiaro_io::IoError> {
    let loaded = chiaro_io::load_scene(path)?;
    for w in &loaded.warnings {
        eprintln!("warning: {w}");
    }
    let settings = chiaro_core::scene::RenderSettings {
        technique,
        ..loaded.scene.render.clone()
    };
    Ok((loaded.scene, settings))
}

/// An example's command line `NAME SCENE OUT [flags]`, read by
/// [`scene_command_line`].
#[cfg(feature = "io")]
#[derive(Debug)]
pub struct SceneCommandLine {
    /// All the arguments, for the flags.
    pub args: Vec<String>,
    /// `OUT`.
    pub out: String,
    /// `SCENE`, loaded with [`load_for`].
    pub scene: Scene,
    /// Its settings, with the example's technique.
    pub settings: chiaro_core::scene::RenderSettings,
}

/// The process's command line as a [`SceneCommandLine`] whose scene has
/// `technique` (`usage` is the error when `SCENE` or `OUT` is missing).
///
/// # Errors
/// `usage`, or the importer's error when the scene does not load.
#[cfg(feature = "io")]
pub fn scene_command_line(
    usage: &str,
    technique: chiaro_core::scene::Technique,
) -> Result<SceneCommandLine, Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let (Some(scene_path), Some(out)) = (args.get(1), args.get(2)) else {
        return Err(usage.into());
    };
    let out = out.clone();
    let (scene, settings) = load_for(std::path::Path::new(scene_path), technique)?;
    Ok(SceneCommandLine {
        args,
        out,
        scene,
        settings,
    })
}

/// Writes `film` as an 8-bit sRGB PNG (clamped, no tone map).
///
/// # Errors
/// The encoder's error when the file cannot be written.
#[cfg(feature = "io")]
pub fn save_png(
    film: &chiaro_core::film::Film,
    path: impl AsRef<std::path::Path>,
) -> image::ImageResult<()> {
    let bytes = crate::bench::srgb8_pixels(film);
    image::save_buffer(
        path,
        &bytes,
        film.width,
        film.height,
        image::ExtendedColorType::Rgb8,
    )
}
