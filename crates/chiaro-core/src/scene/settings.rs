//! Render settings: which technique, the image size, and the options of each
//! technique. Every struct has defaults and round-trips through serde, so a
//! render can be reproduced from its saved settings, and `--set key=value`
//! can address any field by its dotted path (`shadow_map.resolution`).

use super::TransparencyMode;
use glam::Vec3;
use serde::{Deserialize, Serialize};

/// Largest accepted image width or height.
pub const MAX_IMAGE_SIDE: u32 = 16_384;
/// Largest accepted pixel count (width * height): 64 Mpixel, about 1.8 GB of film.
pub const MAX_IMAGE_PIXELS: u64 = 8192 * 8192;
/// Largest accepted samples per pixel.
pub const MAX_SAMPLES: u32 = 1 << 16;
/// Most samples per pixel the scan converter takes (more are rendered as
/// this many, with a warning from [`RenderSettings::validate`]).
pub const MAX_RASTER_SAMPLES: u32 = 64;
/// Accepted shadow-map resolutions (texels per side of a map or cube face).
pub const SHADOW_MAP_RESOLUTIONS: std::ops::RangeInclusive<u32> = 16..=8192;

/// A complete way of making a picture.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum Technique {
    /// Ray-cast eye-light preview: no shadows, camera-headlight shading.
    Preview,
    /// Scan conversion, one illumination per polygon.
    Flat,
    /// Scan conversion, illumination at vertices, colours interpolated.
    Gouraud,
    /// Scan conversion, normals interpolated, illumination per pixel.
    #[default]
    Phong,
    /// Whitted recursive ray tracing.
    Whitted,
    /// Radiosity solved on patches, displayed by Gouraud scan conversion.
    Radiosity,
    /// Radiosity for diffuse interreflection plus Whitted ray tracing.
    Hybrid,
    /// The unbiased path-traced reference.
    Path,
}

impl Technique {
    /// Every technique, in the order they are listed to users.
    pub const ALL: [Technique; 8] = [
        Technique::Preview,
        Technique::Flat,
        Technique::Gouraud,
        Technique::Phong,
        Technique::Whitted,
        Technique::Radiosity,
        Technique::Hybrid,
        Technique::Path,
    ];

    /// The name used on the command line and in scene files.
    pub fn name(self) -> &'static str {
        match self {
            Technique::Preview => "preview",
            Technique::Flat => "flat",
            Technique::Gouraud => "gouraud",
            Technique::Phong => "phong",
            Technique::Whitted => "whitted",
            Technique::Radiosity => "radiosity",
            Technique::Hybrid => "hybrid",
            Technique::Path => "path",
        }
    }

    /// The scan converter's shading mode, for flat, Gouraud and Phong.
    pub fn shade_mode(self) -> Option<ShadeMode> {
        match self {
            Technique::Flat => Some(ShadeMode::Flat),
            Technique::Gouraud => Some(ShadeMode::Gouraud),
            Technique::Phong => Some(ShadeMode::Phong),
            _ => None,
        }
    }

    /// Whether the technique is scan conversion (flat, Gouraud, Phong).
    pub fn is_scan_conversion(self) -> bool {
        self.shade_mode().is_some()
    }

    /// Whether the technique solves radiosity (radiosity, hybrid).
    pub fn solves_radiosity(self) -> bool {
        matches!(self, Technique::Radiosity | Technique::Hybrid)
    }

    /// Parses a technique name, ignoring case and surrounding spaces.
    pub fn from_name(name: &str) -> Option<Self> {
        let name = name.trim();
        Self::ALL
            .into_iter()
            .find(|t| t.name().eq_ignore_ascii_case(name))
    }
}

/// How the scan converter shades a polygon.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ShadeMode {
    /// Constant shading with the face normal.
    Flat,
    /// Illumination at vertices, interpolated colours.
    Gouraud,
    /// Interpolated normals, illumination per pixel.
    Phong,
}

/// How the visibility of a light sample is decided.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum ShadowMethod {
    /// Every light sample is visible.
    None,
    /// Shadow z-buffers (two-pass z-buffer).
    Map,
    /// Crow's shadow volumes with a stencil count.
    Volume,
    /// Shadow rays (ray tracers; the scan converter may use them too).
    #[default]
    Ray,
    /// Atherton-Weiler-Greenberg object-precision shadows.
    Object,
    /// Bouknight-Kelley scan-line shadows.
    Scanline,
}

