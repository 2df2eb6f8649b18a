//! The brute-force accelerator: tests every primitive. Slow and obviously
//! correct; the oracle the BVH is tested against.

use super::{Accelerator, Hit, intersect_sphere, intersect_triangle, sphere_roots};
use crate::geometry::Ray;
use crate::prepared::PreparedScene;
use glam::Vec3;

/// Every triangle and sphere of a prepared scene, in a flat list.
#[derive(Debug, Clone)]
pub struct ListAccel {
    tris: Vec<[Vec3; 3]>,
    spheres: Vec<(Vec3, f32)>,
}

impl ListAccel {
    /// Copies the primitives of `scene`.
    pub fn new(scene: &PreparedScene<'_>) -> Self {
        Self {
            tris: scene
                .triangles
                .iter()
                .map(|t| t.map(|i| scene.positions[i as usize]))
                .collect(),
            spheres: scene.spheres.iter().map(|s| (s.center, s.radius)).collect(),
        }
    }
}

impl Accelerator for ListAccel {
    fn intersect(&self, ray: &Ray) -> Option<Hit> {
        let mut r = *ray;
        let mut best = None;
        for (i, t) in self.tris.iter().enumerate() {
            if let Some((t, u, v)) = intersect_triangle(&r, t[0], t[1], t[2]) {
                r.t_max = t;
                best = Some(Hit {
                    t,
                    prim: i as u32,
                    u,
                    v,
                });
            }
        }
        let n = self.tris.len() as u32;
        for (i, &(c, rad)) in self.spheres.iter().enumerate() {
            if let Some(t) = intersect_sphere(&r, c, rad) {
                r.t_max = t;
                best = Some(Hit {
                    t,
                    prim: n + i as u32,
                    u: 0.0,
                    v: 0.0,
                });
            }
        }
        best
    }

    fn occluded(&self, ray: &Ray) -> bool {
        self.tris
            .iter()
            .any(|t| intersect_triangle(ray, t[0], t[1], t[2]).is_some())
            || self
                .spheres
                .iter()
                .any(|&(c, r)| intersect_sphere(ray, c, r).is_some())
    }

    fn for_each_hit(&self, ray: &Ray, visit: &mut dyn FnMut(&Hit) -> bool) -> bool {
        let n = self.tris.len() as u32;
        for (i, t) in self.tris.iter().enumerate() {
            if let Some((t, u, v)) = intersect_triangle(ray, t[0], t[1], t[2]) {
                let prim = i as u32;
                if visit(&Hit { t, prim, u, v }) {
                    return true;
                }
            }
        }
        for (i, &(c, rad)) in self.spheres.iter().enumerate() {
            let prim = n + i as u32;
            for t in sphere_roots(ray, c, rad).into_iter().flatten() {
                if visit(&Hit {
                    t,
                    prim,
                    u: 0.0,
                    v: 0.0,
                }) {
                    return true;
                }
            }
        }
        false
    }
}
