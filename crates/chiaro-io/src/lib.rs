//! chiaro-io: everything that touches files.
//!
//! - [`scene_toml`]: the `.toml` scene format (DESIGN.md section 2), with
//!   `file:line:col` errors and unknown keys rejected.
//! - [`obj`]: Wavefront OBJ + MTL through tobj.
//! - [`gltf_import`]: glTF 2.0 (`.gltf`, `.glb`, embedded) through the gltf crate.
//! - [`images`]: decoding image textures (PNG, JPEG, HDR, EXR) to linear texels.
//! - [`output`]: writing films (PNG 8/16-bit, OpenEXR with depth and normal,
//!   Radiance HDR, PPM, palette PNG), always through a temporary file and a rename.

pub mod error;
pub mod gltf_import;
pub mod images;
pub mod obj;
pub mod output;
pub mod scene_toml;

pub use error::{IoError, Result};
