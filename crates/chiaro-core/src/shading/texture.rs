//! Texture evaluation, shared by every technique: image textures (bilinear,
//! and trilinear through [`MipMap`] pyramids), procedural solid textures
//! (checker, wood, marble, noise, dimples, from Perlin noise and turbulence),
//! bump mapping by the height gradient, tangent-space normal maps, and the
//! lat-long environment map.

use crate::scene::{Filter, ImageTexture, Procedural, ProceduralKind, Scene, Texture, WrapMode};
use glam::{Vec2, Vec3, Vec4};

/// Wraps a texel coordinate into `0..size`.
#[inline]
pub fn wrap_index(i: i64, size: u32, mode: WrapMode) -> u32 {
    let n = i64::from(size.max(1));
    match mode {
        WrapMode::Repeat => i.rem_euclid(n) as u32,
        WrapMode::Clamp => i.clamp(0, n - 1) as u32,
        WrapMode::Mirror => {
            let m = i.rem_euclid(2 * n);
            (if m < n { m } else { 2 * n - 1 - m }) as u32
        }
    }
}

/// Bilinear lookup of `img` at `uv` (`v = 0` at the top row, as glTF and
/// OBJ-with-flip use), returning linear RGBA. The image's uv transform is
/// not applied here (see [`eval_texture`]).
pub fn bilinear(img: &ImageTexture, uv: Vec2) -> Vec4 {
    if img.texels.is_empty() {
        return Vec4::ONE;
    }
    let x = uv.x * img.width as f32 - 0.5;
    let y = uv.y * img.height as f32 - 0.5;
    if !(x.is_finite() && y.is_finite()) {
        return Vec4::from(img.texels[0]);
    }
    let (wrap_u, wrap_v) = img.wrap_uv();
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = (x - x0, y - y0);
    let (x0, y0) = (x0 as i64, y0 as i64);
    let t = |dx: i64, dy: i64| {
        Vec4::from(img.texel(
            wrap_index(x0 + dx, img.width, wrap_u),
            wrap_index(y0 + dy, img.height, wrap_v),
        ))
    };
    let top = t(0, 0).lerp(t(1, 0), fx);
    let bottom = t(0, 1).lerp(t(1, 1), fx);
    top.lerp(bottom, fy)
}

/// Nearest-texel lookup of `img` at `uv` (the texel containing it), linear RGBA.
pub fn nearest(img: &ImageTexture, uv: Vec2) -> Vec4 {
    if img.texels.is_empty() {
        return Vec4::ONE;
    }
    let x = (uv.x * img.width as f32).floor();
    let y = (uv.y * img.height as f32).floor();
    if !(x.is_finite() && y.is_finite()) {
        return Vec4::from(img.texels[0]);
    }
    let (wrap_u, wrap_v) = img.wrap_uv();
    Vec4::from(img.texel(
        wrap_index(x as i64, img.width, wrap_u),
        wrap_index(y as i64, img.height, wrap_v),
    ))
}

/// A lookup in one level with `filter`.
#[inline]
fn filtered(img: &ImageTexture, uv: Vec2, filter: Filter) -> Vec4 {
    match filter {
        Filter::Linear => bilinear(img, uv),
        Filter::Nearest => nearest(img, uv),
    }
}

// ---------------------------------------------------------------------------
// Mip-mapping (Williams 1983, "Pyramidal parametrics").

/// A mip-map pyramid of an image texture: level 0 is the image, each next
/// level halves both sides (rounding up) by a 2x2 box filter, down to 1x1.
#[derive(Debug, Clone, PartialEq)]
pub struct MipMap {
    /// The levels, finest first.
    pub levels: Vec<ImageTexture>,
}

impl MipMap {
    /// Builds the pyramid of `img`. An empty image gives a single empty level
    /// (which samples as white, like [`bilinear`]).
    pub fn new(img: &ImageTexture) -> Self {
        let mut levels = vec![img.clone()];
        while let Some(prev) = levels.last() {
            if prev.texels.is_empty() || (prev.width <= 1 && prev.height <= 1) {
                break;
            }
            let (w, h) = (
                prev.width.div_ceil(2).max(1),
                prev.height.div_ceil(2).max(1),
            );
            let mut texels = Vec::with_capacity((w * h) as usize);
            for y in 0..h {
                for x in 0..w {
                    // Average the (up to) 2x2 parent texels; odd edges repeat the last one.
                    let x0 = (2 * x).min(prev.width - 1);
                    let x1 = (2 * x + 1).min(prev.width - 1);
                    let y0 = (2 * y).min(prev.height - 1);
                    let y1 = (2 * y + 1).min(prev.height - 1);
                    let s = Vec4::from(prev.texel(x0, y0))
                        + Vec4::from(prev.texel(x1, y0))
                        + Vec4::from(prev.texel(x0, y1))
                        + Vec4::from(prev.texel(x1, y1));
                    texels.push((s * 0.25).to_array());
                }
            }
            let next = ImageTexture {
                source: prev.source.clone(),
                width: w,
                height: h,
                texels,
                ..*prev
            };
            levels.push(next);
        }
        Self { levels }
    }

