//! Mitsuba 3 XML scenes (`.xml`), read into the same [`Scene`] a `.toml`
//! file gives.
//!
//! The file is read in two steps. [`xml`] parses it (roxmltree, positions
//! kept), substitutes `$name` parameters from `<default>`s and `-D
//! name=value` ([`crate::LoadOptions::defines`]), splices `<include>`s and
//! collects `<path>` folders. Then the plugins are mapped onto chiaro by
//! concern: [`sensor`] (camera, film, sampler, integrator), [`shapes`],
//! [`bsdfs`] with their textures, and [`emitters`]; [`transform`] reads
//! `<transform>`s. What maps exactly, approximately (with the warning it
//! prints) or not at all is the table in `docs/import-mitsuba.md`; each
//! plugin not mapped exactly gives one warning naming its file, line and
//! column, and an unknown plugin or a malformed file is an error there.
//!
//! ```
//! let xml = r#"<scene version="3.0.0">
//!   <default name="spp" value="16"/>
//!   <sensor type="perspective">
//!     <float name="fov" value="40"/>
//!     <transform name="to_world"><lookat origin="0,0,5" target="0,0,0" up="0,1,0"/></transform>
//!     <sampler type="independent"><integer name="sample_count" value="$spp"/></sampler>
//!     <film type="hdrfilm"><integer name="width" value="64"/><integer name="height" value="48"/>
//!       <rfilter type="box"/></film>
//!   </sensor>
//!   <emitter type="point"><point name="position" x="0" y="3" z="3"/><rgb name="intensity" value="10"/></emitter>
//!   <shape type="sphere"><bsdf type="diffuse"><rgb name="reflectance" value="0.2, 0.5, 0.8"/></bsdf></shape>
//! </scene>"#;
//! let options = chiaro_io::LoadOptions { defines: vec![("spp".into(), "4".into())] };
//! let loaded = chiaro_io::mitsuba::load_str(xml, std::path::Path::new("."), "doc.xml", &options).expect("test input");
//! assert_eq!(loaded.scene.render.samples, 4);
//! assert_eq!((loaded.scene.render.width, loaded.scene.render.height), (64, 48));
//! ```

pub mod bsdfs;
pub mod emitters;
pub mod props;
pub mod sensor;
pub mod shapes;
pub mod spectra;
pub mod transform;
pub mod xml;

use crate::{Imported, LoadOptions, Loaded, Result, SharedImport};
use chiaro_core::scene::{ImageTexture, MaterialId, Scene, Technique};
use props::Props;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use xml::{Document, Element};

/// Reads the Mitsuba 3 scene file `path` with `options` (its `-D`
/// parameters). Returns the validated scene and its warnings, or an
/// [`crate::IoError`] naming the file, line and column.
pub fn load(path: &Path, options: &LoadOptions) -> Result<Loaded> {
    let doc = xml::read_document(path, &options.defines)?;
    build(&doc, path)
}

/// Reads Mitsuba 3 scene text held in memory; relative file names resolve
/// against `base` and `name` stands for the file in messages.
pub fn load_str(text: &str, base: &Path, name: &str, options: &LoadOptions) -> Result<Loaded> {
    let doc = xml::parse_document(text, Path::new(name), base, &options.defines)?;
    build(&doc, Path::new(name))
}

/// Maps the parsed document onto a scene.
fn build(doc: &Document, path: &Path) -> Result<Loaded> {
    let mut b = Builder::new(doc);
    for el in &doc.elements {
        if let Some(id) = el.attr("id") {
            b.ids.insert(id.to_owned(), el);
        }
    }
    let mut sensor_seen = false;
    let mut integrator_seen = false;
    for el in &doc.elements {
        match el.tag.as_str() {
            "sensor" if sensor_seen => b.warn(el, "only the first sensor is used"),
            "sensor" => {
                sensor_seen = true;
                b.sensor(el)?;
            }
            "integrator" if integrator_seen => b.warn(el, "only the first integrator is used"),
            "integrator" => {
                integrator_seen = true;
                b.integrator(el)?;
            }
            "shape" => b.shape(el, chiaro_core::Mat4::IDENTITY)?,
            // An area emitter with an id is declared for a shape's `<ref>`.
            "emitter" if el.attr("id").is_some() && el.attr("type") == Some("area") => {}
            "emitter" => b.emitter(el)?,
            // Declared for `<ref>`; built where they are referenced.
            "bsdf" | "texture" => b.check_plugin(el)?,
            "medium" | "phase" | "volume" => {
                b.warn(el, "refused: chiaro has no participating media")
            }
            "film" | "sampler" | "rfilter" => b.warn(el, "ignored outside a <sensor>"),
            // Properties at scene level (Mitsuba keeps them for the scene plugin).
            t if props::VALUE_TAGS.contains(&t) => b.warn(el, "scene-level property ignored"),
            other => {
                return Err(el.loc.error(format!(
                    "unknown element <{other}> (expected sensor, integrator, shape, emitter, bsdf, texture, default, include or path)"
                )));
            }
        }
    }
    if !sensor_seen {
        b.warnings.push(format!(
            "{}: the scene has no <sensor>: Mitsuba's default camera is used (fov 39.3 along x, at the origin looking down +z)",
            path.display()
        ));
        b.default_sensor();
    }
    if !integrator_seen {
        b.scene.render.technique = Technique::Path;
    }
    let Builder {
        scene, warnings, ..
    } = b;
    crate::finish(scene, warnings, path)
}

