//! The authoring scene: plain data with typed ids, built by the importers or
//! in code, serialisable, and read (never mutated) by every technique.
//!
//! Items refer to each other by index ([`MeshId`], [`MaterialId`],
//! [`TextureId`]); `Scene::validate` checks that every id is in range and
//! every number is finite before a technique sees the scene.

mod camera;
mod light;
mod material;
mod mesh;
mod settings;
mod texture;
mod validate;

pub use camera::{Camera, NamedCamera, PixelRays, Projection};
pub use light::{AreaShape, Attenuation, Flap, Light, SpotLight};
pub use material::ComplexIor;
pub use material::{
    AlphaMode, Bump, Clearcoat, Distribution, Facing, Material, MetallicRoughness, Occlusion,
    ReflectanceModel, Sidedness, Transmission, TransparencyMode,
};
pub use mesh::{Geometry, Mesh, Object, Transform};
pub use settings::{
    AaMode, DepthCue, FormFactorMethod, LightSelection, MAX_IMAGE_PIXELS, MAX_IMAGE_SIDE,
    MAX_RASTER_SAMPLES, MAX_SAMPLES, PathSettings, PixelFilter, RadiositySettings, RadiositySolver,
    RenderSettings, SHADOW_MAP_RESOLUTIONS, ShadeMode, ShadowMapSettings, ShadowMethod, Technique,
    ToneMap, WhittedSettings,
};
pub use texture::{
    Encoding8, Environment, Filter, ImageTexture, Procedural, ProceduralKind, Texels8, Texture,
    UvTransform, WrapMode,
};
pub use validate::{Issue, Severity};

use glam::Vec3;
use serde::{Deserialize, Serialize};

macro_rules! typed_id {
    ($(#[$doc:meta])* $name:ident) => {
        $(#[$doc])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
        #[serde(transparent)]
        pub struct $name(pub u32);

        impl $name {
            /// The index into the scene's vector of this kind.
            #[inline]
            pub fn index(self) -> usize {
                self.0 as usize
            }
        }
    };
}

typed_id!(
    /// Index of a [`Mesh`] in [`Scene::meshes`].
    MeshId
);
typed_id!(
    /// Index of a [`Material`] in [`Scene::materials`].
    MaterialId
);
typed_id!(
    /// Index of a [`Texture`] in [`Scene::textures`].
    TextureId
);

/// A whole scene: what to draw, how it looks, how it is lit, from where it is
/// seen, and how it is to be rendered.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(default)]
pub struct Scene {
    /// The camera every technique renders from.
    pub camera: Camera,
    /// Further cameras the file offers by name (glTF cameras, TOML
    /// `[cameras.NAME]`); `camera` is what renders.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub cameras: Vec<NamedCamera>,
    /// Triangle meshes in object space, shared by instances.
    pub meshes: Vec<Mesh>,
    /// Materials, named; `Object::material` and `Mesh::face_materials` index it.
    pub materials: Vec<Material>,
    /// Decoded image textures and procedural textures.
    pub textures: Vec<Texture>,
    /// All light sources, including the ambient term.
    pub lights: Vec<Light>,
    /// Placed geometry.
    pub objects: Vec<Object>,
    /// Colour seen where no surface is hit and no environment map is set
    /// (linear RGB radiance).
    pub background: Vec3,
    /// An optional environment: reflection map for the local techniques,
    /// background and lighting for the path tracer.
    pub environment: Option<Environment>,
    /// How to render it (technique, size, samples, per-technique options).
    pub render: RenderSettings,
}

impl Scene {
    /// The material with this name, if any.
    pub fn material_by_name(&self, name: &str) -> Option<MaterialId> {
        self.materials
            .iter()
            .position(|m| m.name == name)
            .map(|i| MaterialId(i as u32))
    }

    /// Adds a material and returns its id.
    pub fn add_material(&mut self, material: Material) -> MaterialId {
        self.materials.push(material);
        MaterialId(self.materials.len() as u32 - 1)
    }

    /// Adds a mesh and returns its id.
    pub fn add_mesh(&mut self, mesh: Mesh) -> MeshId {
        self.meshes.push(mesh);
        MeshId(self.meshes.len() as u32 - 1)
    }

    /// Adds a texture and returns its id.
    pub fn add_texture(&mut self, texture: Texture) -> TextureId {
        self.textures.push(texture);
        TextureId(self.textures.len() as u32 - 1)
    }

    /// Total triangle count over all objects (analytic spheres count as zero).
    pub fn triangle_count(&self) -> usize {
        self.objects
            .iter()
            .map(|o| match o.geometry {
                Geometry::Mesh(id) => self.meshes.get(id.index()).map_or(0, |m| m.indices.len()),
                Geometry::Sphere { .. } => 0,
            })
            .sum()
    }
}
