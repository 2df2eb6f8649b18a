//! Command-line arguments (clap derive).

use clap::{Args, Parser, Subcommand, ValueEnum};
use std::path::PathBuf;

/// chiaro — one scene, every classic illumination and shading technique.
#[derive(Debug, Parser)]
#[command(name = "chiaro", version, about, long_about = None, after_help = EXAMPLES)]
pub struct Cli {
    /// What to do.
    #[command(subcommand)]
    pub command: Command,
    /// The memory a job may use (e.g. 512M, 8G; default: half the process's
    /// limit, the smallest of RAM, cgroup limit and RLIMIT_AS; see info --system).
    /// A scene whose estimate exceeds it is refused before allocating.
    #[arg(long, global = true, value_name = "SIZE")]
    pub memory_limit: Option<chiaro::budget::ByteSize>,
}

const EXAMPLES: &str = "Examples:
  chiaro render scenes/cornell-box.toml -o cornell.png
  chiaro render scenes/teapot.toml --technique gouraud --width 320 --height 240 -o teapot.png
  chiaro render scenes/whitted.toml --set whitted.max_depth=3 --samples 4 -o whitted.exr
  chiaro info scenes/cornell-box.toml
  chiaro info --system
  chiaro render scene.xml -D spp=64 -o mitsuba.exr
  chiaro render scenes/cornell-box.pbrt --technique path -o pbrt.png
  chiaro export scenes/cornell-box.toml --to mitsuba -o cbox.xml
  chiaro compare scenes/cornell-box.toml --techniques phong,whitted --reference path:64 -o sheet.png --report report.json";

/// The subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Render a scene (.toml, .xml (Mitsuba 3), .pbrt (pbrt-v4/v3), .obj, .ply, .gltf, .glb) to an image (.png, .exr, .hdr, .ppm).
    Render(RenderArgs),
    /// Serve a web viewer for SCENE: techniques side by side, orbit camera,
    /// difference images (loopback only unless --host is given).
    Serve {
        /// The scene file.
        scene: PathBuf,
        /// TCP port (0 picks a free one).
        #[arg(long, default_value_t = 8080)]
        port: u16,
        /// IP address to listen on; 0.0.0.0 exposes the viewer to the network.
        #[arg(long, default_value = "127.0.0.1")]
        host: String,
        /// The starting camera.
        #[command(flatten)]
        camera: CameraFlags,
    },
    /// Describe a scene: objects, triangles, lights, materials, textures, bounds, warnings.
    Info {
        /// The scene file.
        #[arg(required_unless_present = "system")]
        scene: Option<PathBuf>,
        /// Show the machine's memory limits and the budget they give (alone,
        /// or before the scene's description).
        #[arg(long)]
        system: bool,
        /// A Mitsuba scene parameter: `-D spp=64` gives `$spp` this value
        /// over the file's `<default>`.
        #[arg(short = 'D', value_name = "NAME=VALUE")]
        define: Vec<String>,
    },
    /// Render a scene with several techniques and measure each against a
    /// reference: writes a contact sheet, prints a Markdown table.
    Compare(CompareArgs),
    /// Write a scene for another renderer (Mitsuba 3 XML, meshes as PLY
    /// files beside it; or pbrt-v4): what maps exactly, refusing the rest.
    Export {
        /// The scene file.
        scene: PathBuf,
        /// `mitsuba` or `pbrt` (default: from the output's extension,
        /// .xml or .pbrt).
        #[arg(long)]
        to: Option<String>,
        /// The scene file to write.
        #[arg(short, long)]
        output: PathBuf,
        /// A Mitsuba scene parameter of the input (`-D spp=64`).
        #[arg(short = 'D', value_name = "NAME=VALUE")]
        define: Vec<String>,
    },
}

/// Palette output modes (8-bit indexed PNG).
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum PaletteArg {
    /// The magazine series' 256-entry palette of 64-level colour bands (make_range).
    Vga,
    /// Heckbert's median-cut palette with Floyd-Steinberg dithering.
    MedianCut,
}

/// Tone-mapping operators.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ToneMapArg {
    /// Clamp to [0, 1].
    Clamp,
    /// Reinhard x / (1 + x).
    Reinhard,
    /// ACES filmic fit.
    Filmic,
}

/// Options shared by every command that renders.
#[derive(Debug, Args, Clone)]
pub struct RenderOptions {
    /// The technique, by name (the list comes from `chiaro::technique_list`).
    #[arg(short, long, help = technique_help())]
    pub technique: Option<String>,
    /// Image width in pixels.
    #[arg(long, allow_negative_numbers = true)]
    pub width: Option<u32>,
    /// Image height in pixels.
    #[arg(long, allow_negative_numbers = true)]
    pub height: Option<u32>,
    /// Samples per pixel.
    #[arg(long, allow_negative_numbers = true)]
    pub samples: Option<u32>,
    /// Random seed.
    #[arg(long, allow_negative_numbers = true)]
    pub seed: Option<u64>,
    /// Worker threads (default: all cores).
    #[arg(long, allow_negative_numbers = true)]
    pub threads: Option<usize>,
    /// Override any render setting, e.g. `--set shadows=map --set whitted.max_depth=3`.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub set: Vec<String>,
    /// A Mitsuba scene parameter: `-D spp=64` gives `$spp` this value over
    /// the file's `<default>`.
    #[arg(short = 'D', value_name = "NAME=VALUE")]
    pub define: Vec<String>,
    /// The camera.
    #[command(flatten)]
    pub camera: CameraFlags,
}