/// The state of one scene being mapped.
#[derive(Debug)]
pub struct Builder<'d> {
    doc: &'d Document,
    /// The scene built so far.
    pub scene: Scene,
    /// Warnings, one per plugin (its issues joined).
    pub warnings: Vec<String>,
    /// Where each plugin's warning is in `warnings`, by its position.
    warned: HashMap<String, usize>,
    /// Top-level plugins by `id`.
    ids: HashMap<String, &'d Element>,
    /// Materials already built from a `<bsdf id>` (key `bsdf:ID`).
    built: HashMap<String, (MaterialId, bsdfs::Built)>,
    /// Decoded images by file and encoding.
    images: HashMap<String, ImageTexture>,
    /// Mesh files read, by path and `flip_normals`.
    files: HashMap<(PathBuf, bool), Imported>,
    /// The mesh of each primitive shape (`rectangle|false`, ...).
    primitives: HashMap<String, chiaro_core::scene::MeshId>,
    /// One shared copy of a file's meshes per material and `flip_normals`.
    shared: HashMap<(PathBuf, u32, bool), SharedImport>,
}

impl<'d> Builder<'d> {
    fn new(doc: &'d Document) -> Self {
        let mut scene = Scene::default();
        scene.render.technique = Technique::Path;
        // Mitsuba's film and sampler defaults (768 x 576, 4 spp).
        scene.render.width = 768;
        scene.render.height = 576;
        scene.render.samples = 4;
        scene.lights.clear();
        Self {
            doc,
            scene,
            warnings: Vec::new(),
            warned: HashMap::new(),
            ids: HashMap::new(),
            built: HashMap::new(),
            images: HashMap::new(),
            files: HashMap::new(),
            primitives: HashMap::new(),
            shared: HashMap::new(),
        }
    }

    /// Adds `message` to the warning of plugin `el` (one line per plugin,
    /// naming its file, line and column).
    pub fn warn(&mut self, el: &Element, message: &str) {
        crate::warnings::warn_at(
            &mut self.warnings,
            &mut self.warned,
            el.loc.describe(),
            message,
            |key| format!("{key}: <{}>: ", el.plugin_name()),
        );
    }

    /// Warns about each property of `p` that no mapping read.
    pub fn warn_unused(&mut self, p: &Props) {
        let names: Vec<String> = p
            .unused()
            .iter()
            .map(|c| match c.attr("name") {
                Some(n) => format!("`{n}`"),
                None => format!("<{}>", c.plugin_name()),
            })
            .collect();
        if !names.is_empty() {
            let msg = format!("ignored: {}", names.join(", "));
            self.warn(p.el, &msg);
        }
    }

    /// The plugin a `<ref id>` names.
    pub fn lookup(&self, r: &Element) -> Result<&'d Element> {
        let id = r.require("id")?;
        self.ids.get(id).copied().ok_or_else(|| {
            r.loc.error(format!(
                "<ref id=\"{id}\"> names no plugin declared at the top of the scene"
            ))
        })
    }

    /// `el`, or the plugin it names where it is a `<ref>`; an error unless
    /// that is a `<tag>`.
    pub fn plugin_of<'e>(&self, el: &'e Element, tag: &str) -> Result<&'e Element>
    where
        'd: 'e,
    {
        let el = if el.tag == "ref" {
            self.lookup(el)?
        } else {
            el
        };
        if el.tag != tag {
            return Err(el
                .loc
                .error(format!("expected a <{tag}>, found <{}>", el.tag)));
        }
        Ok(el)
    }

    /// A file name resolved against the `<path>` folders and the scene's.
    pub fn resolve(&self, name: &str) -> PathBuf {
        self.doc.resolve(name)
    }

    /// The type of a plugin element, or an error at it.
    pub fn plugin_type(el: &Element) -> Result<&str> {
        el.require("type")
    }

    /// Checks a declared-only plugin's type is known (built when referenced).
    fn check_plugin(&mut self, el: &Element) -> Result<()> {
        let ty = Self::plugin_type(el)?;
        let known: &[&str] = if el.tag == "bsdf" {
            bsdfs::BSDF_TYPES
        } else {
            bsdfs::TEXTURE_TYPES
        };
        if !known.contains(&ty) {
            return Err(el.loc.error(format!(
                "unknown {} plugin \"{ty}\" (chiaro reads: {})",
                el.tag,
                known.join(", ")
            )));
        }
        Ok(())
    }
}
