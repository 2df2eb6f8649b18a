//! Ray tracing for chiaro: Whitted recursive ray tracing and the path-traced reference.
//!
//! - [`whitted`]: Whitted (1980) recursive ray tracing with shadow rays,
//!   soft shadows from area lights, refraction, and stratified or adaptive
//!   supersampling; its [`whitted::Tracer`] is reused by the hybrid technique.
//! - [`preview`]: the eye-light preview.

pub mod path;
pub mod preview;
pub mod whitted;
