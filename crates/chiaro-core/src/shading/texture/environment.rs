//! Environment maps (Blinn and Newell 1976; lat-long after Miller and Hoffman
//! 1984): lookups, the importance-sampled [`EnvironmentLight`], the miss rule.

use super::image::{bilinear, bilinear_lanes, wrap_index};
use super::latlong::{latlong_dir, latlong_uv, latlong_uv_lanes};
use crate::scene::{Scene, Texture};
use glam::{Vec2, Vec3};

/// Radiance of the scene's environment map in world direction `dir` (need not
/// be unit): the lat-long image (rotated by `rotate_y_degrees` about +y)
/// times `intensity`, linear RGB. Zero when the scene has no environment or
/// its texture is missing or not an image. Uses the base level (bilinear).
pub fn environment_radiance(scene: &Scene, dir: Vec3) -> Vec3 {
    let Some(env) = &scene.environment else {
        return Vec3::ZERO;
    };
    let Some(Texture::Image(img)) = scene.textures.get(env.texture.index()) else {
        return Vec3::ZERO;
    };
    let Some(d) = dir.try_normalize() else {
        return Vec3::ZERO;
    };
    bilinear(img, environment_uv(env, d)).truncate() * env.intensity
}

/// The image coordinates the environment `env` shows in unit direction `d`.
/// The map turned by +a about +y (right-handed, as an object's `rotate_y`
/// turns it) shows at `d` what it showed at `R_y(-a) d`; a rotation about
/// y keeps `v` and moves the azimuth `u` by `+a / 360`.
#[inline]
pub(super) fn environment_uv(env: &crate::scene::Environment, d: Vec3) -> Vec2 {
    let uv = latlong_uv(d);
    Vec2::new(turned_u(env, uv.x), uv.y)
}

/// The lat-long `u` of the map `env` turned by its rotation, wrapped
/// into `[0, 1)`.
#[inline(always)]
fn turned_u(env: &crate::scene::Environment, u: f32) -> f32 {
    // (`x - floor(x)` is `x.rem_euclid(1.0)` bit for bit, both one
    // rounding of the same exact value, without `fmodf`; -0 gives +0.)
    let x = u + env.rotate_y_degrees / 360.0;
    x - x.floor()
}

/// The unit direction whose [`environment_uv`] is `uv` (`v` from the top,
/// `theta = v pi`), and `sin(theta)`: [`latlong_dir`] turned by the map's
/// rotation.
#[inline]
fn environment_dir(env: &crate::scene::Environment, uv: Vec2) -> (Vec3, f32) {
    latlong_dir(uv, env.rotate_y_degrees / 360.0)
}

/// A direction drawn towards the environment by [`EnvironmentLight::sample`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EnvironmentSample {
    /// Unit direction towards the environment.
    pub wi: Vec3,
    /// [`environment_radiance`] in that direction.
    pub radiance: Vec3,
    /// Density per solid angle.
    pub pdf: f32,
}

/// [`EnvironmentSample`]s of `N` lanes, as component arrays
/// ([`EnvironmentLight::sample_lanes`]).
#[derive(Debug, Clone, Copy)]
pub struct EnvironmentSamples<const N: usize> {
    /// Unit directions towards the environment.
    pub wi: [[f32; N]; 3],
    /// [`environment_radiance`] in those directions.
    pub radiance: [[f32; N]; 3],
    /// Densities per solid angle.
    pub pdf: [f32; N],
    /// False where [`EnvironmentLight::sample`] gives `None` (and in the
    /// lanes not asked for).
    pub ok: [bool; N],
}

/// The environment map as a light to sample (pbrt-v4's
/// `ImageInfiniteLight`, Mitsuba 3's `envmap`): a piecewise-constant
/// density over the lat-long image proportional to the luminance of the
/// bilinear lookup averaged over each texel, times `sin(theta)` (the
/// texel's solid angle). The average covers every texel the bilinear
/// lookup reads there, so the density is positive wherever
/// [`environment_radiance`] is, and next-event estimation alone is
/// unbiased. Radiance comes from [`environment_radiance`], directions
/// follow its rotation rule: one lookup.
#[derive(Debug, Clone)]
pub struct EnvironmentLight<'s> {
    pub(super) scene: &'s Scene,
    pub(super) env: &'s crate::scene::Environment,
    pub(super) dist: crate::sampling::PiecewiseConstant2D,
    /// The mean radiance over the sphere (luminance), for the light's power.
    mean_luminance: f32,
}

