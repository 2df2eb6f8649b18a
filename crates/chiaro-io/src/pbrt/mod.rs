//! pbrt-v4 scenes (`.pbrt`), and pbrt-v3 ones where the two differ little,
//! read into the same [`Scene`] a `.toml` file gives.
//!
//! [`lexer`] splits the file into tokens that keep their file, line and
//! column; [`params`] reads a directive's `"type name" value` list. This
//! module runs the directives in order: the transform stack, attributes,
//! `Include`/`Import`, named materials, textures and object instances, the
//! camera, film, sampler and integrator. [`shapes`], [`materials`] (with
//! textures and spectra) and [`lights`] map what they describe. What maps
//! exactly, approximately (with the warning it prints) or not at all is the
//! table in `docs/import-pbrt.md`; every directive not mapped exactly gives
//! one warning naming its file, line and column, and an unknown directive or
//! a malformed file is an error there.
//!
//! pbrt's camera space is left-handed: `LookAt` puts +x on the right of the
//! image, where chiaro's right-handed camera has `forward x up`. When the
//! camera transform keeps handedness (a plain `LookAt`) the loaded world is
//! mirrored about the camera's vertical plane, so the image is pbrt's and
//! not its mirror image; a file that mirrors its camera itself (the usual
//! `Scale -1 1 1` before `LookAt`) is read as written.
//!
//! ```
//! let text = r#"
//! LookAt 0 0 5  0 0 0  0 1 0
//! Camera "perspective" "float fov" 40
//! Film "rgb" "integer xresolution" 64 "integer yresolution" 48
//! Sampler "independent" "integer pixelsamples" 4
//! WorldBegin
//! LightSource "point" "rgb I" [10 10 10] "point3 from" [0 3 3]
//! Material "diffuse" "rgb reflectance" [0.2 0.5 0.8]
//! Shape "sphere" "float radius" 1
//! "#;
//! let loaded = chiaro_io::pbrt::load_str(text, std::path::Path::new("."), "doc.pbrt").expect("test input");
//! assert_eq!(loaded.scene.render.samples, 4);
//! assert_eq!((loaded.scene.render.width, loaded.scene.render.height), (64, 48));
//! ```

pub mod lexer;
pub mod lights;
pub mod materials;
pub mod params;
pub mod shapes;

use crate::{Imported, Loaded, Result, SharedImport};
use chiaro_core::scene::{Geometry, MaterialId, Object, PixelFilter, Scene, Technique};
use chiaro_core::{Mat4, Vec3};
use lexer::{Kind, Lexer, Loc, Token};
use params::Params;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// `Include`/`Import` nesting allowed.
const MAX_INCLUDE_DEPTH: usize = 32;
/// Objects a scene may place (instancing multiplies them).
const MAX_OBJECTS: usize = 1 << 22;

/// Reads the pbrt scene file `path`. Returns the validated scene and its
/// warnings, or an [`crate::IoError`] naming the file, line and column.
pub fn load(path: &Path) -> Result<Loaded> {
    let text = crate::files::read_text_file(path)?;
    let base = path.parent().unwrap_or_else(|| Path::new("."));
    load_text(&text, base, path)
}

/// Reads pbrt scene text held in memory; relative file names resolve
/// against `base` and `name` stands for the file in messages.
pub fn load_str(text: &str, base: &Path, name: &str) -> Result<Loaded> {
    load_text(text, base, Path::new(name))
}

fn load_text(text: &str, base: &Path, path: &Path) -> Result<Loaded> {
    let mut b = Builder::new(base);
    b.including.push(path.to_path_buf());
    b.run(text, path, 0)?;
    b.finish_scene()?;
    let Builder {
        scene, warnings, ..
    } = b;
    crate::finish(scene, warnings, path)
}

/// A material as written (`Material`, `MakeNamedMaterial`, pbrt's default).
#[derive(Debug, Clone)]
pub struct MaterialSpec {
    /// Its type (`diffuse`, `conductor`, pbrt-v3's `matte`, ...).
    pub ty: String,
    /// Its parameters.
    pub params: Params,
    /// Where it is written.
    pub loc: Loc,
    /// Its name for a named material.
    pub name: Option<String>,
}

/// An area light as written, resolved to its radiance.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AreaSpec {
    /// Emitted radiance (linear RGB).
    pub radiance: Vec3,
    /// Emits from both faces.
    pub two_sided: bool,
}

/// pbrt's graphics state, saved by `AttributeBegin`.
#[derive(Debug, Clone)]
struct State {
    /// `world_from_object` in the file's world (before any mirroring).
    ctm: Mat4,
    /// Index into `Builder::materials`.
    material: usize,
    /// Index into `Builder::areas`.
    area: Option<usize>,
    reverse_orientation: bool,
    /// Transform directives are ignored (`ActiveTransform EndTime`).
    frozen: bool,
}

