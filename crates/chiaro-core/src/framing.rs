//! Automatic camera placement for a scene that brings no camera (a model
//! file opened on its own), used by the loader, the CLI, serve and Python.
//!
//! - **Exterior** (the usual case): the model's front (+z for y up, -y for
//!   z up) seen from [`ELEVATION_DEGREES`] above, so an object shows a
//!   little of its top and a flat test board facing front is read head-on;
//!   the camera's distance and aim solved so that the model's projected
//!   vertices span 80 % of the frame along the tighter axis, centred.
//!   Only vertices that triangles use count (a stray unreferenced vertex
//!   does not shrink the model), placed by each object's full matrix
//!   (negative scales included).
//! - **Interior**: when a point inside the bounding box sees geometry in
//!   nearly every direction, mostly front faces, and the model seen from
//!   outside shows mostly back faces (a room whose walls face inwards), the
//!   camera stands inside at that point, backed towards the near wall,
//!   looking level at the far wall's centre. A solid model's inside sees
//!   back faces, an open scene escapes, a hollow object (a helmet) shows
//!   front faces outside, so none of them counts. Front and back follow
//!   the winding as placed: an object whose matrix mirrors it (negative
//!   determinant) has its winding turned, as glTF specifies.

use crate::accel::{WatertightRay, intersect_sphere};
use crate::geometry::{Aabb, Ray};
use crate::scene::{Camera, Geometry, Scene};
use glam::Vec3;

/// Fraction of the frame (along its tighter axis) a framed model spans.
pub const FILL: f32 = 0.8;
/// How far above the horizontal an exterior camera looks down at the
/// model's front, degrees.
pub const ELEVATION_DEGREES: f32 = 18.0;
/// Fraction of probe rays that must hit for a candidate eye to be inside.
pub const INTERIOR_HITS: f32 = 0.9;
/// Fraction of those hits that must be front faces.
pub const INTERIOR_FRONT: f32 = 0.75;
/// Vertical field of view of an interior camera, degrees.
pub const INTERIOR_FOV: f32 = 60.0;

/// Which world axis is up: glTF and most OBJ files are +y up, many CAD
/// and scan files (and Blender's own space) +z up.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum UpAxis {
    /// +y up; the model's front faces +z.
    #[default]
    Y,
    /// +z up; the model's front faces -y.
    Z,
}

impl UpAxis {
    /// The unit up vector.
    pub fn vector(self) -> Vec3 {
        match self {
            UpAxis::Y => Vec3::Y,
            UpAxis::Z => Vec3::Z,
        }
    }

    /// The unit vector out of the model's front (towards a front view's eye).
    pub fn front(self) -> Vec3 {
        match self {
            UpAxis::Y => Vec3::Z,
            UpAxis::Z => Vec3::NEG_Y,
        }
    }

    /// `y` or `z`, as on the command line.
    pub fn name(self) -> &'static str {
        match self {
            UpAxis::Y => "y",
            UpAxis::Z => "z",
        }
    }
}

/// A camera placed by [`frame_scene`], and whether it stands inside.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Framing {
    /// The camera.
    pub camera: Camera,
    /// Where the scene was judged an interior: the open point inside.
    pub inside: Option<Inside>,
}

/// The point from which a scene was judged an interior.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Inside {
    /// The candidate point that passed the test (free space, walls around).
    pub point: Vec3,
    /// The mean distance from it to the geometry its probes hit.
    pub mean_distance: f32,
    /// The distance from `point` straight up to the ceiling (the first
    /// surface hit, else the bounds' top).
    pub to_ceiling: f32,
    /// The distance from `point` down to the floor: the bounds' bottom
    /// (furniture below the point does not count).
    pub to_floor: f32,
    /// The interior's extent along the two horizontal axes (the model's
    /// front axis, then its side axis), from its bounds.
    pub horizontal_extent: [f32; 2],
    /// The up axis the interior was judged with.
    pub up: UpAxis,
}

