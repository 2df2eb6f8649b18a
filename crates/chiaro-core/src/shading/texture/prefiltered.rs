//! Image-based lighting for the local techniques (scan conversion, Whitted):
//! the environment map prefiltered for the GGX lobe at a few roughness
//! levels and the specular lobe's directional albedo as the scale and bias
//! of F0, Karis 2013, "Real Shading in Unreal Engine 4" (the split-sum
//! approximation, with `n = v = r` for the prefiltered radiance), and the
//! map's diffuse irradiance by normal (the cosine convolution of a small
//! level of the map, as Ramamoorthi and Hanrahan's irradiance environment
//! maps, integrated directly rather than fitted by spherical harmonics,
//! whose ringing blackens normals facing away from small bright lamps).
//!
//! The albedo table integrates the shading layer's own BSDF
//! ([`Bsdf::sample`], whose weight is `eval_brdf_cos / pdf`), so it is what
//! the path tracer integrates. The prefiltered images are built by
//! filtered importance sampling (Křivánek and Colbert 2008): each GGX
//! sample reads a box-filtered level of the map whose texels cover its
//! share of the lobe, so a few hundred samples per texel give smooth
//! images even of a map with small bright lamps.

use super::environment::environment_radiance;
use super::latlong::{latlong_dir as turned_latlong_dir, latlong_uv};
use crate::geometry::Frame;
use crate::scene::{Distribution, ReflectanceModel, Scene, Texture};
use crate::shading::brdf::SurfaceMaterial;
use crate::shading::bsdf::Bsdf;
use crate::shading::fresnel::{fresnel_conductor, fresnel_dielectric, reflect};
use crate::shading::microfacet;
use glam::{Vec2, Vec3};
use rayon::prelude::*;
use std::f32::consts::{PI, TAU};
use std::sync::OnceLock;

/// The roughness (microfacet alpha) of each prefiltered level; level 0 is
/// the map itself ([`environment_radiance`]).
pub const LEVEL_ALPHAS: [f32; 8] = [0.0, 0.05, 0.1, 0.2, 0.35, 0.5, 0.75, 1.0];

/// Width of the prefiltered image of each level (the height is half):
/// narrow lobes need finer images.
const LEVEL_WIDTHS: [u32; 8] = [0, 128, 128, 64, 64, 32, 32, 32];

/// GGX samples per prefiltered texel of each level: each sample reads a
/// filtered level, so narrow lobes on fine images need few.
const LEVEL_SAMPLES: [u32; 8] = [0, 64, 64, 128, 128, 128, 128, 128];

/// A lat-long image in world directions (the [`latlong_uv`] convention,
/// not rotated), read bilinearly: wrapping in `u`, clamped in `v`.
#[derive(Debug, Clone)]
struct LatLong {
    w: u32,
    h: u32,
    texels: Vec<Vec3>,
}

/// The unit direction at lat-long coordinates `uv` ([`latlong_uv`]'s inverse).
#[inline]
fn latlong_dir(uv: Vec2) -> Vec3 {
    turned_latlong_dir(uv, 0.0).0
}

impl LatLong {
    /// A `w` x `h` image with `f` of each texel centre's direction.
    fn from_fn(w: u32, h: u32, f: impl Fn(Vec3) -> Vec3 + Sync) -> Self {
        let texels = (0..w * h)
            .into_par_iter()
            .map(|i| {
                let uv = Vec2::new(
                    ((i % w) as f32 + 0.5) / w as f32,
                    ((i / w) as f32 + 0.5) / h as f32,
                );
                f(latlong_dir(uv))
            })
            .collect();
        Self { w, h, texels }
    }

    /// The image halved in both directions by a 2x2 box filter.
    fn half(&self) -> Self {
        let (w, h) = ((self.w / 2).max(1), (self.h / 2).max(1));
        let at =
            |x: u32, y: u32| self.texels[(y.min(self.h - 1) * self.w + x.min(self.w - 1)) as usize];
        let texels = (0..w * h)
            .map(|i| {
                let (x, y) = (2 * (i % w), 2 * (i / w));
                (at(x, y) + at(x + 1, y) + at(x, y + 1) + at(x + 1, y + 1)) * 0.25
            })
            .collect();
        Self { w, h, texels }
    }

