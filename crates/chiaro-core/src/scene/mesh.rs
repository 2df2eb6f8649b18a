//! Triangle meshes, analytic shapes, and the objects that place them.

use super::{MaterialId, MeshId};
use glam::{Mat4, Quat, Vec2, Vec3, Vec4};
use serde::{Deserialize, Serialize};

/// An indexed triangle mesh in object space. Optional per-vertex arrays are
/// either empty or as long as `positions`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(default)]
pub struct Mesh {
    /// Name (file and node) for messages.
    pub name: String,
    /// Vertex positions.
    pub positions: Vec<Vec3>,
    /// Unit vertex normals, or empty to derive them (crease angle).
    pub normals: Vec<Vec3>,
    /// Texture coordinates, or empty.
    pub uvs: Vec<Vec2>,
    /// A second texture-coordinate set (glTF `TEXCOORD_1`), read by image
    /// textures whose `uv_set` is 1; empty: those read `uvs`.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub uvs1: Vec<Vec2>,
    /// Tangents `xyz` with bitangent sign in `w` (glTF convention), or empty.
    pub tangents: Vec<Vec4>,
    /// Linear RGB vertex colours multiplying the diffuse colour, or empty.
    pub colors: Vec<Vec3>,
    /// Alpha of the vertex colours (glTF `COLOR_0` as RGBA), or empty for 1.
    pub color_alphas: Vec<f32>,
    /// Triangles as vertex indices, counter-clockwise seen from the front.
    pub indices: Vec<[u32; 3]>,
    /// Per-triangle material, or empty to use the object's material.
    pub face_materials: Vec<MaterialId>,
}

/// What an object draws.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Geometry {
    /// A triangle mesh.
    Mesh(MeshId),
    /// An analytic sphere of this radius at the object origin. Ray tracers
    /// intersect it exactly; the scan converter tessellates it by its size
    /// in the image, radiosity with a fixed count
    /// ([`crate::geometry::tessellation`]).
    Sphere { radius: f32 },
}

/// An affine transform written the way scene files write it: scale, then
/// rotate (x, then y, then z, degrees), then translate; or a full matrix.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct Transform {
    /// Translation.
    pub translate: Vec3,
    /// Rotation about x, y and z in degrees, applied in that order.
    pub rotate_degrees: Vec3,
    /// Per-axis scale.
    pub scale: Vec3,
    /// An extra matrix applied after the above (glTF node transforms).
    pub matrix: Mat4,
}

impl Default for Transform {
    fn default() -> Self {
        Self {
            translate: Vec3::ZERO,
            rotate_degrees: Vec3::ZERO,
            scale: Vec3::ONE,
            matrix: Mat4::IDENTITY,
        }
    }
}

impl Transform {
    /// `world_from_object`.
    pub fn world_from_object(&self) -> Mat4 {
        let r = self.rotate_degrees;
        let q = Quat::from_rotation_z(r.z.to_radians())
            * Quat::from_rotation_y(r.y.to_radians())
            * Quat::from_rotation_x(r.x.to_radians());
        self.matrix * Mat4::from_scale_rotation_translation(self.scale, q, self.translate)
    }

    /// A transform from a matrix.
    pub fn from_matrix(matrix: Mat4) -> Self {
        Self {
            matrix,
            ..Self::default()
        }
    }
}

/// A placed piece of geometry with its material and shading options.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct Object {
    /// Name for messages.
    pub name: String,
    /// What to draw.
    pub geometry: Geometry,
    /// Material for faces without a per-face material.
    pub material: MaterialId,
    /// Object-to-world transform.
    pub transform: Transform,
    /// Interpolate vertex normals (true) or shade with face normals (false).
    pub smooth: bool,
    /// Edges whose dihedral angle exceeds this (degrees) keep separate normals.
    pub crease_angle_degrees: f32,
    /// Per-object shading mode for the scan converter, overriding the render's.
    pub shade_mode: Option<super::ShadeMode>,
    /// The object casts shadows.
    pub casts_shadows: bool,
}

impl Default for Object {
    fn default() -> Self {
        Self {
            name: String::new(),
            geometry: Geometry::Mesh(MeshId(0)),
            material: MaterialId(0),
            transform: Transform::default(),
            smooth: true,
            crease_angle_degrees: 30.0,
            shade_mode: None,
            casts_shadows: true,
        }
    }
}