/// Calls `f` with every world-space point of the scene's drawn geometry:
/// the mesh vertices that a triangle uses, and the corners of each
/// sphere's box. Non-finite points are skipped.
pub fn for_each_world_point(scene: &Scene, mut f: impl FnMut(Vec3)) {
    let mut used = Vec::new();
    for o in &scene.objects {
        let m = o.transform.world_from_object();
        match o.geometry {
            Geometry::Mesh(id) => {
                if let Some(mesh) = scene.meshes.get(id.index()) {
                    used.clear();
                    used.resize(mesh.positions.len(), false);
                    for i in mesh.indices.iter().flatten() {
                        if let Some(u) = used.get_mut(*i as usize) {
                            *u = true;
                        }
                    }
                    for (p, _) in mesh.positions.iter().zip(&used).filter(|(_, u)| **u) {
                        let q = m.transform_point3(*p);
                        if q.is_finite() {
                            f(q);
                        }
                    }
                }
            }
            Geometry::Sphere { radius } => {
                for corner in 0..8 {
                    let s = Vec3::new(
                        if corner & 1 == 0 { -radius } else { radius },
                        if corner & 2 == 0 { -radius } else { radius },
                        if corner & 4 == 0 { -radius } else { radius },
                    );
                    let q = m.transform_point3(s);
                    if q.is_finite() {
                        f(q);
                    }
                }
            }
        }
    }
}

/// The largest world coordinate (in absolute value) [`frame_scene`] works
/// with: it squares distances in `f32`, which overflows past about 1.8e19.
pub const MAX_FRAMED_COORDINATE: f32 = 1e18;

/// `x` as a person reads it: exponent form outside `[1e-4, 1e6)`.
fn plain_number(x: f32) -> String {
    if x != 0.0 && x.is_finite() && !(1e-4..1e6).contains(&x.abs()) {
        format!("{x:e}")
    } else {
        format!("{x}")
    }
}

/// `Ok` when every world point of the scene is finite and within
/// [`MAX_FRAMED_COORDINATE`], so that [`frame_scene`] can place a camera;
/// otherwise a message naming the first point that is not: its mesh (or
/// sphere), object, vertex index and position (`mesh "m" (object "o"):
/// vertex 12 at (1e30, 0, 0)`), with how many points are out of range.
pub fn check_framable(scene: &Scene) -> Result<(), String> {
    let bad = |q: Vec3| !q.is_finite() || q.abs().max_element() > MAX_FRAMED_COORDINATE;
    let at = |q: Vec3| {
        format!(
            "({}, {}, {})",
            plain_number(q.x),
            plain_number(q.y),
            plain_number(q.z)
        )
    };
    let mut first: Option<String> = None;
    let mut count = 0usize;
    for o in &scene.objects {
        let m = o.transform.world_from_object();
        match o.geometry {
            Geometry::Mesh(id) => {
                let Some(mesh) = scene.meshes.get(id.index()) else {
                    continue;
                };
                for (i, p) in mesh.positions.iter().enumerate() {
                    let q = m.transform_point3(*p);
                    if bad(q) {
                        count += 1;
                        first.get_or_insert_with(|| {
                            format!(
                                "mesh \"{}\" (object \"{}\"): vertex {i} at {}",
                                mesh.name,
                                o.name,
                                at(q)
                            )
                        });
                    }
                }
            }
            Geometry::Sphere { radius } => {
                let centre = m.transform_point3(Vec3::ZERO);
                let reach = m.transform_vector3(Vec3::splat(radius)).abs().max_element();
                if bad(centre) || !(reach.is_finite() && reach <= MAX_FRAMED_COORDINATE) {
                    count += 1;
                    first.get_or_insert_with(|| {
                        format!(
                            "sphere \"{}\": centre {} radius {}",
                            o.name,
                            at(centre),
                            plain_number(reach)
                        )
                    });
                }
            }
        }
    }
    match first {
        None => Ok(()),
        Some(what) => {
            let more = if count > 1 {
                format!(" (and {} more points out of range)", count - 1)
            } else {
                String::new()
            };
            Err(format!(
                "{what}{more}: the camera cannot be placed automatically for coordinates \
                 beyond {} (or not finite)",
                plain_number(MAX_FRAMED_COORDINATE)
            ))
        }
    }
}

