//! Alpha-tested (glTF `alphaMode: MASK`) geometry for the ray-based
//! techniques: [`Coverage`] answers "is this hit there?" from the texture
//! alpha at the hit's uv, and [`AlphaTested`] wraps any [`Accelerator`] so
//! that every ray (camera, secondary, shadow) skips cut-out hits.
//!
//! Closest hits re-trace from the cut-out hit's distance with the same
//! origin and direction (`t_min = hit.t`), so the triangles behind are met
//! with bit-identical distances and barycentrics; shadow queries filter the
//! any-hit enumeration ([`Accelerator::for_each_hit`]). Scenes without a
//! masked material never build the wrapper, so they pay nothing.

use super::{Accelerator, Hit};
use crate::geometry::Ray;
use crate::prepared::{PreparedScene, alpha_product};
use crate::scene::{AlphaMode, Texture};
use crate::shading::texture::{TexCoord, eval_texture};
use glam::Vec2;

/// No slot: the primitive is not alpha-tested.
const NONE: u32 = u32::MAX;

/// A masked material: its cutoff, factor alpha and base-colour texture.
#[derive(Debug, Clone)]
struct Mask {
    cutoff: f32,
    factor: f32,
    texture: Option<Texture>,
}

/// The alpha test of a prepared scene's masked triangles (analytic spheres
/// are never masked: only glTF sets `alphaMode`, and glTF has no spheres).
#[derive(Debug, Clone)]
pub struct Coverage {
    /// Per primitive: its index in `slots`, or [`NONE`].
    prim_slot: Vec<u32>,
    /// Per masked triangle: its mask, vertex uvs and vertex-colour alphas.
    slots: Vec<(u32, [Vec2; 3], [f32; 3])>,
    masks: Vec<Mask>,
}

impl Coverage {
    /// The masked triangles of `ps`, or `None` when it has none.
    pub fn new(ps: &PreparedScene<'_>) -> Option<Self> {
        Self::of(ps, |mode| match mode {
            AlphaMode::Mask { cutoff } => Some(cutoff),
            _ => None,
        })
    }

    /// The triangles of `ps` with `alphaMode: BLEND` (their [`Self::alpha`]
    /// is the coverage that shadow rays let through as `1 - alpha`), or
    /// `None` when it has none.
    pub fn blend(ps: &PreparedScene<'_>) -> Option<Self> {
        Self::of(ps, |mode| (mode == AlphaMode::Blend).then_some(0.0))
    }

    /// The triangles whose material's mode `pick` gives a cutoff.
    fn of(ps: &PreparedScene<'_>, pick: impl Fn(AlphaMode) -> Option<f32>) -> Option<Self> {
        let mut mask_of = vec![NONE; ps.scene.materials.len()];
        let mut masks = Vec::new();
        for (i, m) in ps.scene.materials.iter().enumerate() {
            if let Some(cutoff) = pick(m.alpha_mode) {
                mask_of[i] = masks.len() as u32;
                masks.push(Mask {
                    cutoff: if cutoff.is_finite() { cutoff } else { 0.5 },
                    factor: m.alpha,
                    texture: m
                        .texture
                        .and_then(|t| ps.scene.textures.get(t.index()).cloned()),
                });
            }
        }
        if masks.is_empty() {
            return None;
        }
        let nprims = ps.triangles.len() + ps.spheres.len();
        let mut prim_slot = vec![NONE; nprims];
        let mut slots = Vec::new();
        for (t, tri) in ps.triangles.iter().enumerate() {
            let mask = mask_of
                .get(ps.tri_material[t].index())
                .copied()
                .unwrap_or(NONE);
            if mask == NONE {
                continue;
            }
            let idx = tri.map(|i| i as usize);
            prim_slot[t] = slots.len() as u32;
            // The uvs of the set the mask's texture reads (eval_texture's rule).
            let second = matches!(
                &masks[mask as usize].texture,
                Some(Texture::Image(img)) if img.uv_set == 1
            ) && !ps.uvs1.is_empty();
            let uvs = if second { &ps.uvs1 } else { &ps.uvs };
            slots.push((mask, idx.map(|i| uvs[i]), idx.map(|i| ps.color_alphas[i])));
        }
        (!slots.is_empty()).then_some(Self {
            prim_slot,
            slots,
            masks,
        })
    }

