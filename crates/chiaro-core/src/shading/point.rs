//! The local illumination model specialised for the common case of the
//! scan converter: no shadows and only point and ambient lights. It lives
//! here, beside [`shade_local`](super::shade_local), as part of the one
//! shading function: the same terms in the same order, tested bit for bit
//! against it, so no technique carries a model of its own.
//!
//! [`PointLighting::shade`] returns bit-for-bit what
//! [`super::shade_local`] returns with every light sample
//! visible: the same floating-point operations in the same order, with the
//! per-light constants (`color * intensity`) computed once per frame instead
//! of once per sample, the Phong mirror direction computed once per sample
//! instead of once per light, and no closures or light-kind dispatch in the
//! loop. The vector arithmetic is done on SSE `Vec3A`s, lane by lane the
//! same IEEE operations as on `Vec3` (add, subtract, multiply, divide and
//! `dot`, which sums `(x + y) + z` in both; glam's `Vec3A::cross` and
//! `normalize` are not used: they fuse or divide differently).
//! Any other light kind (spot, directional, area) or a shadow method
//! makes [`PointLighting::new`] return `None`, and the caller keeps using
//! `shade_local`.

use super::brdf::specular_cos;
use super::{ShadingPoint, SurfaceMaterial};
use crate::scene::{Attenuation, Light, ReflectanceModel};
use glam::{Vec3, Vec3A};
use std::f32::consts::{FRAC_1_PI, PI};

/// One light of [`PointLighting`], in scene order.
#[derive(Debug, Clone, Copy)]
enum Source {
    /// An ambient light's `color * intensity`.
    Ambient(Vec3A),
    /// A point light: position, `color * intensity`, fall-off.
    Point {
        position: Vec3A,
        power: Vec3A,
        attenuation: Attenuation,
    },
}

/// The lights of a scene whose lights are all point or ambient lights, in
/// scene order (the order `shade_local` sums them in).
#[derive(Debug, Clone)]
pub struct PointLighting {
    sources: Vec<Source>,
}

impl PointLighting {
    /// The lighting of `lights`, or `None` when one of them is neither a
    /// point nor an ambient light. Ambient lights are dropped unless
    /// `ambient` (as `LocalLighting::ambient` does).
    pub fn new(lights: &[Light], ambient: bool) -> Option<Self> {
        let mut sources = Vec::with_capacity(lights.len());
        for light in lights {
            match light {
                Light::Ambient { .. } => {
                    if ambient {
                        sources.push(Source::Ambient(light.power_rgb().into()));
                    }
                }
                Light::Point {
                    position,
                    attenuation,
                    ..
                } => sources.push(Source::Point {
                    position: (*position).into(),
                    power: light.power_rgb().into(),
                    attenuation: *attenuation,
                }),
                _ => return None,
            }
        }
        Some(Self { sources })
    }

    /// `shade_local(m, sp, lighting, |_, _| (0.5, 0.5), |_, _| 1)`: emission
    /// plus ambient plus, per point light, `pi f(wo, wi) cos_i I / att(d)`
    /// (see `crate::shading`), bit-identical to it. Linear RGB
    /// radiance towards `sp.wo`.
    #[inline]
    pub fn shade(&self, m: &SurfaceMaterial, sp: &ShadingPoint) -> Vec3 {
        self.model::<false>(m, m.kd.into(), sp)[0]
    }

    /// [`PointLighting::shade`] of `m` with its diffuse colour replaced by
    /// `kd` (a vertex colour applied), without copying the material.
    #[inline]
    pub fn shade_kd(&self, m: &SurfaceMaterial, kd: Vec3, sp: &ShadingPoint) -> Vec3 {
        self.model::<false>(m, kd.into(), sp)[0]
    }

    /// `shade_local_split` with every light sample visible, bit-identical
    /// to it: `[total, rest]`, `rest` being the part that does not scale
    /// with `kd` (emission and specular reflection).
    #[inline]
    pub fn shade_split(&self, m: &SurfaceMaterial, sp: &ShadingPoint) -> [Vec3; 2] {
        self.model::<true>(m, m.kd.into(), sp)
    }