/// What a save on the stack restores.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Saved {
    Attribute,
    Transform,
}

/// The camera as written.
#[derive(Debug, Clone)]
struct CameraSpec {
    camera_from_world: Mat4,
    fov: f32,
    /// `Camera "orthographic"`: its `screenwindow` (x0, x1, y0, y1; camera
    /// space units), `None` for pbrt's default.
    orthographic: Option<Option<[f32; 4]>>,
    loc: Loc,
}

/// An environment waiting for the mirroring decision (made at the end).
#[derive(Debug, Clone)]
pub struct PendingEnv {
    /// The image (as read), or `None` for a constant.
    pub image: Option<chiaro_core::scene::ImageTexture>,
    /// Radiance scale (RGB).
    pub scale: Vec3,
    /// `world_from_light`.
    pub world_from_light: Mat4,
    /// Where it is written.
    pub loc: Loc,
}

/// The state of one scene being read.
#[derive(Debug)]
pub struct Builder {
    /// The scene built so far.
    pub scene: Scene,
    /// Warnings, one per directive (its issues joined).
    pub warnings: Vec<String>,
    warned: HashMap<String, usize>,
    /// Folder of the main file, where relative names resolve.
    base: PathBuf,
    /// Files being read, for refusing self-inclusion.
    including: Vec<PathBuf>,
    state: State,
    stack: Vec<(Saved, State)>,
    named_coords: HashMap<String, Mat4>,
    /// Every material written, in order; `State::material` indexes it.
    pub materials: Vec<MaterialSpec>,
    /// Named materials by name.
    pub named_materials: HashMap<String, usize>,
    /// Built materials by spec index (and area light).
    pub built: HashMap<(usize, Option<usize>), MaterialId>,
    /// Area lights written.
    pub areas: Vec<AreaSpec>,
    /// Textures by (`float` or `spectrum`, name).
    pub textures: HashMap<(bool, String), materials::TexValue>,
    /// Decoded images by file and encoding.
    pub images: HashMap<String, chiaro_core::scene::ImageTexture>,
    /// PLY files read, with their meshes shared per material.
    pub files: HashMap<PathBuf, Imported>,
    /// One shared copy of a file's meshes per material and orientation.
    pub shared: HashMap<(PathBuf, u32, bool), SharedImport>,
    /// Named object instances (`ObjectBegin`): their placed objects.
    instances: HashMap<String, Vec<Object>>,
    /// The object being defined.
    defining: Option<(String, Vec<Object>)>,
    camera: Option<CameraSpec>,
    /// The environment, placed once the mirroring is known.
    pub env: Option<PendingEnv>,
    world_seen: bool,
    /// Whether a `PixelFilter` was given, and where the film is.
    filter_seen: bool,
    film_loc: Option<(Loc, String)>,
}

/// The warning of a tent or Gaussian `PixelFilter`: pbrt draws filter
/// offsets around a pixel without regard to the film's edge, chiaro (as
/// Mitsuba) only inside the film.
const BORDER: &str = "approximate within the filter's radius of the image border (pbrt's filter samples may fall outside the film, chiaro's do not)";

impl Builder {
    fn new(base: &Path) -> Self {
        let mut scene = Scene::default();
        scene.render.technique = Technique::Path;
        // pbrt's defaults: a 1280 x 720 film, 16 samples, maxdepth 5.
        scene.render.width = 1280;
        scene.render.height = 720;
        scene.render.samples = 16;
        scene.render.path.max_depth = 5;
        scene.lights.clear();
        let default_material = MaterialSpec {
            ty: "diffuse".into(),
            params: Params::default(),
            loc: Loc {
                file: Arc::new(PathBuf::from("<pbrt default>")),
                line: 0,
                column: 0,
            },
            name: None,
        };
        Self {
            scene,
            warnings: Vec::new(),
            warned: HashMap::new(),
            base: base.to_path_buf(),
            including: Vec::new(),
            state: State {
                ctm: Mat4::IDENTITY,
                material: 0,
                area: None,
                reverse_orientation: false,
                frozen: false,
            },
            stack: Vec::new(),
            named_coords: HashMap::new(),
            materials: vec![default_material],
            named_materials: HashMap::new(),
            built: HashMap::new(),
            areas: Vec::new(),
            textures: HashMap::new(),
            images: HashMap::new(),
            files: HashMap::new(),
            shared: HashMap::new(),
            instances: HashMap::new(),
            defining: None,
            camera: None,
            env: None,
            world_seen: false,
            filter_seen: false,
            film_loc: None,
        }
    }

    /// Adds `message` to the warning of the directive at `loc`, written
    /// `what` (one line per directive, naming its file, line and column).
    pub fn warn(&mut self, loc: &Loc, what: &str, message: &str) {
        crate::warnings::warn_at(
            &mut self.warnings,
            &mut self.warned,
            loc.describe(),
            message,
            |key| format!("{key}: {what}: "),
        );
    }