    /// The alpha at barycentrics `(u, v)` of primitive `prim`, by the
    /// surface layer's [`alpha_product`] with the texture's base level
    /// (its magnification filter) at the hit's uv; 1 for an unmasked one.
    pub fn alpha(&self, prim: u32, u: f32, v: f32) -> f32 {
        let Some(&(mask, uv, va)) = self
            .prim_slot
            .get(prim as usize)
            .and_then(|&s| self.slots.get(s as usize))
        else {
            return 1.0;
        };
        let m = &self.masks[mask as usize];
        let w = 1.0 - u - v;
        let tex = m.texture.as_ref().map_or(1.0, |t| {
            // The slot holds the uvs of the texture's own set: both sets read them.
            let at = uv[0] * w + uv[1] * u + uv[2] * v;
            let tc = TexCoord {
                uv: at,
                uv1: at,
                ..TexCoord::default()
            };
            eval_texture(t, None, &tc).w
        });
        alpha_product(m.factor, tex, va[0] * w + va[1] * u + va[2] * v)
    }

    /// True when the hit is there: not on a masked primitive, or its alpha
    /// at least the cutoff (glTF: alpha below `alphaCutoff` is not drawn).
    #[inline]
    pub fn covers(&self, hit: &Hit) -> bool {
        match self.prim_slot.get(hit.prim as usize) {
            Some(&s) if s != NONE => {
                let cutoff = self.masks[self.slots[s as usize].0 as usize].cutoff;
                self.alpha(hit.prim, hit.u, hit.v) >= cutoff
            }
            _ => true,
        }
    }

    /// True when primitive `prim` is alpha-tested.
    pub fn is_masked(&self, prim: u32) -> bool {
        self.prim_slot
            .get(prim as usize)
            .is_some_and(|&s| s != NONE)
    }
}

/// An accelerator whose rays pass through cut-out texels of masked
/// materials (see the module documentation).
pub struct AlphaTested {
    inner: Box<dyn Accelerator>,
    coverage: Coverage,
}

impl std::fmt::Debug for AlphaTested {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("AlphaTested")
            .field("masked_triangles", &self.coverage.slots.len())
            .finish_non_exhaustive()
    }
}

impl AlphaTested {
    /// `inner` with the alpha test of `ps` (the scene `inner` was built
    /// over); `inner` itself when `ps` has no masked triangle.
    pub fn wrap(ps: &PreparedScene<'_>, inner: Box<dyn Accelerator>) -> Box<dyn Accelerator> {
        match Coverage::new(ps) {
            Some(coverage) => Box::new(Self { inner, coverage }),
            None => inner,
        }
    }
}

impl Accelerator for AlphaTested {
    fn intersect(&self, ray: &Ray) -> Option<Hit> {
        let mut r = *ray;
        loop {
            let hit = self.inner.intersect(&r)?;
            if self.coverage.covers(&hit) {
                return Some(hit);
            }
            // Continue past the cut-out hit along the same ray.
            r.t_min = hit.t;
        }
    }

    fn occluded(&self, ray: &Ray) -> bool {
        self.inner
            .for_each_hit(ray, &mut |h| self.coverage.covers(h))
    }

