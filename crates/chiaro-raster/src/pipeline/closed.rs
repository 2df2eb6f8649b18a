//! `render.cull_backfaces`, a speed option that never changes a picture:
//! the objects whose back faces no camera ray can reach, so that the scan
//! converter may cull them. A ray from outside a closed, outward-wound,
//! opaque surface meets a front face of it before any back face, so its
//! backs are hidden whatever their material's sidedness (ARCHITECTURE.md,
//! "Sidedness").

use chiaro_core::prepared::PreparedScene;
use chiaro_core::scene::{AlphaMode, Camera};
use glam::Vec3;
use std::collections::HashMap;

/// Per object of a prepared scene: the bounds of its triangles when they
/// form a closed surface (each edge, keyed by its end positions to a
/// millionth of the object's size, used once in each direction), wound
/// outwards (positive signed volume), with every material opaque (no
/// transmission, no alpha); `None` otherwise. What [`hidden_backs`] tests
/// the eye against; it depends on the prepared scene alone, so a render
/// context keeps it between frames.
pub(crate) struct ClosedObjects(Vec<Option<(Vec3, Vec3)>>);

/// The [`ClosedObjects`] of `ps`.
pub(crate) fn closed_objects(ps: &PreparedScene<'_>) -> ClosedObjects {
    let n = ps.scene.objects.len();
    // The triangles of each object.
    let mut tris: Vec<Vec<u32>> = vec![Vec::new(); n];
    for (t, &o) in ps.tri_object.iter().enumerate() {
        if let Some(v) = tris.get_mut(o as usize) {
            v.push(t as u32);
        }
    }
    ClosedObjects(
        tris.iter()
            .map(|ts| {
                if ts.is_empty() {
                    None
                } else {
                    closed_opaque_bounds(ps, ts)
                }
            })
            .collect(),
    )
}

/// Per object of `closed`: true when the eye of `camera` (with image
/// aspect `aspect`, width over height) cannot see any of its back faces.
/// That holds when the object is closed, outward-wound and opaque
/// ([`ClosedObjects`]) and the eye and the near plane's rectangle lie
/// outside its bounding box.
pub(crate) fn hidden_backs(closed: &ClosedObjects, camera: &Camera, aspect: f32) -> Vec<bool> {
    // Every point of the near plane's rectangle lies within this distance
    // of the eye.
    let reach = match camera.orthographic_half_height() {
        None => {
            let tan = (camera.fov_y_degrees.to_radians() * 0.5).tan();
            camera.near * (1.0 + tan * tan * (1.0 + aspect * aspect)).sqrt()
        }
        // Every ray origin (the film) and the near rectangle in front of it.
        Some(hh) => (camera.near * camera.near + hh * hh * (1.0 + aspect * aspect)).sqrt(),
    };
    closed
        .0
        .iter()
        .map(|b| b.is_some_and(|(lo, hi)| outside(lo, hi, camera.eye, reach)))
        .collect()
}

/// Whether the eye and the near plane (within `reach` of it) lie outside
/// the box `lo..hi`, with a margin for rounding; false for NaN bounds.
fn outside(lo: Vec3, hi: Vec3, eye: Vec3, reach: f32) -> bool {
    let outside = (lo - eye).max(eye - hi).max(Vec3::ZERO).length();
    outside > reach * 1.01 + 1e-4 * (hi - lo).max_element()
}

