//! Procedural solid textures: Perlin noise (Perlin 2002, "Improving noise"),
//! turbulence (Perlin 1985), and the checker, wood, marble, noise and dimple patterns.

use crate::scene::{Procedural, ProceduralKind};
use glam::{Vec2, Vec3};

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
pub(super) fn grad(hash: u8, x: f32, y: f32, z: f32) -> f32 {
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