    fn for_each_hit(&self, ray: &Ray, visit: &mut dyn FnMut(&Hit) -> bool) -> bool {
        self.inner
            .for_each_hit(ray, &mut |h| self.coverage.covers(h) && visit(h))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::accel::bvh::SceneBvh;
    use crate::prepared::PrepareOptions;
    use crate::scene::{Filter, ImageTexture, Material, Mesh, Object, Scene};
    use glam::Vec3;

    /// A quad `z = 0` (x, y in [-1, 1], u = (x + 1) / 2) masked by a 2x1
    /// texture whose left texel has alpha `left` and right texel alpha 1,
    /// in front of an opaque quad `z = -1`; vertex alphas `va` on the mask.
    pub(crate) fn masked_scene(mode: AlphaMode, left: f32, va: &[f32]) -> Scene {
        let mut s = Scene::default();
        let mut img = ImageTexture::new(
            "mask".into(),
            2,
            1,
            vec![[1.0, 1.0, 1.0, left], [1.0, 1.0, 1.0, 1.0]],
        );
        img.mag_filter = Filter::Nearest;
        let tex = s.add_texture(Texture::Image(img));
        let front = s.add_material(Material {
            texture: Some(tex),
            alpha_mode: mode,
            ..Material::diffuse("front", Vec3::ONE)
        });
        let back = s.add_material(Material::diffuse("back", Vec3::new(1.0, 0.0, 0.0)));
        for (z, m) in [(0.0, front), (-1.0, back)] {
            let mesh = s.add_mesh(Mesh {
                uvs: vec![
                    Vec2::new(0.0, 0.0),
                    Vec2::new(1.0, 0.0),
                    Vec2::new(1.0, 1.0),
                    Vec2::new(0.0, 1.0),
                ],
                color_alphas: if z == 0.0 { va.to_vec() } else { Vec::new() },
                ..crate::test_square(z)
            });
            s.objects.push(Object {
                geometry: crate::scene::Geometry::Mesh(mesh),
                material: m,
                ..Object::default()
            });
        }
        s
    }

    #[test]
    fn alpha_is_the_product_of_factor_texture_and_vertex_alpha() {
        assert_eq!(alpha_product(0.5, 0.5, 0.5), 0.125);
        assert_eq!(alpha_product(1.0, 1.0, 1.0), 1.0);
        assert_eq!(alpha_product(2.0, 1.0, 1.0), 1.0);
        assert_eq!(alpha_product(f32::NAN, 1.0, 1.0), 1.0);
        // The surface layer and the coverage query agree.
        let s = masked_scene(AlphaMode::Mask { cutoff: 0.5 }, 0.2, &[0.5; 4]);
        let ps = PreparedScene::new(&s, PrepareOptions::default());
        let cov = Coverage::new(&ps).expect("masked");
        for (x, want) in [(-0.5, 0.1), (0.5, 0.5)] {
            let ray = Ray::new(Vec3::new(x, 0.1, 1.0), Vec3::NEG_Z);
            let hit = SceneBvh::new(&ps).intersect(&ray).expect("front quad");
            assert_eq!(hit.prim / 2, 0, "hits the front quad first");
            let ss = ps.shading_surface(&ray, &hit, None);
            assert!((ss.alpha - want).abs() < 1e-6, "{x}: {}", ss.alpha);
            assert!((cov.alpha(hit.prim, hit.u, hit.v) - want).abs() < 1e-6);
        }
    }

    #[test]
    fn rays_pass_through_cut_out_texels_only() {
        let s = masked_scene(AlphaMode::Mask { cutoff: 0.5 }, 0.0, &[]);
        let ps = PreparedScene::new(&s, PrepareOptions::default());
        let accel = AlphaTested::wrap(&ps, Box::new(SceneBvh::new(&ps)));
        let plain = SceneBvh::new(&ps);
        for x in [-0.9f32, -0.3, 0.3, 0.9] {
            let ray = Ray::new(Vec3::new(x, 0.2, 1.0), Vec3::NEG_Z);
            let hit = accel.intersect(&ray).expect("a quad");
            let want_z = if x < 0.0 { -1.0 } else { 0.0 };
            assert!((ray.at(hit.t).z - want_z).abs() < 1e-6, "x = {x}");
            // The hit behind is the one an unfiltered ray finds from there.
            if x < 0.0 {
                let behind = Ray { t_min: 1.5, ..ray };
                assert_eq!(Some(hit), plain.intersect(&behind));
            }
            // A shadow ray between the quads' planes, through the mask only.
            let seg = Ray::segment(Vec3::new(x, 0.2, 1.0), Vec3::new(x, 0.2, -0.5));
            assert_eq!(accel.occluded(&seg), x > 0.0, "x = {x}");
        }
        // Opaque and BLEND materials build no wrapper (no cost).
        for mode in [AlphaMode::Opaque, AlphaMode::Blend] {
            let s = masked_scene(mode, 0.0, &[]);
            let ps = PreparedScene::new(&s, PrepareOptions::default());
            assert!(Coverage::new(&ps).is_none());
        }
    }

    /// A BLEND caster lets a shadow ray through as `1 - alpha` at the
    /// crossing (texture x vertex alpha), not by its factor alone (whose
    /// alpha 1 made the AlphaBlendModeTest label's decal an opaque caster).
    #[test]
    fn blend_casters_transmit_one_minus_the_texture_alpha() {
        let s = masked_scene(AlphaMode::Blend, 0.25, &[0.8; 4]);
        let ps = PreparedScene::new(&s, PrepareOptions::default());
        let casters = crate::shadow::ShadowCasters::new(&ps);
        let accel = SceneBvh::new(&ps);
        for (x, want) in [(-0.5f32, 1.0 - 0.25 * 0.8), (0.5, 1.0 - 0.8)] {
            let seg = Ray::segment(Vec3::new(x, 0.2, 1.0), Vec3::new(x, 0.2, -0.5));
            let tr = casters.transmittance(&accel, &seg);
            assert!(
                (tr - Vec3::splat(want)).abs().max_element() < 1e-6,
                "x = {x}: {tr}"
            );
        }
    }

    #[test]
    fn vertex_alpha_cuts_too() {
        // Texture alpha 1 everywhere; vertex alpha 0.3 < cutoff 0.5.
        let s = masked_scene(AlphaMode::Mask { cutoff: 0.5 }, 1.0, &[0.3; 4]);
        let ps = PreparedScene::new(&s, PrepareOptions::default());
        let accel = AlphaTested::wrap(&ps, Box::new(SceneBvh::new(&ps)));
        let ray = Ray::new(Vec3::new(0.5, 0.0, 1.0), Vec3::NEG_Z);
        let hit = accel.intersect(&ray).expect("back quad");
        assert!((ray.at(hit.t).z + 1.0).abs() < 1e-6);
    }
}