    /// Warns about each parameter of `p` that no mapping read.
    pub fn warn_unused(&mut self, loc: &Loc, what: &str, p: &Params) {
        let names = p.unused();
        if !names.is_empty() {
            self.warn(loc, what, &format!("ignored: {}", names.join(", ")));
        }
    }

    /// A file name resolved against the main file's folder.
    pub fn resolve(&self, name: &str) -> PathBuf {
        crate::resolve(&self.base, name)
    }

    /// The current `world_from_object`.
    pub fn ctm(&self) -> Mat4 {
        self.state.ctm
    }

    /// Sets the area light of the shapes that follow.
    pub fn set_area(&mut self, area: Option<usize>) {
        self.state.area = area;
    }

    /// Whether `ReverseOrientation` is in effect.
    pub fn reverse_orientation(&self) -> bool {
        self.state.reverse_orientation
    }

    /// Places an object: into the object being defined, or the scene.
    pub fn place(&mut self, loc: &Loc, object: Object) -> Result<()> {
        let count = self.scene.objects.len() + self.defining.as_ref().map_or(0, |(_, v)| v.len());
        if count >= MAX_OBJECTS {
            return Err(loc.error(format!(
                "more than {MAX_OBJECTS} objects: refused (instancing multiplies them)"
            )));
        }
        match &mut self.defining {
            Some((_, list)) => list.push(object),
            None => self.scene.objects.push(object),
        }
        Ok(())
    }

    /// The material of the next shape (with its area light), built once.
    pub fn current_material(&mut self) -> Result<MaterialId> {
        let key = (self.state.material, self.state.area);
        if let Some(id) = self.built.get(&key) {
            return Ok(*id);
        }
        let base = match self.built.get(&(self.state.material, None)) {
            Some(id) => *id,
            None => {
                let m = self.build_material(self.state.material, 0)?;
                let id = self.scene.add_material(m);
                self.built.insert((self.state.material, None), id);
                id
            }
        };
        let id = match self.state.area {
            None => base,
            Some(a) => {
                let area = self.areas[a];
                let mut m = self.scene.materials[base.index()].clone();
                m.emission = area.radiance;
                m.emission_two_sided = area.two_sided;
                m.name = format!("{} (emitter)", m.name);
                self.scene.add_material(m)
            }
        };
        self.built.insert(key, id);
        Ok(id)
    }

    /// Runs the directives of `text` (from `file`, `depth` includes deep).
    fn run(&mut self, text: &str, file: &Path, depth: usize) -> Result<()> {
        let mut lx = Lexer::new(text, Arc::new(file.to_path_buf()));
        while let Some(t) = lx.next_token()? {
            if t.kind != Kind::Bare {
                return Err(t
                    .loc
                    .error(format!("expected a directive, found {}", t.shown())));
            }
            self.directive(&t, &mut lx, depth)?;
        }
        Ok(())
    }