    /// The level of detail for the screen-space derivatives of the texture
    /// coordinates, `duv_dx` and `duv_dy` (uv units per pixel): `log2` of the
    /// longer footprint side in level-0 texels (OpenGL 4.6 section 8.14.1,
    /// equation 8.7), clamped to `[0, levels - 1]`. Non-finite input gives 0.
    pub fn lod(&self, duv_dx: Vec2, duv_dy: Vec2) -> f32 {
        let base = &self.levels[0];
        let size = Vec2::new(base.width as f32, base.height as f32);
        let rho = (duv_dx * size).length().max((duv_dy * size).length());
        let lod = if rho > 0.0 { rho.log2() } else { 0.0 };
        if !lod.is_finite() {
            return 0.0;
        }
        lod.clamp(0.0, (self.levels.len() - 1) as f32)
    }

    /// Lookup at level of detail `lod` with the image's filters (OpenGL 4.6
    /// section 8.14): `lod <= 0` is magnification (`mag_filter` on level 0);
    /// otherwise `min_filter` within a level, on the nearest level
    /// (`mip_filter` nearest), blended between the two levels around `lod`
    /// (linear: trilinear with linear filters), or on level 0 (no mip-map).
    /// Linear RGBA.
    pub fn sample(&self, uv: Vec2, lod: f32) -> Vec4 {
        let base = &self.levels[0];
        let max = (self.levels.len() - 1) as f32;
        let lod = if lod.is_finite() {
            lod.clamp(0.0, max)
        } else {
            0.0
        };
        if lod <= 0.0 {
            return filtered(base, uv, base.mag_filter);
        }
        let min = base.min_filter;
        match base.mip_filter {
            None => filtered(base, uv, min),
            Some(Filter::Nearest) => {
                let l = (lod.round() as usize).min(self.levels.len() - 1);
                filtered(&self.levels[l], uv, min)
            }
            Some(Filter::Linear) => {
                let l0 = lod.floor() as usize;
                let f = lod - l0 as f32;
                let a = filtered(&self.levels[l0], uv, min);
                if f <= 0.0 || l0 + 1 >= self.levels.len() {
                    return a;
                }
                a.lerp(filtered(&self.levels[l0 + 1], uv, min), f)
            }
        }
    }

    /// Trilinear lookup with the level chosen from the uv derivatives.
    pub fn sample_footprint(&self, uv: Vec2, duv_dx: Vec2, duv_dy: Vec2) -> Vec4 {
        self.sample(uv, self.lod(duv_dx, duv_dy))
    }
}

// ---------------------------------------------------------------------------
// Perlin noise (Perlin 2002, "Improving noise") and turbulence (Perlin 1985).

/// The permutation of 0..256, shuffled once by a fixed linear congruential
/// generator (Fisher-Yates), doubled to avoid index wrapping.
const PERM: [u8; 512] = {
    let mut p = [0u8; 256];
    let mut i = 0;
    while i < 256 {
        p[i] = i as u8;
        i += 1;
    }
    let mut state: u64 = 0x2545_F491_4F6C_DD1D;
    let mut i = 255;
    while i > 0 {
        state = state
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        let j = ((state >> 33) % (i as u64 + 1)) as usize;
        let t = p[i];
        p[i] = p[j];
        p[j] = t;
        i -= 1;
    }
    let mut out = [0u8; 512];
    let mut k = 0;
    while k < 512 {
        out[k] = p[k & 255];
        k += 1;
    }
    out
};

#[inline]
fn fade(t: f32) -> f32 {
    t * t * t * (t * (t * 6.0 - 15.0) + 10.0)
}

#[inline]
fn grad(hash: u8, x: f32, y: f32, z: f32) -> f32 {
    // The 12 edge directions of a cube (Perlin 2002), with 4 repeated.
    let h = hash & 15;
    let u = if h < 8 { x } else { y };
    let v = if h < 4 {
        y
    } else if h == 12 || h == 14 {
        x
    } else {
        z
    };
    (if h & 1 == 0 { u } else { -u }) + (if h & 2 == 0 { v } else { -v })
}

/// Perlin's improved gradient noise at `p`: smooth, zero at integer lattice
/// points, in about `[-1, 1]`; non-finite input gives 0.
pub fn perlin_noise(p: Vec3) -> f32 {
    if !p.is_finite() {
        return 0.0;
    }
    let f = p.floor();
    let (xi, yi, zi) = (
        (f.x as i64 & 255) as usize,
        (f.y as i64 & 255) as usize,
        (f.z as i64 & 255) as usize,
    );
    let (x, y, z) = (p.x - f.x, p.y - f.y, p.z - f.z);
    let (u, v, w) = (fade(x), fade(y), fade(z));
    let a = PERM[xi] as usize + yi;
    let aa = PERM[a] as usize + zi;
    let ab = PERM[a + 1] as usize + zi;
    let b = PERM[xi + 1] as usize + yi;
    let ba = PERM[b] as usize + zi;
    let bb = PERM[b + 1] as usize + zi;
    let lerp = |t: f32, a: f32, b: f32| a + t * (b - a);
    lerp(
        w,
        lerp(
            v,
            lerp(u, grad(PERM[aa], x, y, z), grad(PERM[ba], x - 1.0, y, z)),
            lerp(
                u,
                grad(PERM[ab], x, y - 1.0, z),
                grad(PERM[bb], x - 1.0, y - 1.0, z),
            ),
        ),
        lerp(
            v,
            lerp(
                u,
                grad(PERM[aa + 1], x, y, z - 1.0),
                grad(PERM[ba + 1], x - 1.0, y, z - 1.0),
            ),
            lerp(
                u,
                grad(PERM[ab + 1], x, y - 1.0, z - 1.0),
                grad(PERM[bb + 1], x - 1.0, y - 1.0, z - 1.0),
            ),
        ),
    )
    .clamp(-1.0, 1.0)
}