/// The world-space bounds of every object (mesh vertices, sphere boxes).
pub fn world_bounds(scene: &Scene) -> Aabb {
    let mut b = Aabb::EMPTY;
    for_each_world_point(scene, |p| b = b.grow(p));
    b
}

/// Fraction of a model's extent, from its lowest point, that counts as its
/// base slab in [`looks_z_up`].
pub const BASE_SLAB: f32 = 0.02;

/// True when a model read with +y up is probably +z up (a scan or CAD part
/// lying on its back): its extent along y is the smallest of the three,
/// and it rests on a flat base at its lowest z: at least 5 % of its drawn
/// vertices lie in the slab of [`BASE_SLAB`] of the z extent above the z
/// minimum, and at least three times the share in the same slab at the y
/// minimum. (A y-up scan has its base at the y minimum; a y-up car, long
/// along z and low along y, has no such slab at its nose.)
pub fn looks_z_up(scene: &Scene) -> bool {
    let b = world_bounds(scene);
    if b.is_empty() {
        return false;
    }
    let ext = b.extent();
    if !(ext.y < ext.x && ext.y < ext.z) {
        return false;
    }
    let (mut n, mut base_y, mut base_z) = (0usize, 0usize, 0usize);
    for_each_world_point(scene, |p| {
        n += 1;
        base_y += usize::from(p.y - b.min.y <= BASE_SLAB * ext.y);
        base_z += usize::from(p.z - b.min.z <= BASE_SLAB * ext.z);
    });
    base_z as f32 >= 0.05 * n as f32 && base_z >= 3 * base_y
}

/// Places a camera for `scene` (see the module documentation) with `up` as
/// the vertical, for images of `aspect` = width / height. `fov_y_degrees`
/// replaces the default field of view (45 degrees outside, 60 inside). An
/// empty scene gets the default camera.
pub fn frame_scene(scene: &Scene, up: UpAxis, aspect: f32, fov_y_degrees: Option<f32>) -> Framing {
    let bounds = world_bounds(scene);
    if bounds.is_empty() {
        return Framing {
            camera: Camera::default(),
            inside: None,
        };
    }
    if let Some((camera, inside)) = interior_camera(scene, bounds, up, fov_y_degrees) {
        return Framing {
            camera,
            inside: Some(inside),
        };
    }
    Framing {
        camera: exterior_camera(scene, bounds, up, aspect, fov_y_degrees),
        inside: None,
    }
}

/// The orthographic camera that frames what the perspective `camera`
/// frames at its target: the same eye, target and clip planes, with a film
/// as high as the field of view is at the target's distance
/// (`half_height = |look_at - eye| tan(fov_y / 2)`). How an orthographic
/// scene camera keeps its projection when the scene is framed again.
pub fn orthographic_view(camera: &Camera) -> Camera {
    let distance = (camera.look_at - camera.eye).length();
    let half_height = distance * (0.5 * camera.fov_y_degrees.to_radians()).tan();
    Camera {
        projection: crate::scene::Projection::Orthographic {
            half_height: half_height.max(f32::MIN_POSITIVE),
        },
        ..*camera
    }
}