    /// Bilinear lookup in the unit direction `d`.
    #[inline]
    fn lookup(&self, d: Vec3) -> Vec3 {
        let uv = latlong_uv(d);
        let x = uv.x * self.w as f32 - 0.5;
        let y = (uv.y * self.h as f32 - 0.5).clamp(0.0, (self.h - 1) as f32);
        if !(x.is_finite() && y.is_finite()) {
            return self.texels[0];
        }
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let (xa, xb) = (
            (x0 as i64).rem_euclid(i64::from(self.w)) as u32,
            (x0 as i64 + 1).rem_euclid(i64::from(self.w)) as u32,
        );
        let (ya, yb) = (y0 as u32, (y0 as u32 + 1).min(self.h - 1));
        let t = |x: u32, y: u32| self.texels[(y * self.w + x) as usize];
        let top = t(xa, ya).lerp(t(xb, ya), fx);
        let bottom = t(xa, yb).lerp(t(xb, yb), fx);
        top.lerp(bottom, fy)
    }
}

/// The i-th of `n` Hammersley points (the first coordinate centred in its
/// stratum).
#[inline]
fn hammersley(i: u32, n: u32) -> Vec2 {
    Vec2::new(
        (i as f32 + 0.5) / n as f32,
        i.reverse_bits() as f32 * (1.0 / 4_294_967_296.0),
    )
}

/// A GGX microfacet normal about +z for the pair `u` (density `D cos_h`).
#[inline]
fn ggx_half_vector(alpha: f32, u: Vec2) -> Vec3 {
    let tan2 = alpha * alpha * u.x / (1.0 - u.x).max(1e-7);
    let cos_t = 1.0 / (1.0 + tan2).sqrt();
    let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
    let phi = TAU * u.y;
    Vec3::new(sin_t * phi.cos(), sin_t * phi.sin(), cos_t)
}

/// The environment of a scene prefiltered for the local techniques' glossy
/// reflection: built once per prepared scene (see
/// `PreparedScene::prefiltered_environment`), only for scenes with a map.
#[derive(Debug, Clone)]
pub struct PrefilteredEnvironment {
    /// The levels `LEVEL_ALPHAS[1..]`.
    levels: Vec<LatLong>,
    /// `E(n) / pi`, the map's irradiance over pi by normal.
    irradiance: LatLong,
}

impl PrefilteredEnvironment {
    /// The table of `scene`'s environment; `None` without an image map or
    /// when its intensity is not positive (nothing to reflect).
    pub fn new(scene: &Scene) -> Option<Self> {
        let env = scene.environment.as_ref()?;
        let Some(Texture::Image(img)) = scene.textures.get(env.texture.index()) else {
            return None;
        };
        if !(env.intensity.is_finite() && env.intensity > 0.0) {
            return None;
        }
        // The map resampled in world directions (rotation and intensity
        // applied by the one lookup), then a box-filtered pyramid.
        let w0 = img.width.max(1).next_power_of_two().clamp(64, 512);
        let base = LatLong::from_fn(w0, w0 / 2, |d| {
            let c = environment_radiance(scene, d);
            if c.is_finite() {
                c.max(Vec3::ZERO)
            } else {
                Vec3::ZERO
            }
        });
        let mut pyramid = vec![base];
        while pyramid[pyramid.len() - 1].h > 2 {
            let next = pyramid[pyramid.len() - 1].half();
            pyramid.push(next);
        }
        let levels = (1..LEVEL_ALPHAS.len())
            .map(|i| prefilter(&pyramid, LEVEL_ALPHAS[i], LEVEL_WIDTHS[i], LEVEL_SAMPLES[i]))
            .collect();
        let irradiance = irradiance(&pyramid);
        Some(Self { levels, irradiance })
    }