/// Perlin's turbulence: `sum_i |noise(2^i p)| / 2^i` over `octaves` octaves,
/// in `[0, 2)`.
pub fn turbulence(p: Vec3, octaves: u32) -> f32 {
    let mut sum = 0.0;
    let mut scale = 1.0;
    for _ in 0..octaves {
        sum += perlin_noise(p * scale).abs() / scale;
        scale *= 2.0;
    }
    sum
}

/// The value in `[0, 1]` of a procedural pattern at the point `q` (already
/// scaled by the texture's `scale`):
/// - checker: parity of `floor(x) + floor(y) + floor(z)`;
/// - wood: rings `frac(r + 2 noise)` of the distance `r` to the y axis, sharpened;
/// - marble: `0.5 + 0.5 sin(x + 5 turbulence)` (Perlin 1985);
/// - noise: `0.5 + 0.5 noise`;
/// - dimples: a height field with a spherical dent of radius 0.4 around every
///   lattice point (1 on the flat surface, 0 at the bottom of a dent).
pub fn pattern(kind: ProceduralKind, q: Vec3) -> f32 {
    if !q.is_finite() {
        return 0.0;
    }
    match kind {
        ProceduralKind::Checker => {
            let f = q.floor();
            let s = f.x as i64 + f.y as i64 + f.z as i64;
            if s.rem_euclid(2) == 0 { 0.0 } else { 1.0 }
        }
        ProceduralKind::Wood => {
            let r = (q.x * q.x + q.z * q.z).sqrt() + 2.0 * perlin_noise(q * 0.5);
            let t = r - r.floor();
            // Early wood light, late wood a thin dark ring.
            (t * t * (3.0 - 2.0 * t)).powf(3.0)
        }
        ProceduralKind::Marble => 0.5 + 0.5 * (q.x + 5.0 * turbulence(q, 5)).sin(),
        ProceduralKind::Noise => 0.5 + 0.5 * perlin_noise(q),
        ProceduralKind::Dimples => {
            let c = q.round();
            let d = (q - c).length();
            const R: f32 = 0.4;
            if d >= R {
                1.0
            } else {
                1.0 - (R * R - d * d).sqrt() / R
            }
        }
    }
}

/// The pattern value of a procedural texture at the object-space point
/// `p_object` (or at `(u, v, 0)` when the texture uses uvs), in `[0, 1]`.
pub fn procedural_value(t: &Procedural, p_object: Vec3, uv: Vec2) -> f32 {
    let q = if t.use_uv { uv.extend(0.0) } else { p_object };
    pattern(t.kind, q * t.scale)
}

/// The colour of a procedural texture: `color_a` at pattern 0 to `color_b` at 1.
pub fn procedural_color(t: &Procedural, p_object: Vec3, uv: Vec2) -> Vec3 {
    t.color_a.lerp(t.color_b, procedural_value(t, p_object, uv))
}

/// Where a texture is looked up: the uv with its screen-space derivatives
/// (zero for "no footprint": the finest level), and the object-space point.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TexCoord {
    /// Texture coordinates.
    pub uv: Vec2,
    /// d(uv)/dx per pixel.
    pub duv_dx: Vec2,
    /// d(uv)/dy per pixel.
    pub duv_dy: Vec2,
    /// Object-space point (solid textures).
    pub p_object: Vec3,
}

/// Evaluates texture `t` at `tc` as linear RGBA: image textures (their uv
/// transform applied) through the mip-map `mip` when given, with the image's
/// filters, else its magnification filter on the base image;
/// procedural textures give their colour with alpha 1.
pub fn eval_texture(t: &Texture, mip: Option<&MipMap>, tc: &TexCoord) -> Vec4 {
    match t {
        Texture::Image(img) => {
            let tr = &img.uv_transform;
            let (uv, dx, dy) = if tr.is_identity() {
                (tc.uv, tc.duv_dx, tc.duv_dy)
            } else {
                let l = tr.linear();
                (tr.apply(tc.uv), l * tc.duv_dx, l * tc.duv_dy)
            };
            match mip {
                Some(m) => m.sample_footprint(uv, dx, dy),
                None => filtered(img, uv, img.mag_filter),
            }
        }
        Texture::Procedural(p) => procedural_color(p, tc.p_object, tc.uv).extend(1.0),
    }
}

/// Scalar height of texture `t` at `tc` in `[0, 1]`: the pattern value of a
/// procedural texture, the Rec. 709 luminance of an image.
pub fn eval_height(t: &Texture, mip: Option<&MipMap>, tc: &TexCoord) -> f32 {
    match t {
        Texture::Procedural(p) => procedural_value(p, tc.p_object, tc.uv),
        Texture::Image(_) => {
            let c = eval_texture(t, mip, tc);
            0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z
        }
    }
}

