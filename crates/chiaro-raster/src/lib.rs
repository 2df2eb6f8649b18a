//! Scan conversion for chiaro: a tiled, multi-threaded z-buffer polygon
//! rasterizer with flat, Gouraud and Phong shading, texture, bump and
//! environment maps, and supersampled anti-aliasing.
//!
//! # Where each method lives
//! - [`technique`]: [`ScanConversion`], the technique interface's renderer
//!   for flat, Gouraud and Phong.
//! - [`pipeline`]: the driver of the five steps, each in its file:
//!   [`pipeline::vertex`] (clip space, snapping, eye rays),
//!   [`pipeline::binning`] (setup and tiles), [`pipeline::visibility`]
//!   (Catmull's z-buffer into an item buffer),
//!   [`pipeline::shading`] (what every shading method shares per sample) and
//!   [`pipeline::resolve`] (the tent filter into the film).
//! - The shading methods, one file each: [`flat`] (one illumination per
//!   polygon), [`gouraud`] (vertex lighting, its cache, interpolation) and
//!   [`phong`] (the normal interpolated, lit per sample).
//! - Transparency: [`screen_door`] (the ordered-dither mask in the z-buffer)
//!   and [`abuffer`] (Carpenter's A-buffer, the sorted transparent fragments).
//! - [`shadows`]: the shadow methods: [`shadows::rays`] (shadow rays),
//!   [`shadows::maps`] (Williams' shadow z-buffers), [`shadows::volumes`]
//!   (Crow's shadow volumes), [`shadows::object_precision`]
//!   (Atherton-Weiler-Greenberg) and [`shadows::scanline`]
//!   (Bouknight-Kelley).
//! - [`raster`], [`clip`], [`zbuffer`], [`filter`]: edge functions and
//!   triangle setup, clipping, the plain z-buffer and the pixel filters.
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

pub mod abuffer;
pub mod clip;
pub mod filter;
pub mod flat;
pub mod gouraud;
pub mod phong;
pub mod pipeline;
pub mod raster;
pub mod screen_door;
pub mod shadows;
pub mod technique;
pub mod zbuffer;

pub use pipeline::{RasterOptions, RasterWork, dither_threshold};
pub use shadows::volumes::VolumeCounting;
pub use technique::ScanConversion;

use pipeline::render_work;
