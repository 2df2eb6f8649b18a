//! What a technique is, in words: each renderer describes the techniques
//! it draws ([`Description`], returned by
//! [`crate::context::Renderer::descriptions`]), beside its code. The
//! facade's limitations, `chiaro info` and the README's technique tables
//! are generated from these descriptions.

use crate::scene::Technique;

/// Something a scene can have that some technique does not draw.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Feature {
    /// The scene's lights, shadows included (preview lights with an eye light).
    Lights,
    /// Ambient lights (`Ia ka kd`).
    AmbientLight,
    /// Light from the environment map falling on surfaces.
    EnvironmentLight,
    /// Mirror reflection of the scene (`reflect > 0`, or a Fresnel dielectric).
    Mirrors,
    /// Refraction: light bent through a transmitting surface with `ior != 1`.
    Refraction,
    /// Surfaces that let light through (`transmit > 0`, glTF `BLEND`).
    Transparency,
    /// Specular highlights (`specular > 0`).
    Highlights,
    /// Normal and bump maps.
    NormalMaps,
    /// Highlights and shadows that fall inside one large polygon.
    InsideLargePolygons,
    /// Light that mirrors and glass send onto other surfaces (caustics).
    SpecularIndirect,
    /// Depth cueing (`render.depth_cue`).
    DepthCue,
    /// Shadows with `shadows = "volume"` (the volumes exist per sample).
    VolumeShadows,
    /// Alpha-masked surfaces (glTF `alphaMode: MASK`): cut-out texels.
    AlphaMask,
    /// Alpha-masked shadow casters under `shadows` = volume, object or
    /// scanline (polygon shadows that do not cut texels).
    AlphaMaskShadows,
    /// Rough glass: a Fresnel dielectric whose Torrance-Sparrow roughness
    /// blurs what it reflects and transmits (`shading::dielectric`).
    RoughTransmission,
    /// A clear coat (glTF `KHR_materials_clearcoat`): its reflection of
    /// other objects.
    ClearCoat,
}

/// What the techniques that reflect only the environment in a clear coat
/// show of it.
pub const COAT_REFLECTS_ENVIRONMENT: &str = "reflections of other objects in a clear coat: the coat reflects the environment map and the lights' highlights only";

/// What the Whitted-style tracers show of rough glass.
pub const ROUGH_AS_SMOOTH: &str = "the blur of rough glass: it reflects and refracts along the smooth (mirror and Snell) directions";

/// One technique described by the renderer that draws it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Description {
    /// The technique.
    pub technique: Technique,
    /// Its name in prose ("Gouraud"; the command line's is
    /// [`Technique::name`]).
    pub title: &'static str,
    /// What the method is, in a line (the README's "what it is").
    pub method: &'static str,
    /// What its pictures show.
    pub shows: &'static str,
    /// What it cannot show: each feature a scene may have, with what the
    /// picture shows instead. Each entry is what the renderer's code does.
    pub cannot_show: &'static [(Feature, &'static str)],
}

/// What the local techniques cannot show of the environment's light: one
/// implementation (`shading::texture`'s prefiltered lookups) lights every
/// technique but path, with no visibility.
pub const ENVIRONMENT_UNOCCLUDED: &str = "occlusion of the environment map's light: the map lights every surface (diffuse from its irradiance, glossy from its prefiltered levels) as if nothing stood in its way, and glossy surfaces reflect the map, not the objects beside them";