    /// The irradiance from the map at a surface with unit normal `n`
    /// divided by pi, `E(n) / pi` (the radiance a white Lambertian surface
    /// reflects), from a small image of it by normal (bilinear); never
    /// negative.
    pub fn irradiance_over_pi(&self, n: Vec3) -> Vec3 {
        match n.try_normalize() {
            Some(n) => self.irradiance.lookup(n),
            None => Vec3::ZERO,
        }
    }

    /// The prefiltered radiance around the reflected direction `r` (need
    /// not be unit) for roughness `alpha`, interpolated linearly between the
    /// two nearest levels; alpha 0 is the map itself, alphas beyond 1 read
    /// level 1.
    pub fn radiance(&self, scene: &Scene, r: Vec3, alpha: f32) -> Vec3 {
        let Some(r) = r.try_normalize() else {
            return Vec3::ZERO;
        };
        let a = if alpha.is_nan() {
            0.0
        } else {
            alpha.clamp(0.0, 1.0)
        };
        if a <= 0.0 {
            return environment_radiance(scene, r);
        }
        let i = LEVEL_ALPHAS[1..].iter().position(|&l| a <= l).unwrap_or(6);
        let (a0, a1) = (LEVEL_ALPHAS[i], LEVEL_ALPHAS[i + 1]);
        let hi = self.levels[i].lookup(r);
        if a >= a1 {
            return hi;
        }
        let lo = if i == 0 {
            environment_radiance(scene, r)
        } else {
            self.levels[i - 1].lookup(r)
        };
        lo.lerp(hi, (a - a0) / (a1 - a0))
    }
}

/// Width of the irradiance image (the height is half) and the widest
/// pyramid level it is integrated from.
const IRRADIANCE_WIDTH: u32 = 64;
const IRRADIANCE_SOURCE_WIDTH: u32 = 64;

/// `E(n) / pi` per texel (normal `n`): the cosine-weighted mean of the
/// map's pyramid level at most `IRRADIANCE_SOURCE_WIDTH` wide over the
/// hemisphere about `n`, texels weighted by their solid angle,
/// `sum L w cos / sum w cos` (exact for a constant map; never negative).
fn irradiance(pyramid: &[LatLong]) -> LatLong {
    let src = pyramid
        .iter()
        .find(|l| l.w <= IRRADIANCE_SOURCE_WIDTH)
        .unwrap_or(&pyramid[pyramid.len() - 1]);
    // Every source texel's direction, solid-angle weight and radiance.
    let texels: Vec<(Vec3, f32, Vec3)> = (0..src.w * src.h)
        .map(|i| {
            let uv = Vec2::new(
                ((i % src.w) as f32 + 0.5) / src.w as f32,
                ((i / src.w) as f32 + 0.5) / src.h as f32,
            );
            (latlong_dir(uv), (uv.y * PI).sin(), src.texels[i as usize])
        })
        .collect();
    LatLong::from_fn(IRRADIANCE_WIDTH, IRRADIANCE_WIDTH / 2, |n| {
        let (mut sum, mut weight) = (Vec3::ZERO, 0.0f32);
        for &(d, w, l) in &texels {
            let c = n.dot(d);
            if c > 0.0 {
                sum += l * (w * c);
                weight += w * c;
            }
        }
        if weight > 0.0 {
            sum / weight
        } else {
            Vec3::ZERO
        }
    })
}
/// One prefiltered level: per texel (direction `r`), the GGX lobe with
/// `n = v = r`, `sum L(l) (n.l) / sum (n.l)` over `n` Hammersley half
/// vectors, each read from the pyramid level whose texel's solid
/// angle matches the sample's (`1 / (N pdf)`, `pdf = D / 4`), one level
/// coarser (Karis's bias).
fn prefilter(pyramid: &[LatLong], alpha: f32, w: u32, n: u32) -> LatLong {
    let base = &pyramid[0];
    let texel_solid_angle = (TAU / base.w as f32) * (PI / base.h as f32);
    let max_lod = (pyramid.len() - 1) as f32;
    // The samples in the lobe's frame (+z = n = v): direction, weight,
    // level of detail before the sin(theta) of the texel it falls in.
    let samples: Vec<(Vec3, f32, f32)> = (0..n)
        .filter_map(|i| {
            let h = ggx_half_vector(alpha, hammersley(i, n));
            let l = 2.0 * h.z * h - Vec3::Z;
            if l.z <= 0.0 {
                return None;
            }
            let pdf = microfacet::d(Distribution::Ggx, h.z, alpha) / 4.0;
            let omega = 1.0 / (n as f32 * pdf.max(1e-12));
            Some((l, l.z, 0.5 * (omega / texel_solid_angle).log2() + 1.0))
        })
        .collect();
    LatLong::from_fn(w, w / 2, |r| {
        let frame = Frame::from_normal(r);
        let (mut sum, mut weight) = (Vec3::ZERO, 0.0f32);
        for &(l, nl, lod) in &samples {
            let d = frame.to_world(l);
            let sin_t = (d.x * d.x + d.z * d.z).sqrt().max(1e-3);
            let lod = (lod - 0.5 * sin_t.log2()).clamp(0.0, max_lod);
            let (k, f) = (lod.floor() as usize, lod.fract());
            let mut c = pyramid[k].lookup(d);
            if f > 0.0 && k + 1 < pyramid.len() {
                c = c.lerp(pyramid[k + 1].lookup(d), f);
            }
            sum += c * nl;
            weight += nl;
        }
        if weight > 0.0 {
            sum / weight
        } else {
            Vec3::ZERO
        }
    })
}

