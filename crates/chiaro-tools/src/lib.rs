//! chiaro-tools: what is built on the renderer rather than part of it.
//!
//! - [`compare`]: render a scene with several techniques and measure each
//!   against a reference (`chiaro compare`, Python's `chiaro.compare`);
//! - [`sheet`]: the contact sheet of a comparison, as a picture;
//! - [`gallery`]: every technique on every bundled scene, with a manifest
//!   of pixel hashes (`cargo run --release -p chiaro-tools --example
//!   gallery`);
//! - [`metrics`]: the image metrics all of them report, and the web viewer
//!   and Python too.
//!
//! The renderer's API (scene, settings, [`chiaro::render`]) is the `chiaro`
//! crate; errors are its [`chiaro::Error`].

pub mod compare;
pub mod gallery;
pub mod metrics;
pub mod sheet;