    /// One directive, its arguments read from `lx`.
    fn directive(&mut self, t: &Token, lx: &mut Lexer, depth: usize) -> Result<()> {
        let loc = &t.loc;
        match t.text.as_str() {
            "Identity" => self.apply(Mat4::IDENTITY, true),
            "Translate" => {
                let v = vec3_of(lx, "Translate")?;
                self.apply(Mat4::from_translation(v), false);
            }
            "Scale" => {
                let v = vec3_of(lx, "Scale")?;
                self.apply(Mat4::from_scale(v), false);
            }
            "Rotate" => {
                let angle = lx.number("Rotate's angle")?;
                let axis = vec3_of(lx, "Rotate's axis")?;
                let axis = axis
                    .try_normalize()
                    .ok_or_else(|| loc.error("Rotate: the axis is zero"))?;
                self.apply(Mat4::from_axis_angle(axis, angle.to_radians()), false);
            }
            "LookAt" => {
                let mut v = [0.0f32; 9];
                for x in &mut v {
                    *x = lx.number("LookAt's nine numbers")?;
                }
                let m = look_at(
                    Vec3::new(v[0], v[1], v[2]),
                    Vec3::new(v[3], v[4], v[5]),
                    Vec3::new(v[6], v[7], v[8]),
                )
                .ok_or_else(|| {
                    loc.error("LookAt: the eye and the target coincide or the up vector is parallel to the view direction")
                })?;
                self.apply(m, false);
            }
            "Transform" | "ConcatTransform" => {
                let m = matrix_of(lx, &t.text)?;
                self.apply(m, t.text == "Transform");
            }
            "CoordinateSystem" => {
                let name = lx.string("a coordinate system name")?;
                self.named_coords.insert(name.text, self.state.ctm);
            }
            "CoordSysTransform" => {
                let name = lx.string("a coordinate system name")?;
                match self.named_coords.get(&name.text) {
                    Some(m) => self.state.ctm = *m,
                    None => self.warn(
                        loc,
                        "CoordSysTransform",
                        &format!("no coordinate system named \"{}\"; ignored", name.text),
                    ),
                }
            }
            "ActiveTransform" => {
                let which = lx.expect("StartTime, EndTime or All")?;
                match which.text.as_str() {
                    "StartTime" | "All" => self.state.frozen = false,
                    "EndTime" => {
                        self.state.frozen = true;
                        self.warn(loc, "ActiveTransform", "approximate: motion blur is not drawn; the start-time transform is used");
                    }
                    other => {
                        return Err(which.loc.error(format!(
                            "ActiveTransform: expected StartTime, EndTime or All, found {other}"
                        )));
                    }
                }
            }
            "TransformTimes" => {
                lx.number("the start time")?;
                lx.number("the end time")?;
            }
            "ReverseOrientation" => {
                self.state.reverse_orientation = !self.state.reverse_orientation
            }
            "AttributeBegin" | "TransformBegin" => {
                let kind = if t.text == "AttributeBegin" {
                    Saved::Attribute
                } else {
                    Saved::Transform
                };
                if self.stack.len() > 4096 {
                    return Err(loc.error("attributes nested more than 4096 deep"));
                }
                self.stack.push((kind, self.state.clone()));
            }
            "AttributeEnd" | "TransformEnd" => {
                let kind = if t.text == "AttributeEnd" {
                    Saved::Attribute
                } else {
                    Saved::Transform
                };
                match self.stack.pop() {
                    Some((k, saved)) => {
                        if k != kind {
                            self.warn(loc, &t.text, "does not match the Begin it closes");
                        }
                        if kind == Saved::Transform {
                            self.state.ctm = saved.ctm;
                        } else {
                            self.state = saved;
                        }
                    }
                    None => {
                        return Err(loc.error(format!("{} without a matching Begin", t.text)));
                    }
                }
            }
            "Attribute" => {
                let target = lx.string("an attribute target")?;
                let p = Params::read(lx)?;
                self.warn(
                    loc,
                    &format!("Attribute \"{}\"", target.text),
                    &format!(
                        "ignored: default parameters are not applied ({} given)",
                        p.list.len()
                    ),
                );
            }
            // Their settings change no image.
            "Option" => {
                let _ = Params::read(lx)?;
            }
            "Accelerator" => {
                let _ = lx.string("an accelerator type")?;
                let _ = Params::read(lx)?;
            }
            "ColorSpace" => {
                let name = lx.string("a colour space")?;
                if name.text != "srgb" {
                    self.warn(
                        loc,
                        "ColorSpace",
                        &format!(
                            "approximate: RGB values are read as linear sRGB, not \"{}\"",
                            name.text
                        ),
                    );
                }
            }
            "Camera" => self.camera_directive(loc, lx)?,
            "Film" => self.film(loc, lx)?,
            "Sampler" => {
                let ty = lx.string("a sampler type")?;
                let p = Params::read(lx)?;
                let n = p.int("pixelsamples", 16)?;
                self.scene.render.samples = u32::try_from(n)
                    .ok()
                    .filter(|n| *n > 0)
                    .ok_or_else(|| loc.error(format!("pixelsamples must be positive, got {n}")))?;
                for skip in [
                    "seed",
                    "jitter",
                    "randomization",
                    "dimensions",
                    "xsamples",
                    "ysamples",
                ] {
                    p.skip(skip);
                }
                let what = format!("Sampler \"{}\"", ty.text);
                self.warn_unused(loc, &what, &p);
            }
            "Integrator" => self.integrator(loc, lx)?,
            "PixelFilter" => {
                let ty = lx.string("a filter type")?;
                let p = Params::read(lx)?;
                let what = format!("PixelFilter \"{}\"", ty.text);
                self.filter_seen = true;
                match ty.text.as_str() {
                    "box" => {
                        let r = p.float("xradius", 0.5)?.max(p.float("yradius", 0.5)?);
                        self.scene.render.filter = PixelFilter::Box;
                        if (r - 0.5).abs() > 1e-6 {
                            self.warn(
                                loc,
                                &what,
                                "approximate: chiaro's box filter is one pixel wide",
                            );
                        }
                    }
                    "triangle" => {
                        self.scene.render.filter = PixelFilter::Tent;
                        let r = p.float("xradius", 2.0)?.max(p.float("yradius", 2.0)?);
                        if (r - 1.0).abs() > 1e-6 {
                            self.warn(loc, &what, &format!("approximate: drawn with chiaro's tent of radius 1 pixel (not {r})"));
                        } else {
                            self.warn(loc, &what, BORDER);
                        }
                    }
                    // Mitsuba's Gaussian is pbrt's of sigma 0.5 cut at 2 pixels.
                    "gaussian"
                        if (p.float("sigma", 0.5)? - 0.5).abs() < 1e-6
                            && (p.float("xradius", 1.5)? - 2.0).abs() < 1e-6
                            && (p.float("yradius", 1.5)? - 2.0).abs() < 1e-6 =>
                    {
                        self.scene.render.filter = PixelFilter::Gaussian;
                        self.warn(loc, &what, BORDER);
                    }
                    "gaussian" | "mitchell" | "sinc" | "lanczos" => {
                        self.scene.render.filter = PixelFilter::Tent;
                        for k in ["xradius", "yradius", "sigma", "B", "C", "tau", "alpha"] {
                            p.skip(k);
                        }
                        self.warn(
                            loc,
                            &what,
                            "approximate: drawn with chiaro's tent filter (radius 1)",
                        );
                    }
                    other => {
                        return Err(ty.loc.error(format!(
                            "unknown PixelFilter \"{other}\" (expected box, triangle, gaussian, mitchell, sinc or lanczos)"
                        )));
                    }
                }
                self.warn_unused(loc, &what, &p);
            }
            "WorldBegin" => {
                self.world_seen = true;
                self.state.ctm = Mat4::IDENTITY;
                self.named_coords.insert("world".into(), Mat4::IDENTITY);
            }
            "WorldEnd" => {}
            "Include" | "Import" => {
                let name = lx.string("a file name")?;
                self.include(&name, depth)?;
            }
            "MakeNamedMaterial" => {
                let name = lx.string("a material name")?;
                let p = Params::read(lx)?;
                let ty = p.string("type")?.ok_or_else(|| {
                    loc.error(format!(
                        "MakeNamedMaterial \"{}\" needs a \"string type\"",
                        name.text
                    ))
                })?;
                if self.named_materials.contains_key(&name.text) {
                    self.warn(
                        loc,
                        "MakeNamedMaterial",
                        &format!("\"{}\" is defined again; the later one is used", name.text),
                    );
                }
                self.materials.push(MaterialSpec {
                    ty,
                    params: p,
                    loc: loc.clone(),
                    name: Some(name.text.clone()),
                });
                self.named_materials
                    .insert(name.text, self.materials.len() - 1);
            }
            "Material" => {
                let ty = lx.string("a material type")?;
                let p = Params::read(lx)?;
                self.materials.push(MaterialSpec {
                    ty: ty.text,
                    params: p,
                    loc: loc.clone(),
                    name: None,
                });
                self.state.material = self.materials.len() - 1;
            }
            "NamedMaterial" => {
                let name = lx.string("a material name")?;
                self.state.material = *self.named_materials.get(&name.text).ok_or_else(|| {
                    name.loc.error(format!(
                        "no material named \"{}\" is defined before this line",
                        name.text
                    ))
                })?;
            }
            "Texture" => self.texture(loc, lx)?,
            "LightSource" => self.light_source(loc, lx)?,
            "AreaLightSource" => self.area_light(loc, lx)?,
            "Shape" => self.shape(loc, lx)?,
            "ObjectBegin" => {
                let name = lx.string("an object name")?;
                if self.defining.is_some() {
                    return Err(loc.error("ObjectBegin inside another ObjectBegin"));
                }
                if self.stack.len() > 4096 {
                    return Err(loc.error("attributes nested more than 4096 deep"));
                }
                self.stack.push((Saved::Attribute, self.state.clone()));
                self.defining = Some((name.text, Vec::new()));
            }
            "ObjectEnd" => {
                let Some((name, objects)) = self.defining.take() else {
                    return Err(loc.error("ObjectEnd without an ObjectBegin"));
                };
                if self.instances.contains_key(&name) {
                    self.warn(
                        loc,
                        "ObjectEnd",
                        &format!("object \"{name}\" is defined again; the later one is used"),
                    );
                }
                self.instances.insert(name, objects);
                match self.stack.pop() {
                    Some((_, saved)) => self.state = saved,
                    None => return Err(loc.error("ObjectEnd without an ObjectBegin")),
                }
            }
            "ObjectInstance" => {
                let name = lx.string("an object name")?;
                if self.defining.is_some() {
                    return Err(loc.error(
                        "ObjectInstance inside ObjectBegin is refused (pbrt does not nest instances)",
                    ));
                }
                let objects = self.instances.get(&name.text).cloned().ok_or_else(|| {
                    name.loc.error(format!(
                        "no object named \"{}\" is defined before this line",
                        name.text
                    ))
                })?;
                let m = self.state.ctm;
                for mut o in objects {
                    o.transform.matrix = m * o.transform.matrix;
                    if let Geometry::Sphere { radius } = o.geometry {
                        let (s, c) = shapes::sphere_placement(o.transform.matrix);
                        o.geometry = Geometry::Sphere { radius: radius * s };
                        o.transform =
                            chiaro_core::scene::Transform::from_matrix(Mat4::from_translation(c));
                    }
                    self.place(loc, o)?;
                }
            }
            "MakeNamedMedium" => {
                let _ = lx.string("a medium name")?;
                let _ = Params::read(lx)?;
                self.warn(
                    loc,
                    "MakeNamedMedium",
                    "refused: chiaro has no participating media (ignored)",
                );
            }
            "MediumInterface" => {
                let _ = lx.string("an inside medium")?;
                if lx.peek()?.is_some_and(|t| t.kind == Kind::Quoted) {
                    let _ = lx.string("an outside medium")?;
                }
                self.warn(
                    loc,
                    "MediumInterface",
                    "refused: chiaro has no participating media (ignored)",
                );
            }
            other => {
                return Err(loc.error(format!("unknown directive {other}")));
            }
        }
        Ok(())
    }