    /// The body of this module's parent's `local_model` for these lights:
    /// `[total, rest]`, `rest` zero unless `SPLIT`; `kd` stands for `m.kd`.
    #[inline(always)]
    fn model<const SPLIT: bool>(
        &self,
        m: &SurfaceMaterial,
        kd: Vec3A,
        sp: &ShadingPoint,
    ) -> [Vec3; 2] {
        let (ka, ks) = (Vec3A::from(m.ka), Vec3A::from(m.ks));
        let ks_ambient = Vec3A::from(m.ks_ambient);
        let (p, n, wo) = (Vec3A::from(sp.p), Vec3A::from(sp.n), Vec3A::from(sp.wo));
        let mut out = Vec3A::from(m.emission);
        let mut rest = out;
        let has_specular = m.has_specular();
        let phong = m.model == ReflectanceModel::Phong;
        // phong_lobe's mirror direction (fresnel::reflect), the same for
        // every light.
        let r = 2.0 * n.dot(wo) * n - wo;
        for src in &self.sources {
            match *src {
                // ambient_term: ia * ka * (kd + ks_ambient).
                Source::Ambient(power) => {
                    out += power * ka * (kd + ks_ambient);
                    if SPLIT {
                        rest += power * ka * ks_ambient;
                    }
                }
                Source::Point {
                    position,
                    power,
                    attenuation,
                } => {
                    // sample_light for a point light.
                    let d = position - p;
                    let dist = d.length();
                    if dist <= 0.0 {
                        continue;
                    }
                    let wi = d / dist;
                    let intensity = power * attenuation.factor(dist);
                    let cos_i = wi.dot(n);
                    if cos_i <= 0.0 {
                        continue;
                    }
                    let spec = if !has_specular {
                        Vec3A::ZERO
                    } else if phong {
                        // brdf::specular_cos for the Phong lobe.
                        let c = r.dot(wi);
                        let lobe = if c <= 0.0 { 0.0 } else { c.powf(m.shininess) };
                        ks * (lobe * FRAC_1_PI)
                    } else {
                        specular_cos(m, sp.n, sp.wo, wi.into(), cos_i).into()
                    };
                    let mut f = kd * (FRAC_1_PI * cos_i);
                    if has_specular {
                        f += spec;
                    }
                    // The light's sums over its one sample start at zero.
                    let mut sum = Vec3A::ZERO;
                    sum += PI * f * intensity;
                    out += sum;
                    if SPLIT {
                        let mut sum_rest = Vec3A::ZERO;
                        sum_rest += PI * spec * intensity;
                        rest += sum_rest;
                    }
                }
            }
        }
        [out.into(), if SPLIT { rest.into() } else { Vec3::ZERO }]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{Distribution, Material};
    use crate::shading::{LocalLighting, shade_local, shade_local_split};
    use glam::Vec2;

    /// A seeded xorshift generator of numbers in `[-1, 1)`.
    struct Rng(u64);

    impl Rng {
        fn next(&mut self) -> f32 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            (self.0 >> 40) as f32 / (1u64 << 23) as f32 - 1.0
        }
    }

    fn unit(rng: &mut Rng) -> Vec3 {
        loop {
            let v = Vec3::new(rng.next(), rng.next(), rng.next());
            if let Some(u) = v.try_normalize() {
                return u;
            }
        }
    }

    #[test]
    fn point_lighting_is_bit_identical_to_shade_local_and_split() {
        let lights = vec![
            Light::Ambient {
                color: Vec3::new(0.2, 0.3, 0.4),
                intensity: 0.5,
            },
            Light::Point {
                position: Vec3::new(2.0, 3.0, 1.0),
                color: Vec3::new(1.0, 0.9, 0.8),
                intensity: 7.0,
                attenuation: Attenuation::InverseSquare,
            },
            Light::Point {
                position: Vec3::new(-3.0, 1.0, 2.0),
                color: Vec3::ONE,
                intensity: 2.0,
                attenuation: Attenuation::None,
            },
        ];
        let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
        // Every lobe: Lambert alone (ks = 0), Phong, Blinn, Torrance-Sparrow
        // with either distribution.
        let (ggx, beckmann) = (Distribution::Ggx, Distribution::Beckmann);
        for (model, distribution, ks) in [
            (ReflectanceModel::Phong, ggx, 0.0),
            (ReflectanceModel::Phong, ggx, 0.3),
            (ReflectanceModel::Blinn, ggx, 0.3),
            (ReflectanceModel::TorranceSparrow, ggx, 0.3),
            (ReflectanceModel::TorranceSparrow, beckmann, 0.3),
        ] {
            let mat = Material {
                diffuse: Vec3::new(0.6, 0.5, 0.4),
                specular: Vec3::splat(ks),
                ambient: Vec3::splat(0.7),
                shininess: 24.0,
                model,
                distribution,
                roughness: 0.35,
                ..Material::default()
            };
            let m = SurfaceMaterial::from_material(&mat);
            for ambient in [false, true] {
                let fast = PointLighting::new(&lights, ambient).expect("point lights only");
                let env = LocalLighting {
                    lights: &lights,
                    area_samples: 4,
                    ambient,
                    group: None,
                    share: crate::shading::SampleShare::WHOLE,
                };
                for _ in 0..500 {
                    let n = unit(&mut rng);
                    let sp = ShadingPoint {
                        p: unit(&mut rng) * 0.8,
                        n,
                        ng: n,
                        wo: unit(&mut rng),
                    };
                    let want =
                        shade_local(&m, &sp, &env, |_, _| Vec2::splat(0.5), |_, _| Vec3::ONE);
                    let got = fast.shade(&m, &sp);
                    let bits = |v: Vec3| v.to_array().map(f32::to_bits);
                    assert_eq!(bits(got), bits(want));
                    let want_split =
                        shade_local_split(&m, &sp, &env, |_, _| Vec2::splat(0.5), |_, _| Vec3::ONE);
                    let got_split = fast.shade_split(&m, &sp);
                    assert_eq!(got_split.map(bits), want_split.map(bits));
                    // A vertex colour applied to kd.
                    let color = Vec3::new(0.9, 0.4, 0.7);
                    let tinted = SurfaceMaterial {
                        kd: m.kd * color,
                        ..m
                    };
                    let want_kd = shade_local(
                        &tinted,
                        &sp,
                        &env,
                        |_, _| Vec2::splat(0.5),
                        |_, _| Vec3::ONE,
                    );
                    assert_eq!(bits(fast.shade_kd(&m, m.kd * color, &sp)), bits(want_kd));
                }
            }
        }
    }

    #[test]
    fn other_lights_are_refused() {
        let lights = vec![Light::Directional {
            direction: Vec3::NEG_Y,
            color: Vec3::ONE,
            intensity: 1.0,
        }];
        assert!(PointLighting::new(&lights, true).is_none());
        assert!(PointLighting::new(&[], true).is_some());
    }
}
