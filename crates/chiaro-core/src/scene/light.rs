//! Light sources: ambient, point, directional, Warn spot, and area lights.
//! Emissive meshes are lights too, but live in their material's `emission`.

use glam::Vec3;
use serde::{Deserialize, Serialize};

/// How a positional light's intensity falls off with distance `d`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum Attenuation {
    /// No fall-off: `f_att = 1`.
    None,
    /// Physical: `f_att = 1 / d^2`.
    #[default]
    InverseSquare,
    /// The lecture notes' empirical compromise `f_att = min(1 / (c1 + c2 d + c3 d^2), 1)`.
    Empirical { c1: f32, c2: f32, c3: f32 },
}

impl Attenuation {
    /// The attenuation factor at distance `d` (scene units).
    #[inline]
    pub fn factor(&self, d: f32) -> f32 {
        match *self {
            Attenuation::None => 1.0,
            Attenuation::InverseSquare => 1.0 / (d * d).max(1e-12),
            Attenuation::Empirical { c1, c2, c3 } => {
                let denom = c1 + c2 * d + c3 * d * d;
                if denom <= 1.0 { 1.0 } else { 1.0 / denom }
            }
        }
    }
}

/// One of Warn's flaps (shutters): a slab that confines a spotlight's light
/// to `min <= (p - position) . axis <= max`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Flap {
    /// Unit axis, world space.
    pub axis: Vec3,
    /// Lower bound along the axis, relative to the light position.
    pub min: f32,
    /// Upper bound along the axis, relative to the light position.
    pub max: f32,
}

/// A Warn (1983) spotlight: a point source whose intensity is
/// `cos^exponent(angle to the axis)`, cut off outside a cone and by flaps.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SpotLight {
    /// Position, world space.
    pub position: Vec3,
    /// Unit direction of the axis (most intense direction).
    pub direction: Vec3,
    /// RGB colour.
    pub color: Vec3,
    /// Scalar intensity Ip.
    pub intensity: f32,
    /// Distance fall-off.
    pub attenuation: Attenuation,
    /// Warn exponent n of `cos^n`.
    pub exponent: f32,
    /// Half-angle of the cone, degrees; no light outside it.
    pub cone_degrees: f32,
    /// Width (degrees) of a smooth fall-off just inside the cone edge, 0 for a hard edge.
    pub cone_softness_degrees: f32,
    /// Shutters.
    pub flaps: Vec<Flap>,
}

/// The shape of an area light. Points on it emit `radiance` towards the side
/// its normal faces (both sides if `two_sided`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum AreaShape {
    /// Parallelogram `corner + s * edge_u + t * edge_v`, `s, t in [0, 1]`;
    /// normal `edge_u x edge_v` normalised.
    Quad {
        corner: Vec3,
        edge_u: Vec3,
        edge_v: Vec3,
    },
    /// Disk with centre, unit normal and radius.
    Disk {
        center: Vec3,
        normal: Vec3,
        radius: f32,
    },
    /// Sphere emitting outwards.
    Sphere { center: Vec3, radius: f32 },
    /// Triangle `(a, b, c)`, normal `(b - a) x (c - a)` normalised. Emissive
    /// mesh triangles become lights of this shape in
    /// [`crate::prepared::PreparedScene::lights`].
    Triangle { a: Vec3, b: Vec3, c: Vec3 },
}

impl AreaShape {
    /// Surface area in square scene units.
    pub fn area(&self) -> f32 {
        match *self {
            AreaShape::Quad { edge_u, edge_v, .. } => edge_u.cross(edge_v).length(),
            AreaShape::Disk { radius, .. } => std::f32::consts::PI * radius * radius,
            AreaShape::Sphere { radius, .. } => 4.0 * std::f32::consts::PI * radius * radius,
            AreaShape::Triangle { a, b, c } => 0.5 * (b - a).cross(c - a).length(),
        }
    }

    /// A point of the shape (its centre), used for shadow-map placement.
    pub fn center(&self) -> Vec3 {
        match *self {
            AreaShape::Quad {
                corner,
                edge_u,
                edge_v,
            } => corner + 0.5 * (edge_u + edge_v),
            AreaShape::Disk { center, .. } | AreaShape::Sphere { center, .. } => center,
            AreaShape::Triangle { a, b, c } => (a + b + c) / 3.0,
        }
    }
}

/// A light source.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Light {
    /// The textbook ambient term `Ia` (local techniques only).
    Ambient { color: Vec3, intensity: f32 },
    /// A point source.
    Point {
        position: Vec3,
        color: Vec3,
        intensity: f32,
        attenuation: Attenuation,
    },
    /// A source at infinity; `direction` is the unit direction the light travels.
    Directional {
        direction: Vec3,
        color: Vec3,
        intensity: f32,
    },
    /// A Warn spotlight.
    Spot(SpotLight),
    /// An area light of constant radiance `color * intensity`.
    Area {
        shape: AreaShape,
        color: Vec3,
        intensity: f32,
        two_sided: bool,
    },
}

impl Light {
    /// `color * intensity`: Ip for point-like lights, `Ia` for ambient,
    /// emitted radiance for area lights.
    pub fn power_rgb(&self) -> Vec3 {
        match self {
            Light::Ambient { color, intensity }
            | Light::Point {
                color, intensity, ..
            }
            | Light::Directional {
                color, intensity, ..
            }
            | Light::Area {
                color, intensity, ..
            } => *color * *intensity,
            Light::Spot(s) => s.color * s.intensity,
        }
    }

    /// A short name for messages ("point", "spot", ...).
    pub fn kind(&self) -> &'static str {
        match self {
            Light::Ambient { .. } => "ambient",
            Light::Point { .. } => "point",
            Light::Directional { .. } => "directional",
            Light::Spot(_) => "spot",
            Light::Area { .. } => "area",
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn empirical_attenuation_is_clamped_to_one() {
        let a = Attenuation::Empirical {
            c1: 0.5,
            c2: 0.0,
            c3: 0.0,
        };
        assert_eq!(a.factor(1.0), 1.0);
        let a = Attenuation::Empirical {
            c1: 1.0,
            c2: 0.5,
            c3: 0.25,
        };
        assert!((a.factor(2.0) - 1.0 / 3.0).abs() < 1e-6);
    }

    #[test]
    fn inverse_square() {
        assert!((Attenuation::InverseSquare.factor(4.0) - 1.0 / 16.0).abs() < 1e-7);
    }
}