    /// `ctm = ctm * m` (or `ctm = m` when `replace`), unless frozen.
    fn apply(&mut self, m: Mat4, replace: bool) {
        if self.state.frozen {
            return;
        }
        self.state.ctm = if replace { m } else { self.state.ctm * m };
    }

    fn include(&mut self, name: &Token, depth: usize) -> Result<()> {
        if depth + 1 > MAX_INCLUDE_DEPTH {
            return Err(name
                .loc
                .error(format!("Include nested more than {MAX_INCLUDE_DEPTH} deep")));
        }
        let path = self.resolve(&name.text);
        let canonical = path.canonicalize().unwrap_or_else(|_| path.clone());
        if self
            .including
            .iter()
            .any(|p| p.canonicalize().unwrap_or_else(|_| p.clone()) == canonical)
        {
            return Err(name.loc.error(format!("\"{}\" includes itself", name.text)));
        }
        let text = crate::files::read_text_file(&path)
            .map_err(|e| name.loc.error(format!("Include: {e}")))?;
        self.including.push(path.clone());
        let r = self.run(&text, &path, depth + 1);
        self.including.pop();
        r
    }

    fn camera_directive(&mut self, loc: &Loc, lx: &mut Lexer) -> Result<()> {
        let ty = lx.string("a camera type")?;
        let p = Params::read(lx)?;
        let what = format!("Camera \"{}\"", ty.text);
        let orthographic = match ty.text.as_str() {
            "perspective" => false,
            "orthographic" => true,
            "realistic" | "spherical" => {
                return Err(ty.loc.error(format!(
                    "Camera \"{}\" is refused: chiaro has perspective and orthographic cameras",
                    ty.text
                )));
            }
            other => {
                return Err(ty.loc.error(format!(
                    "unknown Camera \"{other}\" (expected perspective or orthographic)"
                )));
            }
        };
        // The screen window of an orthographic camera is its film, in
        // camera space units (pbrt-v4 `CameraBase`, `OrthographicCamera`).
        let screen = if orthographic {
            match p.floats("screenwindow")? {
                None => Some(None),
                Some(v) => match <[f32; 4]>::try_from(v.as_slice()) {
                    Ok(w) if w[1] > w[0] && w[3] > w[2] && w.iter().all(|x| x.is_finite()) => {
                        Some(Some(w))
                    }
                    _ => {
                        return Err(p.loc_of("screenwindow").error(format!(
                            "screenwindow: expected four finite numbers x0 < x1, y0 < y1, got {v:?}"
                        )));
                    }
                },
            }
        } else {
            None
        };
        let fov = if orthographic {
            90.0
        } else {
            p.float("fov", 90.0)?
        };
        if !(fov > 0.0 && fov < 180.0) {
            return Err(p
                .loc_of("fov")
                .error(format!("fov must be in (0, 180) degrees, got {fov}")));
        }
        if p.float("lensradius", 0.0)? > 0.0 {
            p.skip("focaldistance");
            self.warn(
                loc,
                &what,
                "approximate: drawn as a pinhole camera (no depth of field)",
            );
        }
        for k in ["screenwindow", "frameaspectratio"] {
            if p.has(k) && !(orthographic && k == "screenwindow") {
                self.warn(
                    loc,
                    &what,
                    &format!("approximate: \"{k}\" is ignored (the film's aspect is used)"),
                );
            }
        }
        for k in ["shutteropen", "shutterclose"] {
            p.skip(k);
        }
        if self.camera.is_some() {
            self.warn(loc, &what, "only the last camera is used");
        }
        // pbrt names the camera's space "camera": world_from_camera.
        let camera_from_world = self.state.ctm;
        self.named_coords
            .insert("camera".into(), camera_from_world.inverse());
        self.camera = Some(CameraSpec {
            camera_from_world,
            fov,
            orthographic: screen,
            loc: loc.clone(),
        });
        self.warn_unused(loc, &what, &p);
        Ok(())
    }

