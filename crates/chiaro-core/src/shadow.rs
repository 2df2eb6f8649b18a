//! The one shadow-ray query through transparent surfaces, shared by the
//! scan converter's shadow rays and the Whitted tracer.
//!
//! **Rule.** A shadow ray is a refraction-free ray along the segment to the
//! light sample. Every surface it crosses multiplies the light by that
//! surface's transmit colour `kt` (clamped to `[0, 1]`) once; an opaque
//! surface stops it; a surface of an object with `casts_shadows = false`
//! is ignored. A crossing is one surface at one distance: the hits of one
//! object within a relative `1e-5` of each other's distance are one
//! crossing (a ray through an edge or vertex shared by several triangles
//! is reported on each). So a closed transparent object, entered and left,
//! transmits `kt^2` (Whitted weights a refracted ray by `kt` at each of the
//! two surfaces), and two panes, or two coincident surfaces of different
//! objects, transmit `kt1 * kt2` (Foley et al. section 16.12). A glTF
//! `BLEND` surface's `kt` is `1 - alpha` at the crossing (factor x texture
//! x vertex alpha, the surface layer's per-point value).

use crate::accel::{Accelerator, Hit};
use crate::geometry::{Ray, offset_ray_origin};
use crate::prepared::PreparedScene;
use crate::shading::LightSample;
use glam::Vec3;

/// How a primitive affects shadow rays.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Blocker {
    /// Casts no shadow (its object has `casts_shadows = false`).
    Ignore,
    /// Blocks all light.
    Opaque,
    /// Lets through this RGB fraction (the material's transmit colour, in
    /// `[0, 1]`, not all zero).
    Filter(Vec3),
}

/// Relative distance under which two hits of one object are one crossing.
const SAME_CROSSING: f32 = 1e-5;

/// The shadow casters of a prepared scene: each primitive's [`Blocker`]
/// class (triangles, then analytic spheres, as [`Hit::prim`] numbers them)
/// and object.
#[derive(Debug, Clone)]
pub struct ShadowCasters {
    blockers: Vec<Blocker>,
    /// BLEND triangles: a crossing lets through `1 - alpha` at the hit's uv
    /// (the surface layer's per-point `kt`), not the factor's `transmit`.
    blend: Option<crate::accel::alpha::Coverage>,
    objects: Vec<u32>,
    all_opaque: bool,
}

impl ShadowCasters {
    /// The casters of `ps`: a material with a transmit colour above zero in
    /// any channel is a filter, any other an opaque caster, unless its
    /// object casts no shadows.
    pub fn new(ps: &PreparedScene<'_>) -> Self {
        let scene = ps.scene;
        let class = |material: crate::scene::MaterialId, object: u32| {
            let casts = scene
                .objects
                .get(object as usize)
                .is_none_or(|o| o.casts_shadows);
            if !casts {
                return Blocker::Ignore;
            }
            let kt = ps.material(material).transmit;
            // NaN-safe: a NaN channel counts as 0.
            let kt = Vec3::new(
                kt.x.clamp(0.0, 1.0),
                kt.y.clamp(0.0, 1.0),
                kt.z.clamp(0.0, 1.0),
            );
            if kt.max_element() > 0.0 {
                Blocker::Filter(kt)
            } else {
                Blocker::Opaque
            }
        };
        let mut blockers = Vec::with_capacity(ps.triangles.len() + ps.spheres.len());
        let mut objects = Vec::with_capacity(blockers.capacity());
        for t in 0..ps.triangles.len() {
            blockers.push(class(ps.tri_material[t], ps.tri_object[t]));
            objects.push(ps.tri_object[t]);
        }
        for s in &ps.spheres {
            blockers.push(class(s.material, s.object));
            objects.push(s.object);
        }
        let blend = crate::accel::alpha::Coverage::blend(ps);
        let all_opaque = blend.is_none() && blockers.iter().all(|b| *b == Blocker::Opaque);
        Self {
            blockers,
            blend,
            objects,
            all_opaque,
        }
    }

