//! A reusable z-buffer / item buffer: which item is nearest at each pixel
//! centre of a view, for hemicube form factors (Cohen and Greenberg 1985),
//! shadow maps and picking.
//!
//! It runs the same pipeline as the renderer: homogeneous near-plane and
//! guard-band clipping ([`crate::clip`]), fixed-point snapping, integer edge
//! functions with the top-left rule ([`crate::raster`]). So a closed mesh
//! covers every interior pixel exactly once and a triangle crossing the eye
//! plane shows its visible part.
//!
//! ```
//! use chiaro_raster::zbuffer::{item_buffer, NO_ITEM};
//! use chiaro_core::{Mat4, Vec3, scene::Camera};
//!
//! let cam = Camera { eye: Vec3::new(0.0, 0.0, 3.0), ..Default::default() };
//! let clip_from_world = cam.projection_matrix(1.0) * cam.view_matrix();
//! let positions = [Vec3::new(-1.0, -1.0, 0.0), Vec3::new(1.0, -1.0, 0.0), Vec3::new(0.0, 1.0, 0.0)];
//! let buf = item_buffer(clip_from_world, 16, 16, &positions, &[[0, 1, 2]], &[7]);
//! assert_eq!(buf.id[8 * 16 + 8], 7);
//! assert_eq!(buf.id[0], NO_ITEM);
//! assert!((buf.depth[8 * 16 + 8] - 3.0).abs() < 1e-4);
//! ```

use crate::raster::{DepthKey, RasterTri, Rect, Viewport, rasterize};
use glam::{Mat4, Vec3};

/// The id of pixels that no item covers.
pub const NO_ITEM: u32 = u32::MAX;

/// The nearest item at each pixel centre. Row-major from the top-left.
#[derive(Debug, Clone, PartialEq)]
pub struct ItemBuffer {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Depth of the nearest surface: with [`DepthKey::InvW`] (the default) the
    /// clip-space `w`, i.e. the distance along the view axis for a perspective
    /// projection; with [`DepthKey::ZOverW`] the NDC `z / w`.
    /// `f32::INFINITY` where nothing was drawn.
    pub depth: Vec<f32>,
    /// Id of the nearest item, [`NO_ITEM`] where nothing was drawn.
    pub id: Vec<u32>,
}

/// Options of [`item_buffer_with`].
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ItemBufferOptions {
    /// Skip triangles whose screen winding is clockwise as seen by the camera
    /// (i.e. that are counter-clockwise seen from their back).
    pub cull_back_faces: bool,
    /// What the depth test compares.
    pub depth_key: DepthKey,
}

/// Rasterizes `triangles` (indices into `positions`, world space,
/// counter-clockwise from the front) seen through `clip_from_world` into a
/// `width x height` item buffer, one sample at each pixel centre, keeping the
/// nearest triangle per pixel and writing `ids[t]` for triangle `t`.
///
/// `clip_from_world` must be a perspective projection times a view matrix,
/// with the Direct3D/Vulkan clip convention: `z_clip >= 0` in front of the
/// near plane (e.g. [`chiaro_core::scene::Camera::projection_matrix`]); a
/// 90-degree hemicube face is `Camera { fov_y_degrees: 90, .. }` with aspect 1.
/// Triangles behind the near plane are clipped; nothing is culled.
/// Triangles with out-of-range indices are skipped; when `ids` is shorter
/// than `triangles` the remaining triangles write their own index. Ties in
/// depth keep the earlier triangle. Returns an empty buffer for a zero size.
pub fn item_buffer(
    clip_from_world: Mat4,
    width: u32,
    height: u32,
    positions: &[Vec3],
    triangles: &[[u32; 3]],
    ids: &[u32],
) -> ItemBuffer {
    item_buffer_with(
        clip_from_world,
        width,
        height,
        positions,
        triangles,
        ids,
        &ItemBufferOptions::default(),
    )
}