impl<'s> EnvironmentLight<'s> {
    /// The environment of `scene` as a light; `None` without an image map
    /// or when it is black (or its intensity is not positive).
    pub fn new(scene: &'s Scene) -> Option<Self> {
        let env = scene.environment.as_ref()?;
        let Some(Texture::Image(img)) = scene.textures.get(env.texture.index()) else {
            return None;
        };
        if !(env.intensity.is_finite() && env.intensity > 0.0) {
            return None;
        }
        // An image without texels reads as white (see `bilinear`): one cell.
        let n = img.texel_count();
        let (w, h) = if n == 0 {
            (1, 1)
        } else {
            (img.width.max(1), img.height.max(1))
        };
        if n != 0 && n != (w as usize) * (h as usize) {
            return None;
        }
        use rayon::prelude::*;
        // Each texel's luminance (negative and non-finite channels as 0).
        let lum: Vec<f32> = if n == 0 {
            vec![1.0]
        } else {
            (0..n)
                .into_par_iter()
                .map(|i| {
                    let t = img.texel_at(i);
                    let c = |v: f32| if v.is_finite() { v.max(0.0) } else { 0.0 };
                    0.2126 * c(t[0]) + 0.7152 * c(t[1]) + 0.0722 * c(t[2])
                })
                .collect()
        };
        let (wrap_u, wrap_v) = img.wrap_uv();
        let at = |x: i64, y: i64| -> f32 {
            if lum.len() == 1 {
                return lum[0];
            }
            let (x, y) = (wrap_index(x, w, wrap_u), wrap_index(y, h, wrap_v));
            lum[(y * w + x) as usize]
        };
        // The bilinear lookup's mean over texel (x, y): its tent filter's
        // weights over the cell are 3/4 for the texel and 1/8 for each
        // neighbour per axis. Rows in parallel (a 1k map in a few ms).
        const W: [f32; 3] = [0.125, 0.75, 0.125];
        let rows: Vec<Vec<f32>> = (0..h)
            .into_par_iter()
            .map(|y| {
                let sin_t = ((y as f32 + 0.5) / h as f32 * std::f32::consts::PI).sin();
                (0..w)
                    .map(|x| {
                        let mut m = 0.0;
                        for (dy, wy) in W.iter().enumerate() {
                            for (dx, wx) in W.iter().enumerate() {
                                let (tx, ty) =
                                    (i64::from(x) + dx as i64 - 1, i64::from(y) + dy as i64 - 1);
                                m += wy * wx * at(tx, ty);
                            }
                        }
                        m * sin_t
                    })
                    .collect()
            })
            .collect();
        let func: Vec<f32> = rows.concat();
        let sum: f64 = func.iter().map(|&f| f64::from(f)).sum();
        let weight: f64 = (0..h)
            .map(|y| {
                f64::from(((y as f32 + 0.5) / h as f32 * std::f32::consts::PI).sin()) * f64::from(w)
            })
            .sum();
        let dist = crate::sampling::PiecewiseConstant2D::new(&func, w as usize)?;
        Some(Self {
            scene,
            env,
            dist,
            mean_luminance: (sum / weight.max(1e-30)) as f32 * env.intensity,
        })
    }

    /// A direction for the uniform pair `u`: the direction, its radiance
    /// and its density per solid angle (`pdf_uv / (2 pi^2 sin theta)`);
    /// `None` at the poles, where the density is infinite. One lane of
    /// [`Self::sample_lanes`].
    #[inline]
    pub fn sample(&self, u: Vec2) -> Option<EnvironmentSample> {
        let s = self.sample_lanes(&[u.x], &[u.y], &[true]);
        let at = |v: &[[f32; 1]; 3]| Vec3::new(v[0][0], v[1][0], v[2][0]);
        s.ok[0].then(|| EnvironmentSample {
            wi: at(&s.wi),
            radiance: at(&s.radiance),
            pdf: s.pdf[0],
        })
    }