    fn film(&mut self, loc: &Loc, lx: &mut Lexer) -> Result<()> {
        let ty = lx.string("a film type")?;
        let p = Params::read(lx)?;
        let what = format!("Film \"{}\"", ty.text);
        self.film_loc = Some((loc.clone(), what.clone()));
        let size = |name: &str, default: i64| -> Result<u32> {
            let v = p.int(name, default)?;
            u32::try_from(v).ok().filter(|v| *v > 0).ok_or_else(|| {
                p.loc_of(name)
                    .error(format!("{name} must be positive, got {v}"))
            })
        };
        self.scene.render.width = size("xresolution", 1280)?;
        self.scene.render.height = size("yresolution", 720)?;
        for k in [
            "filename",
            "savefp16",
            "diagonal",
            "maxcomponentvalue",
            "writefp16",
        ] {
            p.skip(k);
        }
        if p.has("cropwindow") || p.has("pixelbounds") {
            self.warn(
                loc,
                &what,
                "approximate: the crop window is ignored (use --set crop=...)",
            );
        }
        for k in ["iso", "exposuretime", "whitebalance", "sensor"] {
            if p.has(k) {
                self.warn(
                    loc,
                    &what,
                    &format!(
                        "approximate: \"{k}\" is ignored (chiaro writes the radiance as it is)"
                    ),
                );
            }
        }
        self.warn_unused(loc, &what, &p);
        Ok(())
    }