/// The bounds of triangles `ts` when they are opaque and closed and
/// outward-wound, see [`ClosedObjects`].
fn closed_opaque_bounds(ps: &PreparedScene<'_>, ts: &[u32]) -> Option<(Vec3, Vec3)> {
    let opaque = |t: u32| {
        let m = ps.material(ps.tri_material[t as usize]);
        m.transmit == Vec3::ZERO && m.alpha_mode == AlphaMode::Opaque && m.alpha >= 1.0
    };
    if !ts.iter().all(|&t| opaque(t)) {
        return None;
    }
    let corners = |t: u32| ps.triangles[t as usize].map(|i| ps.positions[i as usize]);
    let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
    for &t in ts {
        for p in corners(t) {
            lo = lo.min(p);
            hi = hi.max(p);
        }
    }
    // Closed and consistently wound: each directed edge once, and its reverse.
    // Positions within a millionth of the object's size are one vertex (a
    // tessellated sphere's seam and poles are computed, not shared).
    let cell = (hi - lo).max_element().max(f32::MIN_POSITIVE) * 1e-6;
    let key = |p: Vec3| ((p - lo) / cell).round().to_array().map(|x| x as i64);
    let mut edges: HashMap<([i64; 3], [i64; 3]), i32> = HashMap::with_capacity(3 * ts.len());
    let mut volume = 0.0f64;
    for &t in ts {
        let c = corners(t);
        let keys = c.map(key);
        // A triangle with two equal corners (a sphere's pole) has no area
        // and would count an edge both ways.
        if keys[0] == keys[1] || keys[1] == keys[2] || keys[2] == keys[0] {
            continue;
        }
        volume += f64::from(c[0].dot(c[1].cross(c[2])));
        for k in 0..3 {
            let (a, b) = (keys[k], keys[(k + 1) % 3]);
            let (e, s) = if a < b { ((a, b), 1) } else { ((b, a), 1 << 8) };
            *edges.entry(e).or_insert(0) += s;
        }
    }
    // Each undirected edge counted once forwards (1) and once backwards (256).
    (volume > 0.0 && edges.values().all(|&c| c == 1 + (1 << 8))).then_some((lo, hi))
}

#[cfg(test)]
mod tests {
    use super::*;
    use chiaro_core::prepared::PrepareOptions;
    use chiaro_core::scene::{Geometry, Material, Mesh, Object, Scene};

    /// A unit cube centred at the origin, wound outwards, or inwards.
    fn cube(outwards: bool) -> Scene {
        use chiaro_testkit::scenes::{BOX_FACES, box_corner};
        let p: Vec<Vec3> = (0..8)
            .map(|k| box_corner(Vec3::splat(-0.5), Vec3::splat(0.5), k))
            .collect();
        let mut indices = Vec::new();
        for [a, b, c, d] in BOX_FACES.map(|q| q.map(|i| i as u32)) {
            let mut tri =
                |x: u32, y: u32, z: u32| indices.push(if outwards { [x, y, z] } else { [x, z, y] });
            tri(a, b, c);
            tri(a, c, d);
        }
        let mut s = Scene::default();
        s.add_material(Material::default());
        let m = s.add_mesh(Mesh {
            positions: p,
            indices,
            ..Default::default()
        });
        s.objects.push(Object {
            geometry: Geometry::Mesh(m),
            ..Default::default()
        });
        s
    }

    fn hidden(s: &Scene) -> bool {
        let ps = PreparedScene::new(s, PrepareOptions::default());
        hidden_backs(&closed_objects(&ps), &s.camera, 4.0 / 3.0)[0]
    }

    #[test]
    fn a_closed_outward_cube_seen_from_outside_hides_its_backs() {
        let mut s = cube(true);
        assert!(hidden(&s));
        // Wound inwards: its "backs" are what the eye sees.
        assert!(!hidden(&cube(false)));
        // The eye inside.
        s.camera.eye = Vec3::new(0.1, 0.0, 0.2);
        assert!(!hidden(&s));
        // The near plane reaching into it.
        s.camera.eye = Vec3::new(0.0, 0.0, 0.6);
        s.camera.near = 0.2;
        assert!(!hidden(&s));
    }

    #[test]
    fn a_tessellated_sphere_hides_its_backs() {
        let s = chiaro_testkit::scenes::white_sphere();
        let ps = PreparedScene::new(&s, PrepareOptions::default());
        assert!(!ps.triangles.is_empty());
        assert!(hidden_backs(&closed_objects(&ps), &s.camera, 1.0)[0]);
    }

    #[test]
    fn an_open_or_transparent_cube_shows_its_backs() {
        let mut s = cube(true);
        s.meshes[0].indices.pop();
        assert!(!hidden(&s));
        let mut s = cube(true);
        s.materials[0].transmit = Vec3::splat(0.5);
        assert!(!hidden(&s));
    }
}
