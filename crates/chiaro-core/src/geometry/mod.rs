//! Geometry: rays, bounds, orthonormal frames, normals and tangents,
//! built-in primitives, the Utah teapot, and how finely analytic
//! primitives are tessellated.

mod bounds;
mod frame;
pub mod normals;
pub mod primitives;
mod ray;
pub mod teapot;
pub mod tessellation;

pub use bounds::Aabb;
pub use frame::Frame;
pub use normals::{face_normal, vertex_normals};
pub use ray::{Ray, offset_ray_origin};