    /// The casters of a technique whose shadow rays cross only BLEND
    /// surfaces (`1 - alpha` at each crossing, by the rule of the module)
    /// and stop at every other surface, whatever its transmit colour or
    /// object: the path tracer's, which carries light through glass by BSDF
    /// sampling. `None` when `ps` has no BLEND triangle.
    pub fn blend_only(ps: &PreparedScene<'_>) -> Option<Self> {
        let blend = crate::accel::alpha::Coverage::blend(ps)?;
        let objects: Vec<u32> = ps
            .tri_object
            .iter()
            .copied()
            .chain(ps.spheres.iter().map(|s| s.object))
            .collect();
        Some(Self {
            blockers: vec![Blocker::Opaque; objects.len()],
            blend: Some(blend),
            objects,
            all_opaque: false,
        })
    }

    /// These casters with the opaque ones ignored (`None` when there is no
    /// transparent caster): the tint of transparent casters alone, for a
    /// technique that finds opaque shadows another way.
    pub fn transparent_only(&self) -> Option<Self> {
        let blockers: Vec<Blocker> = self
            .blockers
            .iter()
            .map(|b| match b {
                Blocker::Opaque => Blocker::Ignore,
                b => *b,
            })
            .collect();
        blockers
            .iter()
            .any(|b| matches!(b, Blocker::Filter(_)))
            .then(|| Self {
                blockers,
                blend: self.blend.clone(),
                objects: self.objects.clone(),
                all_opaque: false,
            })
    }

    /// The class of primitive `prim` (opaque when out of range).
    #[inline]
    pub fn blocker(&self, prim: u32) -> Blocker {
        self.blockers
            .get(prim as usize)
            .copied()
            .unwrap_or(Blocker::Opaque)
    }

    /// True when every primitive is an opaque caster (a shadow ray can stop
    /// at its first hit).
    pub fn all_opaque(&self) -> bool {
        self.all_opaque
    }

    /// RGB transmittance along `ray` (within its `t` range) by the rule of
    /// the module: 0 when an opaque caster is crossed, the product of the
    /// transmit colours of the crossings otherwise (1 when none). `accel`
    /// must be built over the prepared scene these casters come from.
    pub fn transmittance<A: Accelerator + ?Sized>(&self, accel: &A, ray: &Ray) -> Vec3 {
        if self.all_opaque {
            return if accel.occluded(ray) {
                Vec3::ZERO
            } else {
                Vec3::ONE
            };
        }
        let mut tr = Vec3::ONE;
        // Crossings counted so far, as (t, object); the rare ray with more
        // than 16 of them keeps the rest in `more`.
        let mut seen = [(0.0f32, u32::MAX); 16];
        let mut nseen = 0usize;
        let mut more: Vec<(f32, u32)> = Vec::new();
        // A BLEND caster's transmittance at the hit, `1 - alpha` there.
        let blend_kt = |h: &Hit| {
            self.blend
                .as_ref()
                .filter(|c| c.is_masked(h.prim))
                .map(|c| Vec3::splat((1.0 - c.alpha(h.prim, h.u, h.v)).clamp(0.0, 1.0)))
        };
        let blocked = accel.for_each_hit(ray, &mut |h: &Hit| match self.blocker(h.prim) {
            Blocker::Ignore => false,
            Blocker::Opaque if blend_kt(h).is_none() => true,
            Blocker::Opaque | Blocker::Filter(_) => {
                let kt = match (blend_kt(h), self.blocker(h.prim)) {
                    (Some(kt), _) => kt,
                    (None, Blocker::Filter(kt)) => kt,
                    _ => Vec3::ZERO,
                };
                let object = self
                    .objects
                    .get(h.prim as usize)
                    .copied()
                    .unwrap_or(u32::MAX);
                let tol = SAME_CROSSING * h.t.abs().max(1e-3);
                let same = |&(t, o): &(f32, u32)| o == object && (t - h.t).abs() <= tol;
                if seen[..nseen].iter().any(same) || more.iter().any(same) {
                    return false;
                }
                if nseen < seen.len() {
                    seen[nseen] = (h.t, object);
                    nseen += 1;
                } else {
                    more.push((h.t, object));
                }
                tr *= kt;
                tr.max_element() <= 0.0
            }
        });
        if blocked { Vec3::ZERO } else { tr }
    }

