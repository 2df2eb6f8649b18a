//! chiaro-core: the plain data and the math that every chiaro technique shares.
//!
//! Nothing here renders a picture or reads a file. The crate holds the
//! authoring [`scene::Scene`], the [`prepared::PreparedScene`] built from it
//! once per render, geometry, acceleration structures, the one local
//! illumination function ([`shading`]), sampling warps, and the [`film::Film`]
//! that renderers write into.
//!
//! # Glossary
//! - **world space**: the scene's space, in scene units; `world_from_object`
//!   matrices take an object's mesh into it.
//! - **wo / wi**: unit directions that always point *away* from the surface,
//!   towards the viewer (`wo`) and towards the light (`wi`).
//! - **radiance**: linear RGB `f32`, W/(sr m^2) per channel in the scene's
//!   relative units. sRGB appears only at the 8-bit boundary (chiaro-io).
//! - **Ip**: a point light's intensity times its colour; it gives irradiance
//!   `pi * Ip * cos(theta) / d^2` (the radiometric convention, ARCHITECTURE.md).
//! - **ka, kd, ks, n, kr, kt**: the classic material coefficients (ambient,
//!   diffuse albedo, specular, Phong exponent, mirror reflection, transmission).
//! - **technique**: one complete way of making a picture (flat, gouraud,
//!   phong, whitted, radiosity, hybrid, path, preview).

pub mod accel;
pub mod budget;
pub mod context;
pub mod error;
pub mod film;
pub mod framing;
pub mod geometry;
pub mod prepared;
pub mod progress;
#[cfg(test)]
mod proptests;
pub mod sampling;
pub mod scene;
pub mod shading;
pub mod shadow;
pub mod technique;

pub use glam;

/// The square `z` = const with x, y in [-1, 1], as two triangles (a test
/// fixture: the panes and masked quads of the shadow and alpha tests).
#[cfg(test)]
pub(crate) fn test_square(z: f32) -> scene::Mesh {
    scene::Mesh {
        positions: vec![
            glam::Vec3::new(-1.0, -1.0, z),
            glam::Vec3::new(1.0, -1.0, z),
            glam::Vec3::new(1.0, 1.0, z),
            glam::Vec3::new(-1.0, 1.0, z),
        ],
        indices: vec![[0, 1, 2], [0, 2, 3]],
        ..scene::Mesh::default()
    }
}
pub use glam::{Mat3, Mat4, Vec2, Vec3, Vec3A, Vec4};
