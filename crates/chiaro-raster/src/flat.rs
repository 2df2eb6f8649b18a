//! Flat (faceted) shading for the scan converter: the illumination model
//! evaluated once per polygon, at its centroid with the face normal, and
//! used for every sample of it (constant shading: Foley, van Dam, Feiner
//! and Hughes, *Computer Graphics: Principles and Practice*, 2nd ed.,
//! 16.2.1). The per-sample steps every method shares are in
//! [`crate::pipeline::shading`].

use crate::pipeline::shading::{Ctx, Lit, SampleAt, Split};
use crate::pipeline::triangles::TriData;
use chiaro_core::shading::ShadingPoint;
use glam::{Vec3, Vec3A};

impl Ctx<'_, '_> {
    /// Flat shading of triangle `td`: once, at the centroid, with the face
    /// normal. The same values as `surface` at the centroid, `flipped` and
    /// `untextured_material` give, from the cached triangle.
    pub(crate) fn flat_split(&self, td: &TriData<'_>) -> Split {
        let t = td.t;
        let third = 1.0 / 3.0;
        let (p, sm) = if td.textured {
            let hit = self.surface(td, third, third, true, true);
            (hit.p, self.untextured_material(&hit))
        } else {
            // surface(): w = 1 - u - v, then the same interpolations.
            let w = 1.0 - third - third;
            let mut sm = self.base(td);
            sm.kd *= Vec3::from(td.c[0] * w + td.c[1] * third + td.c[2] * third);
            (
                Vec3::from(td.p[0] * w + td.p[1] * third + td.p[2] * third),
                sm,
            )
        };
        let mut n = Vec3::from(td.ng);
        // flipped(t), with the cached face normal (PreparedScene::face_normal).
        if td.material.sidedness.eye_sees_back()
            && td.ng.dot(Vec3A::from(self.rays.eye) - td.p[0]) < 0.0
        {
            n = -n;
        }
        let wo = (self.rays.eye - p).normalize_or_zero();
        let sp = ShadingPoint { p, n, ng: n, wo };
        self.illuminate_split(t, &sm, &sp)
    }
}

/// Flat shading of the sample `at` of triangle `td`: the triangle's one
/// illumination ([`TriData::flat`]), textured per pixel, with the face
/// normal.
#[inline]
pub(crate) fn shade(ctx: &Ctx<'_, '_>, td: &TriData, at: &SampleAt) -> Lit {
    ctx.split_sample(td, at, td.flat, at.hit.ng * at.sign)
}

/// The colour of a [`TriData::lean`] flat sample: the triangle's one
/// illumination, untextured. The same operations as [`shade`] for that case.
#[inline(always)]
pub(crate) fn lean_color(td: &TriData) -> Vec3 {
    td.flat.diffuse * Vec3::ONE + td.flat.rest
}