    /// [`Self::sample`] of the pairs `(u0[i], u1[i])` of the lanes set in
    /// `m`: the cell searches lane by lane (every lane's row, then every
    /// lane's column), then the directions (the
    /// polynomial `sin_cos`), densities and radiance lookups of all lanes
    /// together, each lane's bits what one lane alone gets.
    #[inline(always)]
    pub fn sample_lanes<const N: usize>(
        &self,
        u0: &[f32; N],
        u1: &[f32; N],
        m: &[bool; N],
    ) -> EnvironmentSamples<N> {
        let (su, sv, pdf_uv) = self.dist.sample_lanes(u0, u1, m);
        let mut wi = [[0.0; N]; 3];
        let mut pdf = [0.0; N];
        let mut ok = [false; N];
        for i in 0..N {
            let (d, sin_t) = environment_dir(self.env, Vec2::new(su[i], sv[i]));
            (wi[0][i], wi[1][i], wi[2][i]) = (d.x, d.y, d.z);
            ok[i] = m[i] & (sin_t > 0.0 && pdf_uv[i] > 0.0);
            pdf[i] = pdf_uv[i] / (2.0 * std::f32::consts::PI * std::f32::consts::PI * sin_t);
        }
        let (radiance, _) = self.lookup_lanes(&wi, &ok, false);
        EnvironmentSamples {
            wi,
            radiance,
            pdf,
            ok,
        }
    }

    /// The density per solid angle with which [`Self::sample`] draws the
    /// direction `dir` (need not be unit).
    #[inline]
    pub fn pdf(&self, dir: Vec3) -> f32 {
        let Some(d) = dir.try_normalize() else {
            return 0.0;
        };
        let sin_t = (d.x * d.x + d.z * d.z).sqrt();
        if sin_t <= 0.0 {
            return 0.0;
        }
        self.dist.pdf(environment_uv(self.env, d))
            / (2.0 * std::f32::consts::PI * std::f32::consts::PI * sin_t)
    }

    /// [`environment_radiance`] in direction `dir` (need not be unit) and
    /// [`Self::pdf`] of it, the same values from one lat-long lookup (what
    /// a path tracer needs of a ray that escapes after a scatter). One
    /// lane of [`Self::radiance_pdf_lanes`].
    #[inline]
    pub fn radiance_pdf(&self, dir: Vec3) -> (Vec3, f32) {
        let (l, pdf) = self.lookup_lanes(&[[dir.x], [dir.y], [dir.z]], &[true], true);
        (Vec3::new(l[0][0], l[1][0], l[2][0]), pdf[0])
    }

    /// [`Self::radiance_pdf`] of the directions `(d[0][i], d[1][i],
    /// d[2][i])` of the lanes set in `m` (zero in the others), each
    /// lane's bits what one lane alone gets.
    #[inline(always)]
    pub fn radiance_pdf_lanes<const N: usize>(
        &self,
        d: &[[f32; N]; 3],
        m: &[bool; N],
    ) -> ([[f32; N]; 3], [f32; N]) {
        self.lookup_lanes(d, m, true)
    }