/// Cosines (of `n . wo`, from 0 to 1) and roughnesses (from 0 to 1) of the
/// directional albedo table's nodes, and BSDF samples per node.
const ALBEDO_COS: usize = 32;
const ALBEDO_ALPHA: usize = 16;
const ALBEDO_SAMPLES: u32 = 1024;

/// The specular lobe's directional albedo `integral f cos dwi` for
/// Torrance-Sparrow with Schlick's Fresnel, which is linear in F0: `F0 *
/// scale + bias`, tabulated over `n . wo` and alpha for one distribution.
#[derive(Debug, Clone)]
struct AlbedoTable {
    /// `[scale, bias]` per node, cosine-major.
    nodes: Vec<[f32; 2]>,
}

impl AlbedoTable {
    /// Integrates the shading layer's BSDF: `Bsdf::sample`'s weight is
    /// `eval_brdf_cos / pdf`, and with `ks = (1, 0, 0)` its red channel is
    /// the albedo for F0 = 1 (`scale + bias`) and its green one for F0 = 0
    /// (`bias`).
    fn new(dist: Distribution) -> Self {
        let nodes = (0..ALBEDO_COS * ALBEDO_ALPHA)
            .into_par_iter()
            .map(|i| {
                let (c, a) = (i / ALBEDO_ALPHA, i % ALBEDO_ALPHA);
                let cos_o = (c as f32 / (ALBEDO_COS - 1) as f32).max(1e-3);
                let alpha = a as f32 / (ALBEDO_ALPHA - 1) as f32;
                let e = directional_albedo(dist, cos_o, alpha, ALBEDO_SAMPLES);
                [e.x - e.y, e.y]
            })
            .collect();
        Self { nodes }
    }

    /// `(scale, bias)` at `cos_o` and `alpha`, bilinear between nodes
    /// (both clamped to `[0, 1]`).
    fn lookup(&self, cos_o: f32, alpha: f32) -> (f32, f32) {
        let x = cos_o.clamp(0.0, 1.0) * (ALBEDO_COS - 1) as f32;
        let y = if alpha.is_nan() {
            0.0
        } else {
            alpha.clamp(0.0, 1.0)
        } * (ALBEDO_ALPHA - 1) as f32;
        let (x0, y0) = (
            (x.floor() as usize).min(ALBEDO_COS - 2),
            (y.floor() as usize).min(ALBEDO_ALPHA - 2),
        );
        let (fx, fy) = (x - x0 as f32, y - y0 as f32);
        let at = |c: usize, a: usize| Vec2::from(self.nodes[c * ALBEDO_ALPHA + a]);
        let v = at(x0, y0)
            .lerp(at(x0, y0 + 1), fy)
            .lerp(at(x0 + 1, y0).lerp(at(x0 + 1, y0 + 1), fy), fx);
        (v.x, v.y)
    }
}

