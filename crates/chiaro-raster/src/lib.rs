//! Scan conversion for chiaro: a tiled, multi-threaded z-buffer polygon
//! rasterizer with flat, Gouraud and Phong shading, texture, bump and
//! environment maps, and supersampled anti-aliasing.
//!
//! # Glossary
//! - **clip space**: homogeneous coordinates after `clip_from_world`; the near
//!   plane is `z >= 0` (Direct3D/Vulkan convention), `w` is the view depth.
//! - **screen space**: pixels, `x` right, `y` down, pixel centres at `+0.5`.
//! - **edge function**: `E(p) = (b - a) x (p - a)`, positive inside a
//!   triangle; evaluated exactly on snapped fixed-point vertices.
//! - **top-left rule**: a sample exactly on an edge belongs to the triangle
//!   only if that edge is a top or left edge, so shared edges are drawn once.
//! - **item buffer**: per-pixel id of the nearest triangle (a visibility
//!   buffer); the renderer shades only these visible samples (deferred).
//! - **tile / bin**: a square of the screen rendered by one thread, and the
//!   list of triangles overlapping it.

pub mod clip;
pub mod filter;
pub mod object_shadows;
pub mod raster;
pub mod render;
pub mod scanline_shadows;
pub mod shadow;
pub mod zbuffer;

pub use render::{
    RasterOptions, RasterWork, dither_threshold, render, render_counted, render_prepared,
    render_prepared_into, render_prepared_with, shade_mode_of,
};
pub use shadow::VolumeCounting;