/// The front view from [`ELEVATION_DEGREES`] above, fitted to the
/// projected vertices.
fn exterior_camera(
    scene: &Scene,
    bounds: Aabb,
    up: UpAxis,
    aspect: f32,
    fov_y_degrees: Option<f32>,
) -> Camera {
    let base = Camera::default();
    let fov = fov_y_degrees.unwrap_or(base.fov_y_degrees);
    let el = ELEVATION_DEGREES.to_radians();
    let upv = up.vector();
    let front = up.front();
    // Unit vector from the target towards the eye.
    let d = (front * el.cos() + upv * el.sin()).normalize();
    let forward = -d;
    let right = forward.cross(upv).normalize();
    let cam_up = right.cross(forward);
    let tan_y = (0.5 * fov.to_radians()).tan();
    let tan_x = aspect.clamp(0.05, 20.0) * tan_y;
    let radius = (0.5 * bounds.diagonal()).max(1e-6);

    // Distance that puts every point within FILL of the frame's half-extents
    // around the target `c`: depth(p) = t - (p - c).d must reach
    // |x| / (FILL tan_x) and |y| / (FILL tan_y).
    let distance = |c: Vec3| {
        let mut t = 0.0f32;
        for_each_world_point(scene, |p| {
            let q = p - c;
            let need =
                (q.dot(right).abs() / (FILL * tan_x)).max(q.dot(cam_up).abs() / (FILL * tan_y));
            t = t.max(q.dot(d) + need);
        });
        t.max(radius * 1e-3)
    };
    // Aim at the middle of the projected extent, not the box centre, so the
    // model is centred in the frame (the projection is not symmetric).
    let mut c = bounds.center();
    let mut t = distance(c);
    for _ in 0..3 {
        let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
        for_each_world_point(scene, |p| {
            let q = p - c;
            let depth = (t - q.dot(d)).max(1e-6 * t);
            let s = Vec3::new(
                q.dot(right) / (depth * tan_x),
                q.dot(cam_up) / (depth * tan_y),
                0.0,
            );
            lo = lo.min(s);
            hi = hi.max(s);
        });
        let mid = 0.5 * (lo + hi);
        c += right * (mid.x * t * tan_x) + cam_up * (mid.y * t * tan_y);
        t = distance(c);
    }
    let (mut near_depth, mut far_depth) = (f32::INFINITY, 0.0f32);
    for_each_world_point(scene, |p| {
        let depth = t - (p - c).dot(d);
        near_depth = near_depth.min(depth);
        far_depth = far_depth.max(depth);
    });
    Camera {
        eye: c + d * t,
        look_at: c,
        up: upv,
        fov_y_degrees: fov,
        near: (0.5 * near_depth).max(t * 1e-4),
        far: 2.0 * far_depth.max(t),
        ..Default::default()
    }
}

/// Nearest hit of each probe ray from `eye` along `dirs`: `(t,
/// front_facing)`, `None` where the ray escapes.
fn probe(scene: &Scene, eye: Vec3, dirs: &[Vec3]) -> Vec<Option<(f32, bool)>> {
    let rays: Vec<Ray> = dirs.iter().map(|&d| Ray::new(eye, d)).collect();
    probe_rays(scene, &rays)
}

/// Nearest hit of each ray, as [`probe`]. Brute force over every triangle
/// (a handful of rays, one pass over the geometry, no acceleration
/// structure to build).
fn probe_rays(scene: &Scene, probes: &[Ray]) -> Vec<Option<(f32, bool)>> {
    let rays: Vec<WatertightRay> = probes.iter().map(WatertightRay::new).collect();
    let dirs: Vec<Vec3> = probes.iter().map(|r| r.dir).collect();
    let mut best: Vec<Option<(f32, bool)>> = vec![None; dirs.len()];
    let mut consider = |i: usize, t: f32, front: bool| {
        if t > 0.0 && best[i].is_none_or(|(b, _)| t < b) {
            best[i] = Some((t, front));
        }
    };
    let mut world: Vec<Vec3> = Vec::new();
    for o in &scene.objects {
        let m = o.transform.world_from_object();
        // A mirroring matrix turns the winding: the front is then the side
        // the stored winding calls the back (glTF 2.0, section 3.7.4).
        let mirrored = m.determinant() < 0.0;
        match o.geometry {
            Geometry::Mesh(id) => {
                let Some(mesh) = scene.meshes.get(id.index()) else {
                    continue;
                };
                world.clear();
                world.extend(mesh.positions.iter().map(|p| m.transform_point3(*p)));
                for tri in &mesh.indices {
                    let (Some(&a), Some(&b), Some(&c)) = (
                        world.get(tri[0] as usize),
                        world.get(tri[1] as usize),
                        world.get(tri[2] as usize),
                    ) else {
                        continue;
                    };
                    let ng = (b - a).cross(c - a);
                    for (i, r) in rays.iter().enumerate() {
                        if let Some((t, _, _)) = r.intersect(a, b, c) {
                            consider(i, t, (ng.dot(dirs[i]) < 0.0) != mirrored);
                        }
                    }
                }
            }
            Geometry::Sphere { radius } => {
                let centre = m.transform_point3(Vec3::ZERO);
                let r = m.transform_vector3(Vec3::new(radius, 0.0, 0.0)).length();
                for (i, ray) in probes.iter().enumerate() {
                    if let Some(t) = intersect_sphere(ray, centre, r) {
                        consider(i, t, (ray.origin - centre).length() >= r);
                    }
                }
            }
        }
    }
    best
}