/// How a technique chooses among many lights (the path tracer's light per
/// next-event estimate, an emissive mesh's triangles in the local model).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum LightSelection {
    /// The hierarchy where there are more than
    /// `shading::light_tree::AUTO_TREE_LIGHTS` lights to choose from, else
    /// power.
    #[default]
    Auto,
    /// In proportion to each light's power.
    Power,
    /// By the light hierarchy: power, distance and orientation as seen from
    /// the shading point (Conty Estevez and Kulla 2018).
    Tree,
}

impl LightSelection {
    /// True for the default, [`LightSelection::Auto`].
    pub fn is_auto(&self) -> bool {
        *self == Self::Auto
    }
}

/// Anti-aliasing strategy.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum AaMode {
    /// `samples` stratified samples per pixel, box-filtered.
    #[default]
    Supersample,
    /// Whitted's adaptive supersampling (ray tracers).
    Adaptive,
    /// One sample per pixel, then an edge-aware post filter.
    Post,
}

/// Reconstruction filter that resolves the supersamples of a pixel: the
/// weighted mean of the radiance over the film around the pixel centre
/// (`crate::film::reconstruction`). Scan conversion weights its samples;
/// the path tracer draws its film positions from the filter; the other
/// techniques box-filter.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum PixelFilter {
    /// The mean of the pixel's own samples.
    #[default]
    Box,
    /// A tent (triangle) of radius one pixel: every sample within one pixel
    /// of the pixel centre, in this pixel or a neighbour, weighted by
    /// `max(0, 1 - |dx|) * max(0, 1 - |dy|)` and normalised by the weight sum.
    Tent,
    /// Mitsuba's default `gaussian`: standard deviation 0.5 pixel, cut off
    /// at 2 pixels, `max(0, exp(-x²/2σ²) - exp(-8))` per axis (the
    /// path tracer; scan conversion resolves it as the tent).
    Gaussian,
}

/// Tone mapping applied when writing low-dynamic-range images.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum ToneMap {
    /// Clamp to `[0, 1]`.
    #[default]
    Clamp,
    /// Reinhard `x / (1 + x)`.
    Reinhard,
    /// A filmic curve (ACES fit by Narkowicz 2015).
    Filmic,
}

/// Depth cueing: blend towards `color` with distance from the eye.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DepthCue {
    /// The cue colour reached at `far`.
    pub color: Vec3,
    /// Distance where cueing starts (scale `max_scale`).
    pub near: f32,
    /// Distance where cueing ends (scale `min_scale`).
    pub far: f32,
    /// Fraction of the shaded colour kept at `near`.
    pub max_scale: f32,
    /// Fraction of the shaded colour kept at `far`.
    pub min_scale: f32,
}

impl Default for DepthCue {
    fn default() -> Self {
        Self {
            color: Vec3::ZERO,
            near: 0.0,
            far: 100.0,
            max_scale: 1.0,
            min_scale: 0.0,
        }
    }
}

/// Options of shadow z-buffers.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ShadowMapSettings {
    /// Side of each shadow map (or cube face) in texels.
    pub resolution: u32,
    /// Constant depth bias, in shadow-map texels.
    pub bias: f32,
    /// Slope-scaled bias factor.
    pub slope_bias: f32,
    /// Percentage-closer filter radius in texels (0 = a single test).
    pub pcf_radius: u32,
}

impl Default for ShadowMapSettings {
    fn default() -> Self {
        Self {
            resolution: 2048,
            bias: 1.0,
            slope_bias: 2.0,
            pcf_radius: 1,
        }
    }
}

/// Options of the Whitted ray tracer.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct WhittedSettings {
    /// Maximum recursion depth (0 = local shading at the first hit only).
    pub max_depth: u32,
    /// Rays whose accumulated weight falls below this are not traced.
    pub min_weight: f32,
    /// Adaptive supersampling: subdivide where corner colours differ by more.
    pub adaptive_threshold: f32,
    /// Adaptive supersampling: maximum subdivision depth.
    pub adaptive_max_depth: u32,
}

