//! Flat (faceted) shading for the scan converter: the illumination model
//! evaluated once per polygon, at its centroid with the face normal, and
//! used for every sample of it (constant shading: Foley, van Dam, Feiner
//! and Hughes, *Computer Graphics: Principles and Practice*, 2nd ed.,
//! 16.2.1). A textured polygon is lit without its colours (the light per
//! unit of diffuse colour, ambient reflectance and F0), which each sample
//! then applies from its textures; the lobe's roughness is the one at the
//! centroid. The per-sample steps every method shares are in
//! [`crate::pipeline::shading`].

use crate::pipeline::shading::{Ctx, Lit, SampleAt, Split};
use crate::pipeline::triangles::TriData;
use chiaro_core::shading::{FactoredLight, ShadingPoint};
use glam::{Vec2, Vec3};

impl Ctx<'_, '_> {
    /// Flat shading of the untextured triangle `td`: once, at the centroid,
    /// with the face normal and the material's colours. The same values as
    /// `surface` at the centroid, `flipped` and `untextured_material` give,
    /// from the cached triangle.
    pub(crate) fn flat_split(&self, td: &TriData<'_>) -> Split {
        let third = 1.0 / 3.0;
        // surface(): w = 1 - u - v, then the same interpolations.
        let w = 1.0 - third - third;
        let mut sm = self.base(td);
        sm.kd *= Vec3::from(td.c[0] * w + td.c[1] * third + td.c[2] * third);
        let p = Vec3::from(td.p[0] * w + td.p[1] * third + td.p[2] * third);
        self.illuminate_split(td.t, &sm, &self.flat_point(td, p))
    }

    /// Flat shading of the textured triangle `td`: the light once, at the
    /// centroid, with the face normal and the lobe of the material there
    /// (its roughness textured), without the colours, which
    /// [`Ctx::factored_sample`] applies per pixel.
    pub(crate) fn flat_factored(&self, td: &TriData<'_>) -> FactoredLight {
        let third = 1.0 / 3.0;
        let hit = self.surface(td, third, third, true, true);
        let lobe = self.ps.surface_material_lod(&hit, Vec2::ZERO, Vec2::ZERO);
        self.illuminate_factored(td.t, &lobe, &self.flat_point(td, hit.p))
    }

    /// The shading point of a flat triangle at `p`: the face normal, on the
    /// viewer's side for the back of a two-sided surface.
    fn flat_point(&self, td: &TriData<'_>, p: Vec3) -> ShadingPoint {
        let mut n = Vec3::from(td.ng);
        // flipped(t), with the cached face normal (PreparedScene::face_normal).
        if td.material.sidedness.eye_sees_back()
            && td.ng.dot(self.rays.toward_viewer(td.p[0])) < 0.0
        {
            n = -n;
        }
        let wo = self.rays.toward_viewer3(p).normalize_or_zero();
        ShadingPoint { p, n, ng: n, wo }
    }
}

/// Flat shading of the sample `at` of triangle `td`: the triangle's one
/// illumination ([`TriData::flat`], or [`TriData::flat_factored`] with the
/// textured colours applied per pixel), with the face normal.
#[inline]
pub(crate) fn shade(ctx: &Ctx<'_, '_>, td: &TriData, at: &SampleAt) -> Lit {
    let n = at.hit.ng * at.sign;
    if td.textured {
        ctx.factored_sample(td, at, &td.flat_factored, n)
    } else {
        ctx.split_sample(td, at, td.flat, n)
    }
}

/// The colour of a [`TriData::lean`] flat sample: the triangle's one
/// illumination, untextured. The same operations as [`shade`] for that case.
#[inline(always)]
pub(crate) fn lean_color(td: &TriData) -> Vec3 {
    td.flat.diffuse * Vec3::ONE + td.flat.rest
}