/// The directional albedo of a Torrance-Sparrow lobe with
/// `ks = (1, 0, 0)` (red: F0 = 1, green and blue: F0 = 0) for
/// `n . wo = cos_o`, by `samples` Hammersley samples of the shading
/// layer's [`Bsdf::sample`].
fn directional_albedo(dist: Distribution, cos_o: f32, alpha: f32, samples: u32) -> Vec3 {
    let bsdf = Bsdf::new(
        SurfaceMaterial {
            kd: Vec3::ZERO,
            ks: Vec3::X,
            model: ReflectanceModel::TorranceSparrow,
            roughness: alpha,
            distribution: dist,
            kr: Vec3::ZERO,
            kt: Vec3::ZERO,
            ..SurfaceMaterial::default()
        },
        false,
    );
    let wo = Vec3::new((1.0 - cos_o * cos_o).max(0.0).sqrt(), 0.0, cos_o);
    let mut sum = Vec3::ZERO;
    for i in 0..samples {
        if let Some(s) = bsdf.sample(
            Vec3::Z,
            Vec3::Z,
            wo,
            true,
            0.5,
            hammersley(i, samples),
            || 0.5,
        ) && !s.delta
        {
            sum += s.weight;
        }
    }
    sum / samples as f32
}

/// The albedo tables of both distributions, built on first use (they do
/// not depend on the scene).
fn albedo_tables() -> &'static [AlbedoTable; 2] {
    static TABLES: OnceLock<[AlbedoTable; 2]> = OnceLock::new();
    if let Some(t) = TABLES.get() {
        return t;
    }
    // Built outside the lock: the tables use rayon, and a rayon worker
    // blocked in `get_or_init` while the initialising thread waits for
    // that pool deadlocks (seen with tests rendering in parallel). Two
    // threads may both build them; the values are the same.
    let tables = [
        AlbedoTable::new(Distribution::Ggx),
        AlbedoTable::new(Distribution::Beckmann),
    ];
    TABLES.get_or_init(|| tables)
}

/// The split sum's second factor for Torrance-Sparrow: `(scale, bias)` with
/// `F0 * scale + bias` the lobe's directional albedo at `n . wo = cos_o`.
pub fn specular_albedo_scale_bias(dist: Distribution, cos_o: f32, alpha: f32) -> (f32, f32) {
    let t = &albedo_tables()[match dist {
        Distribution::Ggx => 0,
        Distribution::Beckmann => 1,
    }];
    t.lookup(cos_o, alpha)
}

/// The specular lobe of `m` as the split sum sees it at `n . wo = cos_o`:
/// the roughness whose prefiltered level to read and the lobe's
/// directional albedo. Torrance-Sparrow reads its tabulated albedo. Phong
/// and Blinn use the alpha of the Beckmann lobe their exponent
/// approximates (Walter et al. 2007: Blinn `n = 2 / alpha^2 - 2`; a Phong
/// exponent is about a quarter of Blinn's) and their lobes' albedo at
/// normal incidence in closed form: Phong `2 ks / (n + 1)`, Blinn
/// `8 ks / (n + 2) (1 - 2^(-(n + 2) / 2))` (its half vectors beyond 45
/// degrees reflect below the horizon).
pub fn specular_lobe_albedo(m: &SurfaceMaterial, cos_o: f32) -> (f32, Vec3) {
    let n = m.shininess.max(0.0);
    match m.model {
        ReflectanceModel::TorranceSparrow => {
            let (scale, bias) = specular_albedo_scale_bias(m.distribution, cos_o, m.roughness);
            match m.conductor {
                None => (m.roughness, m.ks * scale + Vec3::splat(bias)),
                // A conductor: the same fit with its normal-incidence
                // reflectance as F0 (Schlick's curve is close to a
                // conductor's Fresnel), tinted by ks.
                Some(c) => {
                    let f = fresnel_conductor(1.0, c.eta, c.k);
                    (m.roughness, m.ks * (f * scale + Vec3::splat(bias)))
                }
            }
        }
        ReflectanceModel::Phong => ((1.0 / (2.0 * n + 1.0)).sqrt(), m.ks * (2.0 / (n + 1.0))),
        ReflectanceModel::Blinn => (
            (2.0 / (n + 2.0)).sqrt().min(1.0),
            m.ks * (8.0 / (n + 2.0) * (1.0 - (-(n + 2.0) / 2.0).exp2())),
        ),
    }
}