impl Default for WhittedSettings {
    fn default() -> Self {
        Self {
            max_depth: 6,
            min_weight: 1e-3,
            adaptive_threshold: 0.05,
            adaptive_max_depth: 3,
        }
    }
}

/// Options of the path tracer.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PathSettings {
    /// Maximum path length in bounces (1 = direct light only).
    pub max_depth: u32,
    /// Russian roulette starts at this depth.
    pub rr_depth: u32,
}

impl Default for PathSettings {
    fn default() -> Self {
        Self {
            max_depth: 8,
            rr_depth: 3,
        }
    }
}

/// The radiosity solvers.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum RadiositySolver {
    /// Full matrix, Jacobi iteration.
    Jacobi,
    /// Full matrix, Gauss-Seidel iteration.
    GaussSeidel,
    /// Progressive refinement (shooting).
    Progressive,
    /// Hierarchical radiosity; above 2048 source triangles its links start
    /// from a cluster hierarchy over the input instead of from every pair
    /// of triangles (docs/decisions/0050-radiosity-clusters.md).
    Hierarchical,
    /// The default: progressive refinement up to
    /// [`RadiositySolver::CLUSTER_ABOVE`] triangles (and with hemicube form
    /// factors), the clustered hierarchical solver above, whose cost grows
    /// with the scene's light rather than its triangle count.
    #[default]
    Auto,
}

impl RadiositySolver {
    /// Every solver.
    pub const ALL: [Self; 5] = [
        Self::Jacobi,
        Self::GaussSeidel,
        Self::Progressive,
        Self::Hierarchical,
        Self::Auto,
    ];

    /// Above this many source triangles the hierarchical solver links
    /// clusters instead of every pair of triangles, and `auto` picks it.
    pub const CLUSTER_ABOVE: usize = 2048;

    /// The solver that runs: `auto` resolved for a scene of `triangles`
    /// source triangles with form factors by `formfactor` (the hierarchical
    /// solver needs area-to-area ones); any other solver is itself.
    pub fn resolve(self, triangles: usize, formfactor: FormFactorMethod) -> Self {
        match self {
            Self::Auto
                if triangles > Self::CLUSTER_ABOVE && formfactor != FormFactorMethod::Hemicube =>
            {
                Self::Hierarchical
            }
            Self::Auto => Self::Progressive,
            s => s,
        }
    }

    /// Parses a solver name.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|s| s.name() == name)
    }

    /// The name, as written in scene files and `--set`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Jacobi => "jacobi",
            Self::GaussSeidel => "gauss-seidel",
            Self::Progressive => "progressive",
            Self::Hierarchical => "hierarchical",
            Self::Auto => "auto",
        }
    }

    /// Whether the solver stores the full form-factor matrix.
    pub fn is_matrix(self) -> bool {
        matches!(self, Self::Jacobi | Self::GaussSeidel)
    }
}

/// The radiosity form-factor methods.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum FormFactorMethod {
    /// Hemicube on the scan converter's item buffer.
    Hemicube,
    /// Exact point-to-polygon factors with ray-cast visibility.
    #[default]
    Raycast,
    /// Exact point-to-polygon factors, no visibility (unoccluded scenes).
    Analytic,
}

impl FormFactorMethod {
    /// Every method.
    pub const ALL: [Self; 3] = [Self::Hemicube, Self::Raycast, Self::Analytic];

    /// Parses a method name.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|m| m.name() == name)
    }

    /// The name, as written in scene files and `--set`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Hemicube => "hemicube",
            Self::Raycast => "raycast",
            Self::Analytic => "analytic",
        }
    }
}

/// Options of the radiosity solver.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RadiositySettings {
    /// The solver.
    pub solver: RadiositySolver,
    /// The form-factor method.
    pub formfactor: FormFactorMethod,
    /// Largest patch edge, scene units (0 = choose from the scene size).
    pub patch_size: f32,
    /// Hemicube resolution (pixels on the top face's side).
    pub hemicube_resolution: u32,
    /// Stop when the unshot energy (or residual) falls below this fraction.
    pub tolerance: f32,
    /// Iteration cap.
    pub max_iterations: u32,
}