/// [`item_buffer`] with back-face culling and the depth key chosen by
/// `options` (use [`DepthKey::ZOverW`] for orthographic projections).
pub fn item_buffer_with(
    clip_from_world: Mat4,
    width: u32,
    height: u32,
    positions: &[Vec3],
    triangles: &[[u32; 3]],
    ids: &[u32],
    options: &ItemBufferOptions,
) -> ItemBuffer {
    let n = width as usize * height as usize;
    let mut key = vec![f32::NEG_INFINITY; n];
    let mut id = vec![NO_ITEM; n];
    let vp = Viewport {
        width,
        height,
        cull_back: options.cull_back_faces,
        depth_key: options.depth_key,
    };
    let rect = Rect {
        x0: 0,
        y0: 0,
        x1: width,
        y1: height,
    };
    let centre = [[crate::raster::SUBPIXEL as i32 / 2; 2]];
    let mut scratch = Vec::new();
    let mut tris: Vec<RasterTri> = Vec::new();
    for (t, tri) in triangles.iter().enumerate() {
        let Some(p) = tri
            .iter()
            .map(|&i| positions.get(i as usize))
            .collect::<Option<Vec<_>>>()
        else {
            continue;
        };
        let clip = [p[0], p[1], p[2]].map(|q| clip_from_world * q.extend(1.0));
        let item = ids.get(t).copied().unwrap_or(t as u32);
        tris.clear();
        vp.setup(clip, item, &mut scratch, &mut tris);
        for rt in &tris {
            rasterize(rt, rect, &centre, |x, y, _, k| {
                let i = y as usize * width as usize + x as usize;
                if k > key[i] {
                    key[i] = k;
                    id[i] = rt.id;
                }
            });
        }
    }
    let depth = key
        .iter()
        .map(|&k| {
            if k == f32::NEG_INFINITY {
                f32::INFINITY
            } else {
                match options.depth_key {
                    DepthKey::InvW => 1.0 / k,
                    DepthKey::ZOverW => -k,
                }
            }
        })
        .collect();
    ItemBuffer {
        width,
        height,
        depth,
        id,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use chiaro_core::scene::Camera;

    /// The triangle (-1, -1), (1, -1), (0, 1) in the plane at depth `z`,
    /// counter-clockwise seen from +z.
    fn triangle_at(z: f32) -> [Vec3; 3] {
        [
            Vec3::new(-1.0, -1.0, z),
            Vec3::new(1.0, -1.0, z),
            Vec3::new(0.0, 1.0, z),
        ]
    }

    fn cam() -> (Camera, Mat4) {
        let cam = Camera {
            eye: Vec3::new(0.0, 0.0, 3.0),
            near: 0.1,
            ..Default::default()
        };
        let m = cam.projection_matrix(1.0) * cam.view_matrix();
        (cam, m)
    }

    #[test]
    fn nearer_item_wins_regardless_of_order() {
        let (_, m) = cam();
        let p = [triangle_at(0.0), triangle_at(1.0)].concat();
        for tris in [[[0, 1, 2], [3, 4, 5]], [[3, 4, 5], [0, 1, 2]]] {
            let ids = if tris[0][0] == 0 { [10, 20] } else { [20, 10] };
            let b = item_buffer(m, 16, 16, &p, &tris, &ids);
            assert_eq!(b.id[8 * 16 + 8], 20);
            assert!((b.depth[8 * 16 + 8] - 2.0).abs() < 1e-4);
        }
    }

    #[test]
    fn triangle_crossing_the_eye_plane_draws_its_visible_part() {
        // A floor triangle reaching from far in front to behind the camera:
        // every pixel whose centre ray hits the floor inside the triangle is
        // covered, pixels whose rays go up are not, and nothing explodes.
        let (cam, m) = cam();
        let p = [
            Vec3::new(-50.0, -1.0, -50.0),
            Vec3::new(50.0, -1.0, -50.0),
            Vec3::new(0.0, -1.0, 50.0),
        ];
        let (w, h) = (32u32, 32u32);
        let b = item_buffer(m, w, h, &p, &[[0, 2, 1]], &[1]);
        let mut covered = 0;
        for y in 0..h {
            for x in 0..w {
                let d = cam.ray_direction(x as f32 + 0.5, y as f32 + 0.5, w, h);
                let i = (y * w + x) as usize;
                if d.y < -1e-3 {
                    let t = (-1.0 - cam.eye.y) / d.y;
                    let q = cam.eye + d * t;
                    // Inside the triangle (well away from its far edges)?
                    if q.z > -45.0 && q.x.abs() < 0.5 * (50.0 - q.z) - 1.0 {
                        assert_eq!(b.id[i], 1, "pixel {x},{y}");
                        let along = (q - cam.eye).dot(Vec3::NEG_Z);
                        assert!(
                            (b.depth[i] - along).abs() < 5e-3 * along,
                            "{} vs {along}",
                            b.depth[i]
                        );
                        covered += 1;
                    }
                } else if d.y > 1e-3 {
                    assert_eq!(b.id[i], NO_ITEM, "pixel {x},{y}");
                }
            }
        }
        assert!(covered > 200);
    }

    #[test]
    fn culling_option_drops_back_faces() {
        let (_, m) = cam();
        let p = triangle_at(0.0);
        let opts = ItemBufferOptions {
            cull_back_faces: true,
            ..Default::default()
        };
        let front = item_buffer_with(m, 8, 8, &p, &[[0, 1, 2]], &[0], &opts);
        assert!(front.id.contains(&0));
        let back = item_buffer_with(m, 8, 8, &p, &[[0, 2, 1]], &[0], &opts);
        assert!(back.id.iter().all(|&i| i == NO_ITEM));
    }
}