/// The map's light reflected by the Lambertian lobe of diffuse colour `kd`
/// at a point with unit normal `n`: `kd E(n) / pi` from the map's
/// irradiance image. A light like the others, so not scaled
/// by the ambient coefficient. The one diffuse environment term of the
/// scan converter and Whitted.
pub fn environment_diffuse(table: &PrefilteredEnvironment, kd: Vec3, n: Vec3) -> Vec3 {
    if kd == Vec3::ZERO {
        return Vec3::ZERO;
    }
    kd * table.irradiance_over_pi(n)
}

/// The environment reflected by the specular lobe of `m` at a point with
/// unit normal `n` seen from the unit direction `wo`: the split sum
/// `prefiltered(reflect(wo, n), alpha) * albedo` (see
/// [`specular_lobe_albedo`]), under the clear coat if any (which attenuates
/// it by `1 - c F(cos_o)` and adds its own split sum, F0 = 0.04). Zero
/// without a specular lobe or coat, or when `wo` is below the surface. The
/// one glossy environment term of the scan converter and Whitted.
pub fn environment_specular(
    table: &PrefilteredEnvironment,
    scene: &Scene,
    m: &SurfaceMaterial,
    n: Vec3,
    wo: Vec3,
) -> Vec3 {
    let coat = m.clearcoat > 0.0;
    if !m.has_specular() && !coat {
        return Vec3::ZERO;
    }
    let cos_o = n.dot(wo);
    // NaN fails too.
    if cos_o.is_nan() || cos_o <= 0.0 {
        return Vec3::ZERO;
    }
    let r = reflect(wo, n);
    let base = if m.has_specular() {
        let (alpha, albedo) = specular_lobe_albedo(m, cos_o);
        table.radiance(scene, r, alpha) * albedo
    } else {
        Vec3::ZERO
    };
    if !coat {
        return base;
    }
    let alpha = m.clearcoat_alpha;
    let (scale, bias) = specular_albedo_scale_bias(Distribution::Ggx, cos_o, alpha);
    let attenuation =
        1.0 - m.clearcoat * fresnel_dielectric(cos_o, 1.0, crate::shading::brdf::CLEARCOAT_IOR);
    base * attenuation + table.radiance(scene, r, alpha) * (m.clearcoat * (0.04 * scale + bias))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::ImageTexture;
    use crate::shading::fresnel::fresnel_schlick;

    fn map_scene(w: u32, h: u32, f: impl Fn(u32, u32) -> f32, rotate: f32) -> Scene {
        let mut scene = Scene::default();
        let mut texels = Vec::new();
        for y in 0..h {
            for x in 0..w {
                let v = f(x, y);
                texels.push([v, v, v, 1.0]);
            }
        }
        let t = scene.add_texture(Texture::Image(ImageTexture {
            source: "t".into(),
            width: w,
            height: h,
            texels,
            ..ImageTexture::default()
        }));
        scene.environment = Some(crate::scene::Environment {
            texture: t,
            intensity: 1.0,
            rotate_y_degrees: rotate,
            as_background: false,
        });
        scene
    }

    fn dirs() -> impl Iterator<Item = Vec3> {
        (0..40).map(|i| {
            let u = hammersley(i, 40);
            let z = 1.0 - 2.0 * u.x;
            let r = (1.0 - z * z).max(0.0).sqrt();
            Vec3::new(r * (TAU * u.y).cos(), z, r * (TAU * u.y).sin())
        })
    }

    /// A constant map L is L at every level, roughness and direction.
    #[test]
    fn a_constant_map_prefilters_to_itself() {
        let scene = map_scene(64, 32, |_, _| 2.5, 30.0);
        let t = PrefilteredEnvironment::new(&scene).expect("a map");
        for d in dirs() {
            for a in [0.0, 0.03, 0.05, 0.15, 0.3, 0.6, 1.0, 2.0] {
                let c = t.radiance(&scene, d, a);
                assert!(
                    (c - Vec3::splat(2.5)).abs().max_element() < 1e-4,
                    "{d} {a}: {c}"
                );
            }
        }
        assert!(PrefilteredEnvironment::new(&Scene::default()).is_none());
    }

    /// A map bright above the horizon: a rough lobe pointing straight up
    /// sees mostly light, one pointing down mostly darkness, and a smooth
    /// one sees the map; levels increase monotonically in blur (a lobe on
    /// the horizon sees about half).
    #[test]
    fn prefiltering_blurs_the_horizon() {
        let scene = map_scene(128, 64, |_, y| if y < 32 { 1.0 } else { 0.0 }, 0.0);
        let t = PrefilteredEnvironment::new(&scene).expect("a map");
        let up = Vec3::new(0.0, 1.0, 0.0);
        assert!(t.radiance(&scene, up, 1.0).x > 0.8);
        assert!(t.radiance(&scene, -up, 1.0).x < 0.2);
        let near = Vec3::new(1.0, 0.15, 0.0).normalize();
        let mut last = 1.0;
        for a in LEVEL_ALPHAS {
            let c = t.radiance(&scene, near, a).x;
            assert!(c <= last + 1e-3, "alpha {a}: {c} after {last}");
            last = c;
        }
        assert!((t.radiance(&scene, near, 0.0).x - 1.0).abs() < 1e-6);
        let horizon = t.radiance(&scene, Vec3::X, 0.35).x;
        assert!((horizon - 0.5).abs() < 0.05, "{horizon}");
    }

    /// Irradiance: a constant map L gives `E = pi L` for every normal; a
    /// map of L above the horizon and 0 below gives the cosine lobe's
    /// closed form `E(n) = pi L (1 + n.y) / 2`.
    #[test]
    fn irradiance_closed_forms() {
        let scene = map_scene(64, 32, |_, _| 1.5, 45.0);
        let t = PrefilteredEnvironment::new(&scene).expect("a map");
        for d in dirs() {
            let e = t.irradiance_over_pi(d);
            assert!(
                (e - Vec3::splat(1.5)).abs().max_element() < 1e-4,
                "{d}: {e}"
            );
        }
        let scene = map_scene(128, 64, |_, y| if y < 32 { 2.0 } else { 0.0 }, 0.0);
        let t = PrefilteredEnvironment::new(&scene).expect("a map");
        for d in dirs() {
            let e = t.irradiance_over_pi(d).x;
            let expect = 2.0 * (1.0 + d.y) / 2.0;
            assert!((e - expect).abs() < 0.02, "{d}: {e} vs {expect}");
        }
    }

    /// At roughness 0 the albedo is Schlick's Fresnel at `n . wo`:
    /// `scale = 1 - (1 - cos)^5` and `bias = (1 - cos)^5`.
    #[test]
    fn the_albedo_table_at_zero_roughness_is_schlick() {
        for dist in [Distribution::Ggx, Distribution::Beckmann] {
            for k in 3..ALBEDO_COS {
                let c = k as f32 / (ALBEDO_COS - 1) as f32;
                let (s, b) = specular_albedo_scale_bias(dist, c, 0.0);
                for f0 in [0.04f32, 0.5, 0.95] {
                    let e = fresnel_schlick(Vec3::splat(f0), c).x;
                    assert!(
                        (f0 * s + b - e).abs() < 0.01,
                        "{dist:?} cos {c} F0 {f0}: {} vs {e}",
                        f0 * s + b
                    );
                }
            }
        }
    }

    /// For F0 = 1 the table's `scale + bias` is the BRDF's directional
    /// albedo, checked against a plain Monte Carlo integration of
    /// `eval_brdf_cos` over uniformly drawn directions (pseudo-random, not
    /// the BSDF's sampler) within 0.02; F0 = 0 (`bias`) within 0.01.
    #[test]
    fn the_albedo_table_matches_an_independent_integration() {
        use crate::sampling::{pixel_rng, uniform2};
        use crate::shading::eval_brdf_cos;
        let mut rng = pixel_rng(7, 1, 2, 3);
        for dist in [Distribution::Ggx, Distribution::Beckmann] {
            for (cos_o, alpha) in [
                (1.0f32, 0.2f32),
                (0.7, 0.4),
                (0.4, 0.6),
                (0.2, 1.0),
                (0.9, 0.8),
            ] {
                let m = |ks: f32| SurfaceMaterial {
                    kd: Vec3::ZERO,
                    ks: Vec3::splat(ks),
                    model: ReflectanceModel::TorranceSparrow,
                    roughness: alpha,
                    distribution: dist,
                    ..SurfaceMaterial::default()
                };
                let wo = Vec3::new((1.0 - cos_o * cos_o).sqrt(), 0.0, cos_o);
                let n = 200_000;
                let (mut one, mut zero) = (0.0f64, 0.0f64);
                let (m1, m0) = (m(1.0), m(1e-30));
                for _ in 0..n {
                    let wi = crate::sampling::sample_uniform_hemisphere(uniform2(&mut rng));
                    one += f64::from(eval_brdf_cos(&m1, Vec3::Z, wo, wi).x);
                    zero += f64::from(eval_brdf_cos(&m0, Vec3::Z, wo, wi).x);
                }
                let (one, zero) = (
                    (one * f64::from(TAU) / n as f64) as f32,
                    (zero * f64::from(TAU) / n as f64) as f32,
                );
                let (s, b) = specular_albedo_scale_bias(dist, cos_o, alpha);
                assert!(
                    (s + b - one).abs() < 0.02,
                    "{dist:?} cos {cos_o} alpha {alpha}: {} vs {one}",
                    s + b
                );
                assert!(
                    (b - zero).abs() < 0.01,
                    "{dist:?} cos {cos_o} alpha {alpha}: {b} vs {zero}"
                );
            }
        }
    }

    /// Under a constant map L, a specular lobe reflects L times its albedo
    /// (the split sum is exact there); nothing without a lobe or from below.
    #[test]
    fn environment_specular_under_a_constant_map_is_l_times_albedo() {
        let scene = map_scene(32, 16, |_, _| 2.0, 0.0);
        let t = PrefilteredEnvironment::new(&scene).expect("a map");
        let metal = SurfaceMaterial {
            kd: Vec3::ZERO,
            ks: Vec3::new(1.0, 0.8, 0.3),
            model: ReflectanceModel::TorranceSparrow,
            roughness: 0.3,
            ..SurfaceMaterial::default()
        };
        let wo = Vec3::new(0.6, 0.8, 0.0);
        let c = environment_specular(&t, &scene, &metal, Vec3::Y, wo);
        let (s, b) = specular_albedo_scale_bias(Distribution::Ggx, 0.8, 0.3);
        let expect = 2.0 * (metal.ks * s + Vec3::splat(b));
        assert!((c - expect).abs().max_element() < 1e-3, "{c} vs {expect}");
        assert_eq!(
            environment_specular(&t, &scene, &metal, Vec3::Y, -wo),
            Vec3::ZERO
        );
        let matte = SurfaceMaterial {
            ks: Vec3::ZERO,
            ..metal
        };
        assert_eq!(
            environment_specular(&t, &scene, &matte, Vec3::Y, wo),
            Vec3::ZERO
        );
        // Phong: 2 ks / (n + 1) times L.
        let phong = SurfaceMaterial {
            ks: Vec3::ONE,
            shininess: 9.0,
            model: ReflectanceModel::Phong,
            ..metal
        };
        let c = environment_specular(&t, &scene, &phong, Vec3::Y, Vec3::Y);
        assert!((c.x - 2.0 * 0.2).abs() < 1e-3, "{c}");
    }
}