/// 64 directions spread evenly over the sphere (a Fibonacci lattice).
fn probe_directions() -> Vec<Vec3> {
    let n = 64;
    let golden = std::f32::consts::PI * (3.0 - 5f32.sqrt());
    (0..n)
        .map(|i| {
            let z = 1.0 - (2.0 * i as f32 + 1.0) / n as f32;
            let r = (1.0 - z * z).max(0.0).sqrt();
            let phi = golden * i as f32;
            Vec3::new(r * phi.cos(), z, r * phi.sin())
        })
        .collect()
}

/// True when the probes from a point describe an interior: at least
/// [`INTERIOR_HITS`] of them hit, and at least [`INTERIOR_FRONT`] of the
/// hits are front faces.
fn is_interior(hits: &[Option<(f32, bool)>]) -> bool {
    let hit = hits.iter().flatten().count();
    let front = hits.iter().flatten().filter(|(_, f)| *f).count();
    hit as f32 >= INTERIOR_HITS * hits.len() as f32 && front as f32 >= INTERIOR_FRONT * hit as f32
}

/// True when the scene, looked at from outside (rays from a sphere round
/// the box towards its centre), shows mostly back faces: the outside of
/// walls that face in. A hollow object (a helmet's lining faces in) shows
/// its front faces outside and so is not an interior.
fn backs_outside(scene: &Scene, bounds: Aabb, dirs: &[Vec3]) -> bool {
    let c = bounds.center();
    let r = bounds.diagonal().max(1e-6);
    let rays: Vec<Ray> = dirs.iter().map(|&d| Ray::new(c + d * r, -d)).collect();
    let hits = probe_rays(scene, &rays);
    let hit = hits.iter().flatten().count();
    let back = hits.iter().flatten().filter(|(_, f)| !*f).count();
    hit > 0 && back * 2 >= hit
}