    fn integrator(&mut self, loc: &Loc, lx: &mut Lexer) -> Result<()> {
        let ty = lx.string("an integrator type")?;
        let p = Params::read(lx)?;
        let what = format!("Integrator \"{}\"", ty.text);
        self.scene.render.technique = Technique::Path;
        match ty.text.as_str() {
            "path" => {}
            "volpath" | "simplepath" | "simplevolpath" | "bdpt" | "mlt" | "sppm" | "lightpath"
            | "randomwalk" => {
                self.warn(loc, &what, "approximate: drawn by chiaro's path tracer");
            }
            other => {
                return Err(ty.loc.error(format!(
                    "Integrator \"{other}\" is refused: chiaro reads path (and volpath, simplepath, bdpt, mlt, sppm, lightpath, randomwalk as path)"
                )));
            }
        }
        // pbrt's maxdepth counts bounces: 1 is direct light, chiaro's 1.
        let d = p.int("maxdepth", 5)?;
        self.scene.render.path.max_depth = u32::try_from(d)
            .ok()
            .filter(|d| *d >= 1)
            .map(|d| d.min(1024))
            .ok_or_else(|| {
                p.loc_of("maxdepth").error(format!(
                    "maxdepth {d}: chiaro renders paths of at least one bounce"
                ))
            })?;
        for k in ["lightsampler", "regularize", "seed"] {
            p.skip(k);
        }
        self.warn_unused(loc, &what, &p);
        Ok(())
    }