    /// [`environment_radiance`] of the lanes set in `m`, and with `want_pdf`
    /// [`Self::pdf`], in passes over the lanes: the unit directions and the
    /// lat-long mapping (vectorised), the bilinear lookups (their texel
    /// reads issued together), the densities.
    #[inline(always)]
    fn lookup_lanes<const N: usize>(
        &self,
        d: &[[f32; N]; 3],
        m: &[bool; N],
        want_pdf: bool,
    ) -> ([[f32; N]; 3], [f32; N]) {
        // The unit directions (as `try_normalize`; lanes it refuses see
        // nothing).
        let mut unit = [[0.0; N]; 3];
        let mut ok = [false; N];
        for i in 0..N {
            if let Some(v) = Vec3::new(d[0][i], d[1][i], d[2][i]).try_normalize() {
                (unit[0][i], unit[1][i], unit[2][i]) = (v.x, v.y, v.z);
                ok[i] = m[i];
            }
        }
        let (mut u, v) = latlong_uv_lanes(&unit[0], &unit[1], &unit[2]);
        for u in &mut u {
            *u = turned_u(self.env, *u);
        }
        let mut radiance = [[0.0; N]; 3];
        if let Some(Texture::Image(img)) = self.scene.textures.get(self.env.texture.index()) {
            let rgba = bilinear_lanes(img, &u, &v, &ok);
            for i in 0..N {
                let c = rgba[i].truncate() * self.env.intensity;
                (radiance[0][i], radiance[1][i], radiance[2][i]) = (c.x, c.y, c.z);
            }
        }
        let mut pdf = [0.0; N];
        if want_pdf {
            for i in 0..N {
                let (x, z) = (unit[0][i], unit[2][i]);
                let sin_t = (x * x + z * z).sqrt();
                if ok[i] && sin_t > 0.0 {
                    pdf[i] = self.dist.pdf(Vec2::new(u[i], v[i]))
                        / (2.0 * std::f32::consts::PI * std::f32::consts::PI * sin_t);
                }
            }
        }
        (radiance, pdf)
    }

    /// The map's mean radiance over the sphere (luminance, intensity
    /// applied): the power of the light through a disk of radius `r` is
    /// `4 pi^2 r^2` times it (pbrt-v4's `ImageInfiniteLight::Phi`).
    pub fn mean_luminance(&self) -> f32 {
        self.mean_luminance
    }
}

/// The environment's irradiance `E(n)` divided by pi, averaged over all
/// normals `n`: the constant ambient radiance under which a Lambertian
/// surface reflects, on average over its orientations, what it reflects
/// under the map. Averaging the cosine-weighted `E(n)` over the sphere
/// of normals leaves the map's mean radiance over solid angle, integrated
/// here with [`environment_radiance`] at one direction per texel (at most
/// 512x256), rows weighted by `sin(theta)`. Zero without an environment.
pub fn environment_mean_radiance(scene: &Scene) -> Vec3 {
    let Some(env) = &scene.environment else {
        return Vec3::ZERO;
    };
    let Some(Texture::Image(img)) = scene.textures.get(env.texture.index()) else {
        return Vec3::ZERO;
    };
    let (w, h) = (img.width.clamp(1, 512), img.height.clamp(1, 256));
    let (mut sum, mut weight) = (Vec3::ZERO, 0.0f64);
    for row in 0..h {
        let theta = (row as f32 + 0.5) / h as f32 * std::f32::consts::PI;
        let (sin_t, cos_t) = theta.sin_cos();
        let mut row_sum = Vec3::ZERO;
        for col in 0..w {
            let phi = (col as f32 + 0.5) / w as f32 * std::f32::consts::TAU;
            // Any azimuth origin will do: the whole circle is summed.
            let d = Vec3::new(sin_t * phi.cos(), cos_t, sin_t * phi.sin());
            row_sum += environment_radiance(scene, d);
        }
        sum += row_sum * sin_t;
        weight += f64::from(sin_t) * f64::from(w);
    }
    if weight > 0.0 {
        sum / weight as f32
    } else {
        Vec3::ZERO
    }
}

/// What a ray that leaves the scene in direction `dir` sees: a camera ray
/// (`camera`) sees the environment map only when it is drawn as background
/// (`Environment::as_background`), else `scene.background`; any other ray
/// (reflected, refracted, scattered) sees the environment map when there is
/// one, else `scene.background`. The one rule for every technique.
pub fn miss_radiance(scene: &Scene, dir: Vec3, camera: bool) -> Vec3 {
    match &scene.environment {
        Some(env) if env.as_background || !camera => environment_radiance(scene, dir),
        _ => scene.background,
    }
}

/// What the camera sees in direction `dir` where no surface is hit:
/// [`miss_radiance`] of a camera ray.
pub fn background_radiance(scene: &Scene, dir: Vec3) -> Vec3 {
    miss_radiance(scene, dir, true)
}