// ---------------------------------------------------------------------------
// Environment maps (Blinn and Newell 1976; lat-long after Miller and Hoffman 1984).

/// Lat-long texture coordinates of the unit direction `d`: `+y` maps to the
/// top row (`v = 0`), `-z` to the centre column (`u = 0.5`), `u` increasing
/// towards `+x` (so `+x` is at `u = 0.75`).
#[inline]
pub fn latlong_uv(d: Vec3) -> Vec2 {
    let u = 0.5 + d.x.atan2(-d.z) / std::f32::consts::TAU;
    let v = d.y.clamp(-1.0, 1.0).acos() / std::f32::consts::PI;
    Vec2::new(u, v)
}

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
fn environment_uv(env: &crate::scene::Environment, d: Vec3) -> Vec2 {
    let mut uv = latlong_uv(d);
    uv.x = (uv.x + env.rotate_y_degrees / 360.0).rem_euclid(1.0);
    uv
}

/// The unit direction whose [`environment_uv`] is `uv` (`v` from the top,
/// `theta = v pi`), and `sin(theta)`.
#[inline]
fn environment_dir(env: &crate::scene::Environment, uv: Vec2) -> (Vec3, f32) {
    let phi = (uv.x - env.rotate_y_degrees / 360.0 - 0.5) * std::f32::consts::TAU;
    let (sin_t, cos_t) = (uv.y * std::f32::consts::PI).sin_cos();
    let (sin_p, cos_p) = phi.sin_cos();
    (
        Vec3::new(sin_t * sin_p, cos_t, -sin_t * cos_p),
        sin_t.max(0.0),
    )
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
    scene: &'s Scene,
    env: &'s crate::scene::Environment,
    dist: crate::sampling::PiecewiseConstant2D,
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
        let (w, h) = if img.texels.is_empty() {
            (1, 1)
        } else {
            (img.width.max(1), img.height.max(1))
        };
        if !img.texels.is_empty() && img.texels.len() != (w as usize) * (h as usize) {
            return None;
        }
        use rayon::prelude::*;
        // Each texel's luminance (negative and non-finite channels as 0).
        let lum: Vec<f32> = if img.texels.is_empty() {
            vec![1.0]
        } else {
            img.texels
                .par_iter()
                .map(|t| {
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
    /// `None` at the poles, where the density is infinite.
    #[inline]
    pub fn sample(&self, u: Vec2) -> Option<EnvironmentSample> {
        let (uv, pdf_uv) = self.dist.sample(u);
        let (wi, sin_t) = environment_dir(self.env, uv);
        if !(sin_t > 0.0 && pdf_uv > 0.0) {
            return None;
        }
        let pdf = pdf_uv / (2.0 * std::f32::consts::PI * std::f32::consts::PI * sin_t);
        Some(EnvironmentSample {
            wi,
            radiance: environment_radiance(self.scene, wi),
            pdf,
        })
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

// ---------------------------------------------------------------------------
// Bump and normal mapping.

/// Bump mapping with a height-field gradient (Blinn 1978, in the "surface
/// gradient" form of Mikkelsen 2010, "Bump mapping unparametrized
/// surfaces"): the surface displaced by `h` along `n` has the normal
/// `normalize(n - grad_s h)`, where `grad_s h` is the gradient of `h` (scene
/// units per scene unit) projected into the tangent plane.
///
/// `grad_h` is the world-space gradient of the displacement; `n` must be unit.
#[inline]
pub fn bump_normal(n: Vec3, grad_h: Vec3) -> Vec3 {
    let gs = grad_h - grad_h.dot(n) * n;
    (n - gs).try_normalize().unwrap_or(n)
}

/// The world-space surface gradient of a function of uv with partial
/// derivatives `dh_du`, `dh_dv`, on a surface with position derivatives
/// `dpdu`, `dpdv` and unit normal `n`: `dh_du grad u + dh_dv grad v`, where
/// `grad u = (dpdv x n) / (dpdu . (dpdv x n))` and
/// `grad v = (n x dpdu) / (dpdv . (n x dpdu))`. Zero for a degenerate
/// parametrisation.
pub fn uv_surface_gradient(n: Vec3, dpdu: Vec3, dpdv: Vec3, dh_du: f32, dh_dv: f32) -> Vec3 {
    let a = dpdv.cross(n);
    let b = n.cross(dpdu);
    let da = dpdu.dot(a);
    let db = dpdv.dot(b);
    if da.abs() < 1e-20 || db.abs() < 1e-20 {
        return Vec3::ZERO;
    }
    let g = a * (dh_du / da) + b * (dh_dv / db);
    if g.is_finite() { g } else { Vec3::ZERO }
}

/// Tangent-space normal mapping (glTF 2.0 `normalTexture`): the texel `rgb`
/// in `[0, 1]` encodes `t = 2 rgb - 1`, and the perturbed normal is
/// `normalize(t.x T + t.y B + t.z N)` with `B = sign (N x T)`.
/// `tangent` is the tangent with the bitangent sign in `w`; `n` must be unit.
/// Falls back to `n` when the tangent is degenerate.
pub fn normal_map_normal(n: Vec3, tangent: Vec4, rgb: Vec3) -> Vec3 {
    let t = tangent.truncate();
    // Gram-Schmidt: the interpolated tangent need not be orthogonal to n.
    let Some(t) = (t - n * n.dot(t)).try_normalize() else {
        return n;
    };
    let sign = if tangent.w < 0.0 { -1.0 } else { 1.0 };
    let b = n.cross(t) * sign;
    let m = rgb * 2.0 - Vec3::ONE;
    (t * m.x + b * m.y + n * m.z).try_normalize().unwrap_or(n)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::UvTransform;

    #[test]
    fn wrap_modes() {
        assert_eq!(wrap_index(-1, 4, WrapMode::Repeat), 3);
        assert_eq!(wrap_index(5, 4, WrapMode::Clamp), 3);
        assert_eq!(wrap_index(4, 4, WrapMode::Mirror), 3);
        assert_eq!(wrap_index(-1, 4, WrapMode::Mirror), 0);
    }

    fn image(w: u32, h: u32, f: impl Fn(u32, u32) -> f32) -> ImageTexture {
        ImageTexture {
            source: "t".into(),
            width: w,
            height: h,
            texels: (0..w * h)
                .map(|i| {
                    let v = f(i % w, i / w);
                    [v, v, v, 1.0]
                })
                .collect(),
            wrap: WrapMode::Repeat,
            ..Default::default()
        }
    }

    #[test]
    fn per_axis_wrap_filters_and_uv_transform() {
        // A 4x4 ramp in x (value x / 4): repeat in u, clamp in v.
        let mut img = image(4, 4, |x, _| x as f32 / 4.0);
        img.wrap = WrapMode::Repeat;
        img.wrap_t = Some(WrapMode::Clamp);
        img.mag_filter = Filter::Nearest;
        // u = 1.1 wraps to texel 0; v = 5 clamps to the last row.
        assert_eq!(nearest(&img, Vec2::new(1.1, 5.0)).x, 0.0);
        // Clamped in u too: texel 3.
        img.wrap = WrapMode::Clamp;
        assert_eq!(nearest(&img, Vec2::new(1.1, 0.5)).x, 0.75);
        // Nearest picks the containing texel, linear blends the neighbours.
        assert_eq!(nearest(&img, Vec2::new(0.3, 0.5)).x, 0.25);
        assert!((bilinear(&img, Vec2::new(0.25, 0.5)).x - 0.125).abs() < 1e-6);
        // KHR_texture_transform: scale 2 then offset 0.25 maps u = 0.1 to
        // 0.45 (texel 1); a quarter turn maps (u, v) to (v, -u) (the
        // extension's matrix), so u = 0.6 at v = 0.6 reads u' = 0.6.
        let t = UvTransform {
            offset: Vec2::new(0.25, 0.0),
            rotation: 0.0,
            scale: Vec2::splat(2.0),
        };
        assert!((t.apply(Vec2::new(0.1, 0.2)) - Vec2::new(0.45, 0.4)).length() < 1e-6);
        let r = UvTransform {
            rotation: std::f32::consts::FRAC_PI_2,
            ..UvTransform::default()
        };
        assert!((r.apply(Vec2::new(0.3, 0.6)) - Vec2::new(0.6, -0.3)).length() < 1e-6);
        img.uv_transform = t;
        let tc = TexCoord {
            uv: Vec2::new(0.1, 0.5),
            ..TexCoord::default()
        };
        let v = eval_texture(&Texture::Image(img.clone()), None, &tc);
        assert_eq!(v.x, 0.25);
        // Mip filter none: minification stays on level 0 with the min filter.
        img.uv_transform = UvTransform::default();
        img.min_filter = Filter::Nearest;
        img.mip_filter = None;
        let m = MipMap::new(&img);
        assert_eq!(m.sample(Vec2::new(0.3, 0.5), 2.0).x, 0.25);
    }

    #[test]
    fn mip_pyramid_sizes_means_and_lod() {
        let img = image(8, 4, |x, y| ((x + y) % 2) as f32);
        let m = MipMap::new(&img);
        let sizes: Vec<(u32, u32)> = m.levels.iter().map(|l| (l.width, l.height)).collect();
        assert_eq!(sizes, vec![(8, 4), (4, 2), (2, 1), (1, 1)]);
        // Box filtering keeps the mean: a checker becomes uniform grey.
        assert!((m.levels[1].texel(1, 1)[0] - 0.5).abs() < 1e-6);
        // One texel per pixel is level 0; four texels per pixel is level 2.
        assert_eq!(m.lod(Vec2::new(1.0 / 8.0, 0.0), Vec2::ZERO), 0.0);
        assert!((m.lod(Vec2::new(4.0 / 8.0, 0.0), Vec2::new(0.0, 1.0 / 4.0)) - 2.0).abs() < 1e-6);
        assert_eq!(m.lod(Vec2::splat(f32::NAN), Vec2::ZERO), 0.0);
        assert!((m.sample(Vec2::splat(0.3), 3.0).x - 0.5).abs() < 1e-6);
    }

    #[test]
    fn perlin_noise_is_bounded_smooth_and_zero_on_the_lattice() {
        let mut max = 0.0f32;
        for i in 0..2000 {
            let p = Vec3::new(
                i as f32 * 0.173,
                (i % 37) as f32 * 0.311,
                (i % 11) as f32 * 0.77,
            );
            let n = perlin_noise(p);
            assert!((-1.0..=1.0).contains(&n));
            max = max.max(n.abs());
            // Continuity: a tiny step changes little.
            assert!((perlin_noise(p + Vec3::splat(1e-4)) - n).abs() < 1e-2);
        }
        assert!(max > 0.3, "noise is not flat");
        assert_eq!(perlin_noise(Vec3::new(3.0, -2.0, 7.0)), 0.0);
        assert!(turbulence(Vec3::new(0.3, 0.4, 0.5), 4) >= 0.0);
    }

    #[test]
    fn patterns_are_in_range_and_checker_alternates() {
        assert_eq!(
            pattern(ProceduralKind::Checker, Vec3::new(0.5, 0.5, 0.5)),
            0.0
        );
        assert_eq!(
            pattern(ProceduralKind::Checker, Vec3::new(1.5, 0.5, 0.5)),
            1.0
        );
        assert_eq!(
            pattern(ProceduralKind::Checker, Vec3::new(-0.5, 0.5, 0.5)),
            1.0
        );
        assert_eq!(
            pattern(ProceduralKind::Dimples, Vec3::new(0.5, 0.5, 0.5)),
            1.0
        );
        assert!(pattern(ProceduralKind::Dimples, Vec3::new(1.0, 2.0, 3.0)).abs() < 1e-6);
        for kind in [
            ProceduralKind::Wood,
            ProceduralKind::Marble,
            ProceduralKind::Noise,
            ProceduralKind::Dimples,
        ] {
            for i in 0..200 {
                let v = pattern(kind, Vec3::new(i as f32 * 0.37, 0.2, i as f32 * 0.11));
                assert!((0.0..=1.0).contains(&v), "{kind:?}: {v}");
            }
        }
    }

    #[test]
    fn bump_and_normal_map_closed_forms() {
        let n = Vec3::Z;
        // A linear height h = s x on the plane z = 0: normal (-s, 0, 1)/|..|.
        let s = 0.5;
        let g = uv_surface_gradient(n, Vec3::X, Vec3::Y, s, 0.0);
        let b = bump_normal(n, g);
        assert!((b - Vec3::new(-s, 0.0, 1.0).normalize()).length() < 1e-6);
        // The flat normal-map texel leaves the normal unchanged; (1, .5, .5)
        // tilts it onto the tangent.
        let t = Vec4::new(1.0, 0.0, 0.0, 1.0);
        assert!((normal_map_normal(n, t, Vec3::new(0.5, 0.5, 1.0)) - n).length() < 1e-6);
        assert!((normal_map_normal(n, t, Vec3::new(1.0, 0.5, 0.5)) - Vec3::X).length() < 1e-6);
        // The bitangent sign flips y.
        let up = normal_map_normal(n, t, Vec3::new(0.5, 1.0, 0.5));
        let down = normal_map_normal(n, Vec4::new(1.0, 0.0, 0.0, -1.0), Vec3::new(0.5, 1.0, 0.5));
        assert!((up + down).length() < 1e-6);
    }

    #[test]
    fn latlong_convention() {
        assert!((latlong_uv(Vec3::NEG_Z) - Vec2::new(0.5, 0.5)).length() < 1e-6);
        assert!((latlong_uv(Vec3::X) - Vec2::new(0.75, 0.5)).length() < 1e-6);
        assert!(latlong_uv(Vec3::Y).y.abs() < 1e-6);
        let mut scene = Scene::default();
        let t = scene.add_texture(Texture::Image(image(4, 2, |x, _| x as f32)));
        scene.environment = Some(crate::scene::Environment {
            texture: t,
            intensity: 2.0,
            rotate_y_degrees: 0.0,
            as_background: true,
        });
        // -z is u = 0.5: between texels 1 and 2 (values 1 and 2) -> 1.5, times 2.
        assert!((environment_radiance(&scene, Vec3::NEG_Z).x - 3.0).abs() < 1e-5);
        assert_eq!(
            background_radiance(&scene, Vec3::NEG_Z),
            environment_radiance(&scene, Vec3::NEG_Z)
        );
    }

    /// One bright texel at the map's `-z` (u = 0.5, on the horizon); after
    /// `rotate_y = a` it must be seen at `R_y(a) (-z) = (-sin a, 0, -cos a)`,
    /// the direction a right-handed rotation of the world by `a` about +y
    /// turns `-z` to (as an object's `rotate_y` does).
    #[test]
    fn rotate_y_turns_the_map_right_handed() {
        // 8 x 4 texels; texel (3, 1)'s centre is u = 3.5 / 8 = 0.4375,
        // v = 1.5 / 4 = 0.375. Make it the only bright one.
        let img = image(8, 4, |x, y| if (x, y) == (3, 1) { 100.0 } else { 0.0 });
        let mut scene = Scene::default();
        let t = scene.add_texture(Texture::Image(img));
        let texel_dir = |rot_deg: f32| {
            // The texel's direction in the unrotated map, turned by rot_deg.
            let (u, v) = (0.4375_f32, 0.375_f32);
            let phi = (u - 0.5) * std::f32::consts::TAU; // azimuth from -z towards +x
            let theta = v * std::f32::consts::PI; // from +y
            let d = Vec3::new(
                theta.sin() * phi.sin(),
                theta.cos(),
                -theta.sin() * phi.cos(),
            );
            glam::Quat::from_rotation_y(rot_deg.to_radians()) * d
        };
        for rot in [0.0_f32, 90.0, -90.0, 180.0, 30.0, 450.0] {
            scene.environment = Some(crate::scene::Environment {
                texture: t,
                intensity: 1.0,
                rotate_y_degrees: rot,
                as_background: true,
            });
            let d = texel_dir(rot);
            let seen = environment_radiance(&scene, d).x;
            assert!((seen - 100.0).abs() < 1e-2, "rotate_y {rot}: {seen} at {d}");
            // The unrotated direction sees darkness once the turn exceeds the
            // bilinear footprint (one texel, 45 degrees).
            if (45.0..=315.0).contains(&rot.rem_euclid(360.0)) {
                let off = environment_radiance(&scene, texel_dir(0.0)).x;
                assert!(off < 1e-3, "rotate_y {rot}: {off}");
            }
        }
        // Pinned by hand: rotate_y = 90 takes the map's -z to -x, so a texel
        // at the map's centre column is seen looking down -x.
        let centre = image(8, 4, |x, _| if x == 3 || x == 4 { 1.0 } else { 0.0 });
        let c = scene.add_texture(Texture::Image(centre));
        scene.environment = Some(crate::scene::Environment {
            texture: c,
            intensity: 1.0,
            rotate_y_degrees: 90.0,
            as_background: true,
        });
        assert!((environment_radiance(&scene, Vec3::NEG_X).x - 1.0).abs() < 1e-6);
        assert!(environment_radiance(&scene, Vec3::NEG_Z).x.abs() < 1e-6);
        assert!(environment_radiance(&scene, Vec3::X).x.abs() < 1e-6);
    }

    /// The mean radiance of a constant map is its value times the
    /// intensity; a map bright only above the horizon gives half of that
    /// (the upper hemisphere is half the solid angle); no map gives zero.
    #[test]
    fn environment_mean_radiance_closed_forms() {
        let mut scene = Scene::default();
        assert_eq!(environment_mean_radiance(&scene), Vec3::ZERO);
        let t = scene.add_texture(Texture::Image(image(64, 32, |_, _| 2.0)));
        scene.environment = Some(crate::scene::Environment {
            texture: t,
            intensity: 1.5,
            rotate_y_degrees: 30.0,
            as_background: false,
        });
        let m = environment_mean_radiance(&scene);
        assert!((m.x - 3.0).abs() < 1e-3, "{m}");
        let sky = image(64, 32, |_, y| if y < 16 { 1.0 } else { 0.0 });
        let t = scene.add_texture(Texture::Image(sky));
        scene.environment = Some(crate::scene::Environment {
            texture: t,
            intensity: 1.0,
            rotate_y_degrees: 0.0,
            as_background: false,
        });
        let m = environment_mean_radiance(&scene);
        assert!((m.x - 0.5).abs() < 0.02, "{m}");
    }

    /// A rotated map with a bright texel, a ramp and three black rows
    /// (the middle one has zero density: the bilinear mean over it is 0).
    fn spot_scene(rot: f32) -> Scene {
        let img = image(32, 16, |x, y| {
            if (x, y) == (20, 5) {
                500.0
            } else if (11..=13).contains(&y) {
                0.0
            } else {
                0.1 + 0.05 * x as f32
            }
        });
        let mut scene = Scene::default();
        let t = scene.add_texture(Texture::Image(img));
        scene.environment = Some(crate::scene::Environment {
            texture: t,
            intensity: 2.0,
            rotate_y_degrees: rot,
            as_background: true,
        });
        scene
    }

    /// The environment light's density per solid angle integrates to 1
    /// over the sphere (midpoint rule in theta and phi, so the Jacobian
    /// `2 pi^2 sin(theta)` is tested too), and is positive wherever the
    /// lookup's radiance is (also beside a lone bright texel, which the
    /// bilinear lookup spreads into its neighbours).
    #[test]
    fn environment_light_pdf_integrates_to_one() {
        use std::f32::consts::{PI, TAU};
        for rot in [0.0, 30.0, -100.0] {
            let scene = spot_scene(rot);
            let light = EnvironmentLight::new(&scene).expect("a light");
            let (nt, np) = (1024, 2048);
            let mut total = 0.0f64;
            for i in 0..nt {
                let theta = (i as f32 + 0.5) / nt as f32 * PI;
                let mut row = 0.0f64;
                for j in 0..np {
                    let phi = (j as f32 + 0.5) / np as f32 * TAU;
                    let d = Vec3::new(
                        theta.sin() * phi.cos(),
                        theta.cos(),
                        theta.sin() * phi.sin(),
                    );
                    row += f64::from(light.pdf(d));
                }
                total += row * f64::from(theta.sin());
            }
            total *= f64::from(PI / nt as f32) * f64::from(TAU / np as f32);
            assert!((total - 1.0).abs() < 2e-3, "rotate {rot}: {total}");
        }
        // Only one texel lit: every direction with radiance has density.
        let mut scene = Scene::default();
        let t = scene.add_texture(Texture::Image(image(16, 8, |x, y| {
            if (x, y) == (5, 2) { 1.0 } else { 0.0 }
        })));
        scene.environment = Some(crate::scene::Environment {
            texture: t,
            intensity: 1.0,
            rotate_y_degrees: 45.0,
            as_background: true,
        });
        let light = EnvironmentLight::new(&scene).expect("a light");
        let mut lit = 0;
        for i in 0..200 {
            for j in 0..400 {
                let theta = (i as f32 + 0.5) / 200.0 * PI;
                let phi = (j as f32 + 0.5) / 400.0 * TAU;
                let d = Vec3::new(
                    theta.sin() * phi.cos(),
                    theta.cos(),
                    theta.sin() * phi.sin(),
                );
                if environment_radiance(&scene, d).x > 0.0 {
                    lit += 1;
                    assert!(light.pdf(d) > 0.0, "{d}: radiance without density");
                }
            }
        }
        assert!(lit > 100, "{lit}");
        // No map, a black map, zero intensity: no light.
        assert!(EnvironmentLight::new(&Scene::default()).is_none());
        let mut black = spot_scene(0.0);
        black.environment.as_mut().expect("env").intensity = 0.0;
        assert!(EnvironmentLight::new(&black).is_none());
    }

    /// `sample` draws texels with the density's probabilities (chi-square
    /// over the texels, those expecting under 5 samples pooled), returns
    /// `pdf()`'s density and the lookup's radiance.
    #[test]
    fn environment_light_sampling_matches_its_pdf() {
        let scene = spot_scene(30.0);
        let light = EnvironmentLight::new(&scene).expect("a light");
        let env = scene.environment.as_ref().expect("env");
        let (w, h) = (32usize, 16usize);
        let n = 200_000;
        let mut counts = vec![0u32; w * h];
        let mut rng = crate::sampling::pixel_rng(5, 6, 7, 8);
        for _ in 0..n {
            let s = light
                .sample(crate::sampling::uniform2(&mut rng))
                .expect("not at a pole");
            assert!((s.wi.length() - 1.0).abs() < 1e-5);
            let pdf = light.pdf(s.wi);
            assert!((pdf - s.pdf).abs() <= 2e-3 * s.pdf, "{} vs {pdf}", s.pdf);
            assert_eq!(s.radiance, environment_radiance(&scene, s.wi));
            let uv = environment_uv(env, s.wi);
            let cell = |x: f32, n: usize| ((x * n as f32) as usize).min(n - 1);
            counts[cell(uv.y, h) * w + cell(uv.x, w)] += 1;
        }
        // Each texel's probability: its density on the unit square over w h.
        let (mut chi2, mut bins) = (0.0f64, 0usize);
        let (mut pool_e, mut pool_o) = (0.0f64, 0.0f64);
        for y in 0..h {
            for x in 0..w {
                let p = light.dist.pdf(Vec2::new(
                    (x as f32 + 0.5) / w as f32,
                    (y as f32 + 0.5) / h as f32,
                ));
                let e = f64::from(p) / (w * h) as f64 * f64::from(n);
                let o = f64::from(counts[y * w + x]);
                if e < 5.0 {
                    (pool_e, pool_o) = (pool_e + e, pool_o + o);
                } else {
                    chi2 += (o - e) * (o - e) / e;
                    bins += 1;
                }
            }
        }
        if pool_e > 0.0 {
            chi2 += (pool_o - pool_e) * (pool_o - pool_e) / pool_e.max(1.0);
            bins += 1;
        }
        // Wilson-Hilferty: chi2 / k to a standard normal.
        let k = (bins - 1) as f64;
        let z = ((chi2 / k).cbrt() - (1.0 - 2.0 / (9.0 * k))) / (2.0 / (9.0 * k)).sqrt();
        assert!(
            z < 4.5,
            "chi-square {chi2:.1} over {k} degrees of freedom: z = {z:.2}"
        );
        // The middle black row is never drawn; the bright texel (500 among
        // values up to 1.65) takes a third of the samples (its neighbours
        // share its bilinear spread).
        assert!(counts[12 * w..13 * w].iter().all(|&c| c == 0));
        assert!(
            counts[5 * w + 20] as f32 > 0.25 * n as f32,
            "{}",
            counts[5 * w + 20]
        );
    }

    /// `background = false`: the camera sees `scene.background`, every other
    /// ray the environment.
    #[test]
    fn miss_radiance_rule() {
        let mut scene = Scene {
            background: Vec3::new(0.25, 0.5, 0.75),
            ..Scene::default()
        };
        assert_eq!(miss_radiance(&scene, Vec3::Z, true), scene.background);
        assert_eq!(miss_radiance(&scene, Vec3::Z, false), scene.background);
        let t = scene.add_texture(Texture::Image(image(4, 2, |_, _| 2.0)));
        for as_background in [true, false] {
            scene.environment = Some(crate::scene::Environment {
                texture: t,
                intensity: 1.5,
                rotate_y_degrees: 0.0,
                as_background,
            });
            let camera = if as_background {
                Vec3::splat(3.0)
            } else {
                scene.background
            };
            assert_eq!(miss_radiance(&scene, Vec3::Z, true), camera);
            assert_eq!(background_radiance(&scene, Vec3::Z), camera);
            assert_eq!(miss_radiance(&scene, Vec3::Z, false), Vec3::splat(3.0));
        }
    }
}