impl Default for RadiositySettings {
    fn default() -> Self {
        Self {
            solver: RadiositySolver::Auto,
            formfactor: FormFactorMethod::Raycast,
            patch_size: 0.0,
            hemicube_resolution: 128,
            tolerance: 0.01,
            max_iterations: 100_000,
        }
    }
}

/// Everything that decides how a scene is rendered.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RenderSettings {
    /// The technique.
    pub technique: Technique,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Samples per pixel (supersampling or path samples).
    pub samples: u32,
    /// Seed of every random number (per pixel and sample).
    pub seed: u64,
    /// Light visibility for the local techniques and the ray tracers.
    pub shadows: ShadowMethod,
    /// Overrides every material's transparency mode when set.
    pub transparency: Option<TransparencyMode>,
    /// Anti-aliasing strategy.
    pub aa: AaMode,
    /// Reconstruction filter of the supersamples (box by default).
    pub filter: PixelFilter,
    /// Samples per area light per shading point.
    pub light_samples: u32,
    /// How lights are chosen among many (written only when not `auto`, so
    /// saved settings from before it read the same).
    #[serde(skip_serializing_if = "LightSelection::is_auto")]
    pub light_selection: LightSelection,
    /// Depth cueing, off when absent.
    pub depth_cue: Option<DepthCue>,
    /// Tone mapping for 8-bit output.
    pub tonemap: ToneMap,
    /// Exposure in stops applied before tone mapping.
    pub exposure: f32,
    /// Lets the scan converter cull the backs no camera ray reaches (of
    /// closed, outward-wound, opaque meshes the eye is outside of): a speed
    /// option that never changes a picture (ARCHITECTURE.md, "Sidedness").
    pub cull_backfaces: bool,
    /// Shadow map options.
    pub shadow_map: ShadowMapSettings,
    /// Whitted options.
    pub whitted: WhittedSettings,
    /// Path tracer options.
    pub path: PathSettings,
    /// Radiosity options.
    pub radiosity: RadiositySettings,
    /// Render only the pixels `x0 <= x < x1`, `y0 <= y < y1` (`[x0, y0, x1, y1]`);
    /// the others stay black with infinite depth. Every pixel inside has
    /// exactly the value it has in a full render (distributed rendering
    /// relies on it).
    pub crop: Option<[u32; 4]>,
    /// The memory this render may use (`"8G"`, or bytes), a ceiling below
    /// the process budget ([`crate::budget::MemoryBudget::process`]: the
    /// CLI's `--memory-limit`, else a share of the process's memory limit).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub memory_limit: Option<crate::budget::ByteSize>,
}

impl Default for RenderSettings {
    fn default() -> Self {
        Self {
            technique: Technique::Phong,
            width: 640,
            height: 480,
            samples: 1,
            seed: 0,
            shadows: ShadowMethod::Ray,
            transparency: None,
            aa: AaMode::Supersample,
            filter: PixelFilter::Box,
            light_samples: 16,
            light_selection: LightSelection::Auto,
            depth_cue: None,
            tonemap: ToneMap::Clamp,
            exposure: 0.0,
            cull_backfaces: true,
            shadow_map: ShadowMapSettings::default(),
            whitted: WhittedSettings::default(),
            path: PathSettings::default(),
            radiosity: RadiositySettings::default(),
            crop: None,
            memory_limit: None,
        }
    }
}

impl RenderSettings {
    /// The crop window clamped to the image, or the whole image.
    pub fn crop_rect(&self) -> [u32; 4] {
        match self.crop {
            Some([x0, y0, x1, y1]) => {
                let x1 = x1.min(self.width);
                let y1 = y1.min(self.height);
                [x0.min(x1), y0.min(y1), x1, y1]
            }
            None => [0, 0, self.width, self.height],
        }
    }

    /// The memory budget of this render: the smaller of `memory_limit` and
    /// the process budget (both are ceilings).
    pub fn memory_budget(&self) -> crate::budget::MemoryBudget {
        let process = crate::budget::MemoryBudget::process();
        match self.memory_limit {
            Some(b) if b < process.limit => crate::budget::MemoryBudget::new(b.0),
            _ => process,
        }
    }

    /// Width over height.
    pub fn aspect(&self) -> f32 {
        self.width as f32 / self.height.max(1) as f32
    }
}