    /// The camera (fov along the shorter image axis), and the mirroring
    /// that keeps pbrt's left-handed image unmirrored.
    fn finish_scene(&mut self) -> Result<()> {
        if self.defining.is_some() {
            self.warnings
                .push("an ObjectBegin is not closed by ObjectEnd; its shapes are not drawn".into());
        }
        let spec = self.camera.clone().unwrap_or_else(|| CameraSpec {
            camera_from_world: Mat4::IDENTITY,
            fov: 90.0,
            orthographic: None,
            loc: Loc {
                file: Arc::new(PathBuf::from("<pbrt default>")),
                line: 0,
                column: 0,
            },
        });
        if !self.filter_seen {
            // pbrt's default reconstruction filter is a Gaussian.
            self.scene.render.filter = PixelFilter::Tent;
            let message = "approximate: pbrt's default Gaussian pixel filter (no PixelFilter) is drawn with chiaro's tent (radius 1)";
            match self.film_loc.clone() {
                Some((loc, what)) => self.warn(&loc, &what, message),
                None => self.warnings.push(message.to_owned()),
            }
        }
        if self.camera.is_none() {
            self.warnings.push("the scene has no Camera: pbrt's default is used (at the origin looking down +z, fov 90)".into());
        }
        let world_from_camera = spec.camera_from_world.inverse();
        if !world_from_camera.is_finite() || spec.camera_from_world.determinant().abs() < 1e-12 {
            return Err(spec.loc.error("the camera transform is singular"));
        }
        let eye = world_from_camera.transform_point3(Vec3::ZERO);
        let forward = world_from_camera
            .transform_vector3(Vec3::Z)
            .normalize_or_zero();
        let up = world_from_camera
            .transform_vector3(Vec3::Y)
            .normalize_or_zero();
        let right_pbrt = world_from_camera.transform_vector3(Vec3::X);
        let right = forward.cross(up).normalize_or_zero();
        if right == Vec3::ZERO {
            return Err(spec
                .loc
                .error("the camera transform has no usable view or up direction"));
        }
        let (w, h) = (
            self.scene.render.width as f32,
            self.scene.render.height as f32,
        );
        // pbrt's fov spans the shorter image axis.
        let fov_y = if w >= h {
            spec.fov
        } else {
            crate::mitsuba::sensor::fov_y_from_x(spec.fov, w / h)
        };
        self.scene.camera.eye = eye;
        self.scene.camera.look_at = eye + forward;
        self.scene.camera.up = up;
        self.scene.camera.fov_y_degrees = fov_y;
        if let Some(screen) = spec.orthographic {
            // pbrt's default screen window spans [-1, 1] along the shorter
            // image axis; camera space units scale to the world by the
            // camera transform.
            let aspect = w / h;
            let half_height = match screen {
                None if w >= h => 1.0,
                None => 1.0 / aspect,
                Some([x0, x1, y0, y1]) => {
                    let off_centre = x0 != -x1 || y0 != -y1;
                    let stretched = ((x1 - x0) / (y1 - y0) - aspect).abs() > 1e-4 * aspect;
                    if off_centre || stretched {
                        let loc = spec.loc.clone();
                        self.warn(
                            &loc,
                            "Camera \"orthographic\"",
                            "approximate: the screenwindow is centred on the view axis with the film's aspect (its height kept)",
                        );
                    }
                    0.5 * (y1 - y0)
                }
            };
            let scale = world_from_camera.transform_vector3(Vec3::Y).length();
            self.scene.camera.projection = chiaro_core::scene::Projection::Orthographic {
                half_height: half_height * scale,
            };
        }
        // pbrt's image +x is `right_pbrt`, chiaro's `forward x up`: where
        // they differ, mirror the world about the camera's vertical plane.
        let mirror = if right_pbrt.dot(right) < 0.0 {
            let reflect = Mat4::from_mat3(chiaro_core::Mat3::IDENTITY - 2.0 * outer(right));
            Mat4::from_translation(eye) * reflect * Mat4::from_translation(-eye)
        } else {
            Mat4::IDENTITY
        };
        if mirror != Mat4::IDENTITY {
            for o in &mut self.scene.objects {
                o.transform.matrix = mirror * o.transform.matrix;
                if let Geometry::Sphere { .. } = o.geometry {
                    let c = o.transform.matrix.transform_point3(Vec3::ZERO);
                    o.transform =
                        chiaro_core::scene::Transform::from_matrix(Mat4::from_translation(c));
                }
            }
            for l in &mut self.scene.lights {
                *l = crate::transform_light(l, mirror);
            }
        }
        if let Some(env) = self.env.take() {
            self.place_environment(&env, mirror)?;
        }
        Ok(())
    }
}

/// `n n^T`.
fn outer(n: Vec3) -> chiaro_core::Mat3 {
    chiaro_core::Mat3::from_cols(n * n.x, n * n.y, n * n.z)
}

/// Three bare numbers.
fn vec3_of(lx: &mut Lexer, what: &str) -> Result<Vec3> {
    Ok(Vec3::new(
        lx.number(what)?,
        lx.number(what)?,
        lx.number(what)?,
    ))
}

/// Sixteen numbers, bracketed or not, as pbrt writes a matrix (column by
/// column: the translation is the 13th to 15th).
fn matrix_of(lx: &mut Lexer, what: &str) -> Result<Mat4> {
    let bracketed = lx.peek()?.is_some_and(|t| t.kind == Kind::Open);
    if bracketed {
        lx.next_token()?;
    }
    let mut v = [0.0f32; 16];
    for x in &mut v {
        *x = lx.number(&format!("{what}'s 16 numbers"))?;
    }
    if bracketed {
        let t = lx.expect("]")?;
        if t.kind != Kind::Close {
            return Err(t.loc.error(format!(
                "{what}: expected ] after 16 numbers, found {}",
                t.shown()
            )));
        }
    }
    Ok(Mat4::from_cols_array(&v))
}

/// pbrt's `LookAt`: `camera_from_world` for a camera at `eye` looking at
/// `target`, with pbrt's left-handed camera space (+x = normalize(up x
/// dir), +y the orthogonalised up, +z the view direction). `None` when
/// degenerate.
pub fn look_at(eye: Vec3, target: Vec3, up: Vec3) -> Option<Mat4> {
    let dir = (target - eye).try_normalize()?;
    let right = up.try_normalize()?.cross(dir).try_normalize()?;
    let new_up = dir.cross(right);
    let world_from_camera = Mat4::from_cols(
        right.extend(0.0),
        new_up.extend(0.0),
        dir.extend(0.0),
        eye.extend(1.0),
    );
    Some(world_from_camera.inverse())
}