/// The camera inside an interior, or `None` when no candidate point (the
/// box's centre, at half, 0.65 and 0.35 of its height) is inside.
fn interior_camera(
    scene: &Scene,
    bounds: Aabb,
    up: UpAxis,
    fov_y_degrees: Option<f32>,
) -> Option<(Camera, Inside)> {
    let upv = up.vector();
    let dirs = probe_directions();
    if !backs_outside(scene, bounds, &dirs) {
        return None;
    }
    let centre = bounds.center();
    let height = bounds.extent().dot(upv);
    let low = bounds.min.dot(upv);
    let (eye0, mean_distance) = [0.5, 0.65, 0.35].into_iter().find_map(|h| {
        let e = centre + upv * (low + h * height - centre.dot(upv));
        let hits = probe(scene, e, &dirs);
        let (n, sum) = hits
            .iter()
            .flatten()
            .fold((0, 0.0), |(n, s), (t, _)| (n + 1, s + t));
        is_interior(&hits).then_some((e, sum / n.max(1) as f32))
    })?;
    // Look along the longer horizontal side, away from the model's front.
    let ext = bounds.extent();
    let front = up.front();
    let side = front.cross(upv);
    let dir = if ext.dot(front.abs()) >= ext.dot(side.abs()) {
        -front
    } else {
        -side
    };
    let diag = bounds.diagonal();
    let both = probe(scene, eye0, &[-dir, dir]);
    let back = both[0].map_or(0.4 * ext.dot(dir.abs()), |(t, _)| 0.7 * t);
    let eye = eye0 - dir * back;
    let ahead = both[1].map_or(0.5 * ext.dot(dir.abs()), |(t, _)| t);
    let camera = Camera {
        eye,
        look_at: eye + dir * (back + ahead),
        up: upv,
        fov_y_degrees: fov_y_degrees.unwrap_or(INTERIOR_FOV),
        near: (diag * 1e-4).max(1e-6),
        far: 2.0 * diag.max(1e-3),
        ..Default::default()
    };
    let vertical = probe(scene, eye0, &[upv]);
    let inside = Inside {
        point: eye0,
        mean_distance,
        to_ceiling: vertical[0].map_or(bounds.max.dot(upv) - eye0.dot(upv), |(t, _)| t),
        to_floor: eye0.dot(upv) - low,
        horizontal_extent: [ext.dot(front.abs()), ext.dot(side.abs())],
        up,
    };
    Some((camera, inside))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::primitives::{box_mesh, uv_sphere};
    use crate::scene::{Mesh, Object, Transform};

    fn scene_of(meshes: Vec<(Mesh, Transform)>) -> Scene {
        let mut s = Scene::default();
        for (m, t) in meshes {
            let id = s.add_mesh(m);
            s.objects.push(Object {
                geometry: Geometry::Mesh(id),
                transform: t,
                ..Object::default()
            });
        }
        s
    }

    /// A closed room (walls facing in) with a table in the middle.
    fn room() -> Scene {
        let mut walls = box_mesh(Vec3::new(3.0, 1.5, 4.0));
        for t in &mut walls.indices {
            t.swap(1, 2);
        }
        walls.normals.iter_mut().for_each(|n| *n = -*n);
        let table = box_mesh(Vec3::new(0.6, 0.4, 0.6));
        scene_of(vec![
            (walls, Transform::default()),
            (
                table,
                Transform {
                    translate: Vec3::new(0.0, -1.1, 0.0),
                    ..Transform::default()
                },
            ),
        ])
    }

    /// A box shell facing out round a smaller one facing in.
    fn hollow() -> Scene {
        let mut lining = box_mesh(Vec3::splat(0.9));
        for t in &mut lining.indices {
            t.swap(1, 2);
        }
        scene_of(vec![
            (box_mesh(Vec3::ONE), Transform::default()),
            (lining, Transform::default()),
        ])
    }

    /// Issue 47: one vertex at 1e30 overflowed the framing into a NaN
    /// camera, reported as a bad `camera.eye`; the check names the vertex.
    #[test]
    fn absurd_coordinates_are_named_before_framing() {
        let mut mesh = box_mesh(Vec3::ONE);
        mesh.name = "crate".into();
        assert_eq!(
            check_framable(&scene_of(vec![(mesh.clone(), Transform::default())])),
            Ok(())
        );
        mesh.positions[5].x = 1e30;
        mesh.positions[7].z = -3e19;
        let mut scene = scene_of(vec![(mesh, Transform::default())]);
        scene.objects[0].name = "lid".into();
        let msg = check_framable(&scene).expect_err("1e30");
        assert!(
            msg.starts_with("mesh \"crate\" (object \"lid\"): vertex 5 at (1e30, ")
                && msg.contains("and 1 more")
                && msg.contains("beyond 1e18"),
            "{msg}"
        );
    }

    #[test]
    fn a_room_is_framed_from_inside_towards_the_far_wall() {
        let f = frame_scene(&room(), UpAxis::Y, 4.0 / 3.0, None);
        let inside = f.inside.expect("an interior");
        assert!(inside.mean_distance > 1.0 && inside.mean_distance < 5.0);
        // The point is at mid-height of the 3-unit room (y from -1.5 to
        // 1.5), above the table.
        assert!((inside.to_ceiling - 1.5).abs() < 1e-3, "{inside:?}");
        assert!((inside.to_floor - 1.5).abs() < 1e-3, "{inside:?}");
        assert_eq!(inside.horizontal_extent, [8.0, 6.0]);
        let c = f.camera;
        let inside = |p: Vec3| p.abs().cmplt(Vec3::new(3.0, 1.5, 4.0)).all();
        assert!(inside(c.eye), "eye {}", c.eye);
        // The room is longest along z: look along -z, level, at the far wall.
        let d = (c.look_at - c.eye).normalize();
        assert!((d - Vec3::NEG_Z).length() < 1e-5, "{d}");
        assert!((c.look_at.z + 4.0).abs() < 1e-3, "{}", c.look_at);
        assert!(c.eye.z > 1.0, "backed towards the near wall: {}", c.eye);
    }

    #[test]
    fn a_solid_model_or_an_open_box_is_framed_from_outside() {
        // The inside of a closed sphere sees back faces only.
        let s = scene_of(vec![(uv_sphere(1.0, 24, 12), Transform::default())]);
        let f = frame_scene(&s, UpAxis::Y, 1.0, None);
        assert!(f.inside.is_none());
        assert!(f.camera.eye.length() > 1.0);
        // A hollow object: an outer shell facing out, a lining facing in.
        let f = frame_scene(&hollow(), UpAxis::Y, 1.0, None);
        assert!(f.inside.is_none());
        // A room without its ceiling and one wall lets too many probes escape.
        let mut walls = box_mesh(Vec3::ONE);
        walls.indices.truncate(8);
        for t in &mut walls.indices {
            t.swap(1, 2);
        }
        let f = frame_scene(
            &scene_of(vec![(walls, Transform::default())]),
            UpAxis::Y,
            1.0,
            None,
        );
        assert!(f.inside.is_none());
    }

    #[test]
    fn exterior_framing_spans_the_fill_fraction_centred() {
        // A long bar: the projected vertices must reach FILL of the
        // frame's half-extent on the tighter axis, on both sides.
        let s = scene_of(vec![(
            box_mesh(Vec3::new(2.0, 0.3, 0.5)),
            Transform {
                translate: Vec3::new(5.0, -2.0, 1.0),
                ..Transform::default()
            },
        )]);
        for (up, aspect) in [(UpAxis::Y, 1.5), (UpAxis::Z, 0.75)] {
            let cam = frame_scene(&s, up, aspect, None).camera;
            let clip = cam.projection_matrix(aspect) * cam.view_matrix();
            let (mut lo, mut hi) = (Vec3::splat(9.0), Vec3::splat(-9.0));
            for_each_world_point(&s, |p| {
                let c = clip * p.extend(1.0);
                let n = c.truncate() / c.w;
                lo = lo.min(n);
                hi = hi.max(n);
            });
            let span = (hi - lo).truncate() * 0.5;
            let tight = span.x.max(span.y);
            assert!((tight - FILL).abs() < 0.01, "{up:?}: span {span}");
            let mid = (hi + lo).truncate() * 0.5;
            assert!(mid.length() < 0.02, "{up:?}: centre {mid}");
            // From above: the eye is higher than the target along `up`.
            assert!((cam.eye - cam.look_at).dot(up.vector()) > 0.0);
            assert!(lo.z > 0.0 && hi.z < 1.0, "inside the clip range: {lo} {hi}");
        }
    }

    /// The exterior camera looks at the model's front (+z for y up, -y for
    /// z up), from ELEVATION_DEGREES above, not round to one side.
    #[test]
    fn exterior_framing_looks_at_the_front_from_a_little_above() {
        let s = scene_of(vec![(
            box_mesh(Vec3::new(1.0, 0.7, 0.2)),
            Transform::default(),
        )]);
        let el = ELEVATION_DEGREES.to_radians();
        for (up, want) in [
            (UpAxis::Y, Vec3::new(0.0, el.sin(), el.cos())),
            (UpAxis::Z, Vec3::new(0.0, -el.cos(), el.sin())),
        ] {
            let c = frame_scene(&s, up, 4.0 / 3.0, None).camera;
            let d = (c.eye - c.look_at).normalize();
            assert!((d - want).length() < 1e-4, "{up:?}: {d} vs {want}");
        }
        assert!((15.0..=20.0).contains(&ELEVATION_DEGREES));
    }

    /// A vertex no triangle uses (a stray point far away) does not move or
    /// shrink the framing: the bounds are those of the drawn geometry.
    #[test]
    fn unreferenced_vertices_do_not_count() {
        let mesh = box_mesh(Vec3::ONE);
        let framed = frame_scene(
            &scene_of(vec![(mesh.clone(), Transform::default())]),
            UpAxis::Y,
            1.0,
            None,
        );
        let mut stray = mesh;
        stray.positions.push(Vec3::new(500.0, 0.0, 0.0));
        let s = scene_of(vec![(stray, Transform::default())]);
        assert_eq!(world_bounds(&s).max.x, 1.0);
        assert_eq!(frame_scene(&s, UpAxis::Y, 1.0, None), framed);
    }

    /// A closed box placed by a mirroring matrix (scale -1 along x) has its
    /// winding turned, so its outward faces are still its front: it is
    /// framed from outside, not taken for a room with the camera inside
    /// (issue 42: a glTF with negative-scale nodes rendered black). Mirrored
    /// walls facing in still make a room.
    #[test]
    fn a_mirrored_model_is_framed_from_outside() {
        let mirror = Transform::from_matrix(glam::Mat4::from_scale(Vec3::new(-1.0, 1.0, 1.0)));
        let s = scene_of(vec![(uv_sphere(1.0, 24, 12), mirror)]);
        let f = frame_scene(&s, UpAxis::Y, 1.0, None);
        assert!(f.inside.is_none());
        assert!(f.camera.eye.length() > 1.5, "{}", f.camera.eye);
        let mut room = room();
        for o in &mut room.objects {
            o.transform = Transform::from_matrix(
                glam::Mat4::from_scale(Vec3::new(1.0, 1.0, -1.0)) * o.transform.world_from_object(),
            );
        }
        assert!(frame_scene(&room, UpAxis::Y, 1.0, None).inside.is_some());
    }

    /// A model standing on a flat base with +z up, read as y up, looks
    /// Z-up; the same model with +y up, and a long low model (a car along
    /// z), do not.
    #[test]
    fn a_model_on_its_back_looks_z_up() {
        // A figure: a wide flat base slab (many vertices) and a tall body.
        let mut figure = box_mesh(Vec3::new(0.3, 0.2, 1.0));
        let mut base = uv_sphere(0.5, 24, 12);
        for p in &mut base.positions {
            *p = Vec3::new(p.x, 0.6 * p.y, -1.0 + 0.01 * (p.z + 0.5));
        }
        let offset = figure.positions.len() as u32;
        figure.positions.extend(base.positions.iter());
        figure
            .indices
            .extend(base.indices.iter().map(|t| t.map(|i| i + offset)));
        figure.normals.clear();
        let z_up = scene_of(vec![(figure.clone(), Transform::default())]);
        assert!(looks_z_up(&z_up));
        let stood =
            Transform::from_matrix(glam::Mat4::from_rotation_x(-std::f32::consts::FRAC_PI_2));
        assert!(!looks_z_up(&scene_of(vec![(figure, stood)])));
        let car = scene_of(vec![(
            box_mesh(Vec3::new(0.9, 0.7, 2.2)),
            Transform::default(),
        )]);
        assert!(!looks_z_up(&car));
    }
}