    /// RGB transmittance from the surface point `p` (unit geometric normal
    /// `ng`, either side) to the light sample `s`: [`Self::transmittance`]
    /// along the segment from `p`, offset off its surface towards the
    /// light, to just short of the sample point (which may lie on an
    /// emissive triangle). Adds one to `rays`.
    pub fn light_transmittance<A: Accelerator + ?Sized>(
        &self,
        accel: &A,
        p: Vec3,
        ng: Vec3,
        s: &LightSample,
        rays: &mut u64,
    ) -> Vec3 {
        *rays += 1;
        let ray = Ray::segment(offset_ray_origin(p, ng, s.wi), s.point);
        self.transmittance(accel, &ray)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::accel::list::ListAccel;
    use crate::prepared::PrepareOptions;
    use crate::scene::{Geometry, Material, Object, Scene, Transform};

    /// A scene of the unit quads `z = zs[i]` (x, y in [-1, 1]) with
    /// transmit colours `kts[i]`, each its own object, and optionally a
    /// sphere of radius 0.5 at `(0, 0, 5)` with transmit colour `ball`.
    fn panes(zs: &[f32], kts: &[Vec3], ball: Option<Vec3>) -> Scene {
        let mut s = Scene::default();
        for (i, (&z, &kt)) in zs.iter().zip(kts).enumerate() {
            let m = s.add_material(Material {
                transmit: kt,
                ..Material::diffuse(&format!("pane{i}"), Vec3::splat(0.5))
            });
            let mesh = s.add_mesh(crate::test_square(z));
            s.objects.push(Object {
                geometry: Geometry::Mesh(mesh),
                material: m,
                ..Object::default()
            });
        }
        if let Some(kt) = ball {
            let m = s.add_material(Material {
                transmit: kt,
                ..Material::diffuse("ball", Vec3::splat(0.5))
            });
            s.objects.push(Object {
                geometry: Geometry::Sphere { radius: 0.5 },
                material: m,
                transform: Transform {
                    translate: Vec3::new(0.0, 0.0, 5.0),
                    ..Transform::default()
                },
                ..Object::default()
            });
        }
        s
    }

    fn through(scene: &Scene, analytic: bool, from: Vec3, to: Vec3) -> Vec3 {
        let ps = PreparedScene::new(
            scene,
            PrepareOptions {
                analytic_spheres: analytic,
                ..PrepareOptions::default()
            },
        );
        let accel = ListAccel::new(&ps);
        ShadowCasters::new(&ps).transmittance(&accel, &Ray::segment(from, to))
    }

    #[test]
    fn two_panes_multiply_their_colours_once_each() {
        let k1 = Vec3::new(0.8, 0.5, 0.2);
        let k2 = Vec3::new(0.5, 0.5, 1.0);
        let s = panes(&[1.0, 2.0], &[k1, k2], None);
        // Through the quads' shared diagonal (x = y): reported on both
        // triangles of each pane, counted once per pane.
        for from in [Vec3::new(0.3, -0.2, 0.0), Vec3::new(0.25, 0.25, 0.0)] {
            let t = through(&s, false, from, from + Vec3::Z * 3.0);
            assert!((t - k1 * k2).abs().max_element() < 1e-6, "{from}: {t}");
        }
        // Stopping between the panes: the first only.
        let t = through(&s, false, Vec3::ZERO, Vec3::new(0.0, 0.0, 1.5));
        assert!((t - k1).abs().max_element() < 1e-6, "{t}");
        // Two coincident panes of different objects are two surfaces.
        let s = panes(&[1.0, 1.0], &[k1, k2], None);
        let t = through(
            &s,
            false,
            Vec3::new(0.1, 0.3, 0.0),
            Vec3::new(0.1, 0.3, 3.0),
        );
        assert!((t - k1 * k2).abs().max_element() < 1e-6, "{t}");
    }

    #[test]
    fn a_transparent_sphere_transmits_kt_squared_analytic_or_tessellated() {
        let kt = Vec3::new(0.9, 0.6, 0.3);
        let s = panes(&[], &[], Some(kt));
        for analytic in [true, false] {
            for off in [
                Vec3::ZERO,
                Vec3::new(0.2, 0.1, 0.0),
                Vec3::new(0.0, 0.3, 0.0),
            ] {
                let t = through(&s, analytic, off, off + Vec3::Z * 10.0);
                assert!(
                    (t - kt * kt).abs().max_element() < 1e-6,
                    "analytic {analytic} offset {off}: {t}"
                );
                // From inside the sphere: one crossing.
                let t = through(
                    &s,
                    analytic,
                    Vec3::new(0.0, 0.0, 5.0) + off * 0.5,
                    off + Vec3::Z * 10.0,
                );
                assert!(
                    (t - kt).abs().max_element() < 1e-6,
                    "inside {analytic}: {t}"
                );
            }
        }
        // An opaque surface in the way stops everything.
        let s = panes(&[2.0], &[Vec3::ZERO], Some(kt));
        assert_eq!(through(&s, true, Vec3::ZERO, Vec3::Z * 10.0), Vec3::ZERO);
    }

    #[test]
    fn transparent_only_sees_the_filters() {
        let kt = Vec3::new(0.5, 0.6, 0.7);
        let s = panes(&[1.0, 2.0], &[Vec3::ZERO, kt], None);
        let ps = PreparedScene::new(&s, PrepareOptions::default());
        let accel = ListAccel::new(&ps);
        let ray = Ray::segment(Vec3::ZERO, Vec3::Z * 3.0);
        let all = ShadowCasters::new(&ps);
        assert_eq!(all.transmittance(&accel, &ray), Vec3::ZERO);
        let filters = all.transparent_only().expect("one filter");
        assert_eq!(filters.transmittance(&accel, &ray), kt);
        let opaque = panes(&[1.0], &[Vec3::ZERO], None);
        let ps = PreparedScene::new(&opaque, PrepareOptions::default());
        assert!(ShadowCasters::new(&ps).transparent_only().is_none());
    }

    #[test]
    fn objects_that_cast_no_shadow_are_ignored() {
        let mut s = panes(&[1.0], &[Vec3::ZERO], None);
        assert_eq!(through(&s, false, Vec3::ZERO, Vec3::Z * 3.0), Vec3::ZERO);
        s.objects[0].casts_shadows = false;
        assert_eq!(through(&s, false, Vec3::ZERO, Vec3::Z * 3.0), Vec3::ONE);
    }

    #[test]
    fn blend_only_passes_blend_surfaces_and_stops_at_glass() {
        // A BLEND pane of alpha 0.2 at z = 0, a glass pane (kt 0.5) at z = 2.
        let mut s = panes(&[0.0, 2.0], &[Vec3::ZERO, Vec3::splat(0.5)], None);
        let m0 = s.objects[0].material.index();
        s.materials[m0].alpha_mode = crate::scene::AlphaMode::Blend;
        s.materials[m0].alpha = 0.2;
        let ps = PreparedScene::new(&s, PrepareOptions::default());
        let accel = ListAccel::new(&ps);
        let casters = ShadowCasters::blend_only(&ps).expect("a BLEND pane");
        let tr = |z0: f32, z1: f32| {
            let ray = Ray::segment(Vec3::new(0.1, 0.2, z0), Vec3::new(0.1, 0.2, z1));
            casters.transmittance(&accel, &ray)
        };
        // Through the BLEND pane: 1 - 0.2, once for its two triangles' edge.
        let t = tr(1.0, -1.0);
        assert!((t - Vec3::splat(0.8)).abs().max_element() < 1e-6, "{t}");
        // Glass stops it (the path tracer's BSDF carries light through it).
        assert_eq!(tr(3.0, 1.0), Vec3::ZERO);
        // Nothing crossed: 1.
        assert_eq!(tr(1.5, 0.5), Vec3::ONE);
        // Without BLEND surfaces there are no such casters.
        s.materials[m0].alpha_mode = crate::scene::AlphaMode::Opaque;
        let plain = PreparedScene::new(&s, PrepareOptions::default());
        assert!(ShadowCasters::blend_only(&plain).is_none());
    }
}
