//! Ray tracing for chiaro: Whitted recursive ray tracing and the path-traced reference.

pub mod preview;
