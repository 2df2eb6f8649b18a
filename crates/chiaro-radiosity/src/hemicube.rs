//! The hemicube (Cohen and Greenberg 1985): form factors from a patch to
//! every element, by drawing all elements into the five faces of a
//! half-cube around the patch centre with the scan converter's item buffer
//! ([`chiaro_raster::zbuffer::item_buffer`]) and summing precomputed delta
//! form factors over the pixels each element wins.
//!
//! Delta form factors (Cohen and Greenberg 1985, eqs. 7-8), for a unit
//! half-cube with pixels of area `dA = (2 / res)^2`:
//! - top face at `(x, y, 1)`: `dF = dA / (pi (x^2 + y^2 + 1)^2)`;
//! - side face at `(x, 1, z)`, `z` along the normal: `dF = z dA / (pi (x^2 + z^2 + 1)^2)`.
//!
//! They sum to 1 (up to the pixel quadrature), so the row sums of a closed
//! scene are 1 by construction. The hemicube gives `F_ij` from a point (the
//! centroid of `i`); `HemicubeFormFactor::column` turns it into `F_ji` by
//! reciprocity.

use crate::formfactor::FormFactor;
use crate::mesh::Element;
use chiaro_core::geometry::Frame;
use chiaro_core::scene::Camera;
use chiaro_raster::zbuffer::{NO_ITEM, item_buffer};
use glam::Vec3;
use rayon::prelude::*;
use std::f32::consts::PI;

/// Hemicube form factors over a set of elements.
#[derive(Debug)]
pub(crate) struct HemicubeFormFactor<'a> {
    elements: &'a [Element],
    positions: &'a [Vec3],
    triangles: Vec<[u32; 3]>,
    res: u32,
    top: Vec<f32>,
    side: Vec<f32>,
    near: f32,
    far: f32,
}

impl<'a> HemicubeFormFactor<'a> {
    /// A hemicube of `res x res` pixels on the top face (`res` is rounded up
    /// to an even number, at least 2) over `elements`, whose corners are
    /// `positions[e.verts]`. `scene_size` sets the near and far planes.
    pub(crate) fn new(
        elements: &'a [Element],
        positions: &'a [Vec3],
        res: u32,
        scene_size: f32,
    ) -> Self {
        let res = res.max(2).div_ceil(2) * 2;
        let da = (2.0 / res as f32).powi(2);
        let coord = |p: u32| (p as f32 + 0.5) / res as f32 * 2.0 - 1.0;
        let mut top = vec![0.0; (res * res) as usize];
        let mut side = vec![0.0; (res * res / 2) as usize];
        for py in 0..res {
            for px in 0..res {
                let (x, y) = (coord(px), -coord(py));
                let r = x * x + y * y + 1.0;
                top[(py * res + px) as usize] = da / (PI * r * r);
                if py < res / 2 {
                    // Rows above the horizon: y is the height z along the normal.
                    side[(py * res + px) as usize] = y * da / (PI * r * r);
                }
            }
        }
        Self {
            elements,
            positions,
            triangles: elements.iter().map(|e| e.verts).collect(),
            res,
            top,
            side,
            near: scene_size * 1e-5,
            far: scene_size * 10.0,
        }
    }

    /// `F_ij` for every `j` from a hemicube at the centroid of element `i`
    /// (the row of `i`), accumulated into `row` (zeroed first).
    pub(crate) fn row(&self, i: usize, row: &mut [f32]) {
        row.iter_mut().for_each(|r| *r = 0.0);
        let e = &self.elements[i];
        let x = e.c + e.n * self.near * 10.0;
        // Items that face the hemicube centre receive an id; the others only occlude.
        let ids: Vec<u32> = self
            .elements
            .iter()
            .enumerate()
            .map(|(j, o)| {
                if j != i && o.n.dot(x - o.c) > 0.0 {
                    j as u32
                } else {
                    NO_ITEM
                }
            })
            .collect();
        let f = Frame::from_normal(e.n);
        let faces = [
            (f.n, f.t, true),
            (f.s, f.n, false),
            (-f.s, f.n, false),
            (f.t, f.n, false),
            (-f.t, f.n, false),
        ];
        for (forward, up, is_top) in faces {
            let cam = Camera {
                eye: x,
                look_at: x + forward,
                up,
                fov_y_degrees: 90.0,
                near: self.near,
                far: self.far,
                ..Default::default()
            };
            let clip_from_world = cam.projection_matrix(1.0) * cam.view_matrix();
            let rows = if is_top { self.res } else { self.res / 2 };
            let buf = item_buffer(
                clip_from_world,
                self.res,
                self.res,
                self.positions,
                &self.triangles,
                &ids,
            );
            let delta = if is_top { &self.top } else { &self.side };
            for py in 0..rows {
                for px in 0..self.res {
                    let k = (py * self.res + px) as usize;
                    let id = buf.id[k];
                    if id != NO_ITEM {
                        row[id as usize] += delta[k];
                    }
                }
            }
        }
    }
}

impl FormFactor for HemicubeFormFactor<'_> {
    fn column(&self, i: usize, out: &mut [f32]) {
        let mut row = vec![0.0; out.len()];
        self.row(i, &mut row);
        let ai = self.elements[i].area;
        out.par_iter_mut().enumerate().for_each(|(j, o)| {
            let aj = self.elements[j].area;
            *o = if aj > 0.0 { row[j] * ai / aj } else { 0.0 };
        });
    }

    fn row(&self, j: usize, out: &mut [f32]) -> bool {
        HemicubeFormFactor::row(self, j, out);
        true
    }

    fn name(&self) -> &'static str {
        "hemicube"
    }
}
