//! Ray-cast form factors (Wallace, Elmquist and Haines, "A Ray Tracing
//! Algorithm for Progressive Radiosity", SIGGRAPH 1989): area-to-point
//! form factors from quadrature points of the receiver to the source, each
//! weighted by the fraction of visibility rays to the source that are
//! unoccluded, with the exact point-to-polygon term of [`crate::analytic`]
//! in place of the paper's disc approximation.

use crate::analytic::point_to_polygon;
use crate::formfactor::{FormFactor, facing, sub_centroids};
use crate::mesh::Element;
use chiaro_core::accel::Accelerator;
use chiaro_core::geometry::Ray;
use glam::Vec3;
use rayon::prelude::*;

/// Point-to-point visibility against the scene's geometry.
pub struct Visibility<'a> {
    /// The accelerator over the prepared scene's triangles.
    pub accel: &'a dyn Accelerator,
    /// Offset of ray end points along their normals, scene units.
    pub eps: f32,
}

impl std::fmt::Debug for Visibility<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Visibility")
            .field("eps", &self.eps)
            .finish()
    }
}

impl Visibility<'_> {
    /// True if the segment from `a` (normal `na`) to `b` (normal `nb`) is
    /// free; both ends are lifted off their surfaces by `eps`.
    #[inline]
    pub fn visible(&self, a: Vec3, na: Vec3, b: Vec3, nb: Vec3) -> bool {
        let o = a + na * self.eps;
        let t = b + nb * self.eps;
        !self.accel.occluded(&Ray::segment(o, t))
    }
}

/// How a form factor is estimated between two elements.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct PairRule {
    /// Receiver quadrature `m` (m*m points) for distant pairs (centroid
    /// distance above ten times the square root of the larger area).
    pub far_m: u32,
    /// Receiver quadrature for pairs in between.
    pub mid_m: u32,
    /// Receiver quadrature for near pairs (centroid distance below four times
    /// the square root of the larger element's area).
    pub near_m: u32,
    /// Visibility samples on the source (`m*m` rays), 0 for none.
    pub vis_m: u32,
}

/// `F_{recv -> src}`: the mean over quadrature points `x` of the receiver of
/// the exact point-to-polygon form factor to `src`, times the fraction of
/// visibility rays from `x` to points of `src` that are unoccluded
/// (area-to-point form factors with ray-cast visibility, after Wallace,
/// Elmquist and Haines 1989, with the exact polygon term in place of the
/// disc approximation).
pub(crate) fn pair(
    recv: &Element,
    src: &Element,
    rule: PairRule,
    vis: Option<&Visibility<'_>>,
    tol: f32,
) -> f32 {
    if !facing(recv, src, tol) {
        return 0.0;
    }
    let size2 = recv.area.max(src.area);
    let d2 = recv.c.distance_squared(src.c);
    let m = if d2 < 16.0 * size2 {
        rule.near_m
    } else if d2 < 100.0 * size2 {
        rule.mid_m
    } else {
        rule.far_m
    };
    let mut xs = [Vec3::ZERO; 64];
    let nx = sub_centroids(&recv.p, m, &mut xs);
    // Visibility: (2 vis_m)^2 points on the source, of which each receiver
    // point tests every fourth (offset by its index), so a large source is
    // probed at many places while each point casts vis_m^2 rays.
    let mut ys = [Vec3::ZERO; 64];
    let ny = match vis {
        Some(_) if rule.vis_m > 0 => sub_centroids(&src.p, (2 * rule.vis_m).min(8), &mut ys),
        _ => 0,
    };
    let mut sum = 0.0;
    for (a, &x) in xs[..nx].iter().enumerate() {
        if src.n.dot(x - src.c) <= 0.0 {
            continue;
        }
        let f = point_to_polygon(x, recv.n, &src.p);
        if f <= 0.0 {
            continue;
        }
        let frac = match vis {
            Some(v) if ny > 0 => {
                let (mut seen, mut tried) = (0u32, 0u32);
                for y in ys[..ny].iter().skip(a % 4).step_by(4) {
                    tried += 1;
                    if recv.n.dot(*y - x) > 0.0 && v.visible(x, recv.n, *y, src.n) {
                        seen += 1;
                    }
                }
                seen as f32 / tried.max(1) as f32
            }
            _ => 1.0,
        };
        sum += f * frac;
    }
    sum / nx as f32
}

/// Ray-cast (or, without visibility, analytic) form factors over a list of
/// elements.
pub(crate) struct PairFormFactor<'a> {
    pub elements: &'a [Element],
    pub rule: PairRule,
    pub vis: Option<Visibility<'a>>,
    pub tol: f32,
    pub name: &'static str,
}

impl std::fmt::Debug for PairFormFactor<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PairFormFactor")
            .field("rule", &self.rule)
            .field("name", &self.name)
            .finish()
    }
}

impl<'a> PairFormFactor<'a> {
    /// Ray-cast form factors: 1 receiver point for distant pairs, 4 for
    /// middle ones, 36 for near ones; 4
    /// visibility rays.
    pub fn raycast(elements: &'a [Element], vis: Visibility<'a>, tol: f32) -> Self {
        Self {
            elements,
            rule: PairRule {
                far_m: 1,
                mid_m: 2,
                near_m: 6,
                vis_m: 2,
            },
            vis: Some(vis),
            tol,
            name: "raycast",
        }
    }
}

impl FormFactor for PairFormFactor<'_> {
    fn column(&self, i: usize, out: &mut [f32]) {
        let src = &self.elements[i];
        out.par_iter_mut().enumerate().for_each(|(j, o)| {
            *o = if j == i {
                0.0
            } else {
                pair(
                    &self.elements[j],
                    src,
                    self.rule,
                    self.vis.as_ref(),
                    self.tol,
                )
            };
        });
    }

    fn name(&self) -> &'static str {
        self.name
    }
}