/// Camera flags shared by render, compare and serve (rules in `chiaro::camera`).
#[derive(Debug, Args, Clone, Default)]
pub struct CameraFlags {
    /// One of the scene's cameras by name (a glTF camera or a TOML
    /// `[cameras.NAME]`), or by index.
    #[arg(long = "camera", value_name = "NAME")]
    pub name: Option<String>,
    /// The eye position, e.g. `--eye 0,1.5,4`.
    #[arg(long, value_name = "X,Y,Z", allow_hyphen_values = true)]
    pub eye: Option<String>,
    /// The point looked at, e.g. `--look-at 0,1,0`.
    #[arg(long, value_name = "X,Y,Z", allow_hyphen_values = true)]
    pub look_at: Option<String>,
    /// Vertical field of view in degrees.
    #[arg(long, value_name = "DEG", allow_negative_numbers = true)]
    pub fov: Option<String>,
    /// The up axis, y or z; alone it frames the model again with that axis
    /// up (a Z-up OBJ stands upright with `--up z`).
    #[arg(long, value_name = "y|z")]
    pub up: Option<String>,
}

impl CameraFlags {
    /// The flags as a camera request, or an error naming the bad flag.
    pub fn choice(&self) -> Result<chiaro::camera::CameraChoice, chiaro::camera::CameraError> {
        chiaro::camera::CameraChoice::from_flags(
            self.name.as_deref(),
            self.eye.as_deref(),
            self.look_at.as_deref(),
            self.fov.as_deref(),
            self.up.as_deref(),
        )
    }
}

/// `chiaro render`.
#[derive(Debug, Args)]
pub struct RenderArgs {
    /// The scene file.
    pub scene: PathBuf,
    /// Output image; the extension picks the format (.png, .exr, .hdr, .ppm).
    #[arg(short, long, default_value = "out.png")]
    pub output: PathBuf,
    /// Render options.
    #[command(flatten)]
    pub opts: RenderOptions,
    /// Write an 8-bit palette PNG.
    #[arg(long, value_enum)]
    pub palette: Option<PaletteArg>,
    /// Tone mapping for 8-bit output.
    #[arg(long, value_enum)]
    pub tonemap: Option<ToneMapArg>,
    /// Exposure in stops before tone mapping.
    #[arg(long, allow_negative_numbers = true)]
    pub exposure: Option<f32>,
    /// Write 16-bit PNG.
    #[arg(long)]
    pub png16: bool,
    /// Stream the image to a running tev viewer as it renders (HOST:PORT, tev's default port is 14158).
    #[arg(long, value_name = "HOST:PORT")]
    pub display_server: Option<String>,
    /// Radiosity/hybrid: save the view-independent solution to this file.
    #[arg(long, value_name = "FILE")]
    pub save_solution: Option<PathBuf>,
    /// Radiosity/hybrid: render from this saved solution instead of solving.
    #[arg(long, value_name = "FILE")]
    pub solution: Option<PathBuf>,
}

/// `chiaro compare`.
#[derive(Debug, Args)]
pub struct CompareArgs {
    /// The scene file.
    pub scene: PathBuf,
    /// Techniques to compare, comma separated (e.g. `phong,whitted`).
    #[arg(long, value_delimiter = ',', required = true, num_args = 1..)]
    pub techniques: Vec<String>,
    /// The reference, TECHNIQUE:SPP (`path:1024`) or `TECHNIQUE:auto[:CAP]`
    /// (samples added until its own estimated relMSE is below a tenth of
    /// the smallest it judges; at most CAP, default 4096). Its seeds are
    /// derived from --seed, its size and --set options are those of the
    /// techniques.
    #[arg(long, default_value = "path:auto", value_name = "TECHNIQUE:SPP")]
    pub reference: String,
    /// The contact sheet (.png): per row the image, its error against the
    /// reference, and its time and metrics.
    #[arg(short, long, default_value = "compare.png")]
    pub output: PathBuf,
    /// Also write the report as JSON to this file.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Where the reference is cached (default: `.chiaro-cache/` next to the output).
    #[arg(long)]
    pub cache_dir: Option<PathBuf>,
    /// Render the reference even if it is cached, and do not cache it.
    #[arg(long, conflicts_with = "cache_dir")]
    pub no_cache: bool,
    /// Render options (`--technique` is not allowed: use --techniques).
    #[command(flatten)]
    pub opts: RenderOptions,
}

/// `--technique`'s help: the technique names as the facade lists them.
fn technique_help() -> String {
    format!(
        "Technique: {}, in any case (default: the scene's `[render] technique`)",
        chiaro::technique_list()
    )
}
