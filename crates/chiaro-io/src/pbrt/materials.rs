//! `Material`/`MakeNamedMaterial` types and `Texture` classes onto
//! chiaro's material: Lambert `kd`, a Torrance-Sparrow lobe with
//! Schlick's Fresnel from `ks`, a fixed mirror weight `kr`, the Fresnel of
//! a conductor's complex IOR (`Material::conductor`) and Fresnel-split
//! glass, smooth or rough. pbrt-v4's `diffuse`, `dielectric`, `conductor`
//! and a mix of two diffuse materials land on it exactly, as do pbrt-v3's
//! `matte`, `glass`, `metal` and `mirror`; conductors take their RGB eta
//! and k from pbrt's named spectra through the Mitsuba reader's table
//! (`mitsuba::spectra`), and the rest are approximations, each saying so
//! once. Named spectra and blackbodies are reduced to RGB here.

use super::Builder;
use super::lexer::{Lexer, Loc};
use super::params::{Params, Spectrum};
use crate::Result;
use crate::mitsuba::spectra;
use chiaro_core::scene::{
    ComplexIor, Distribution, Filter, Material, Procedural, ProceduralKind, ReflectanceModel,
    Sidedness, Texture, TextureId, UvTransform, WrapMode,
};
use chiaro_core::shading::dielectric::MIN_ROUGH_ALPHA;
use chiaro_core::{Vec2, Vec3};

/// The material types this module reads (pbrt-v4, then pbrt-v3 names).
pub const MATERIALS: &[&str] = &[
    "diffuse",
    "conductor",
    "dielectric",
    "thindielectric",
    "coateddiffuse",
    "coatedconductor",
    "diffusetransmission",
    "interface",
    "mix",
    "matte",
    "metal",
    "mirror",
    "glass",
    "plastic",
    "substrate",
    "uber",
    "translucent",
];

/// The texture classes this module reads.
pub const TEXTURES: &[&str] = &["constant", "imagemap", "checkerboard", "scale"];

/// A texture's value where a material reads it.
#[derive(Debug, Clone, PartialEq)]
pub enum TexValue {
    /// One RGB value (a float texture is grey).
    Const(Vec3),
    /// An image or a procedural texture times a colour.
    Map {
        /// The texture.
        id: TextureId,
        /// What it is multiplied by.
        factor: Vec3,
    },
}

/// pbrt-v4's d-line refractive indices of its named glasses (Schott's
/// catalogue at 587.6 nm).
const GLASSES: &[(&str, f32)] = &[
    ("glass-BK7", 1.5168),
    ("glass-BAF10", 1.6700),
    ("glass-FK51A", 1.4866),
    ("glass-LASF9", 1.8503),
    ("glass-F5", 1.6727),
    ("glass-F10", 1.7283),
    ("glass-F11", 1.7847),
];

/// The RGB `(eta, k)` of pbrt's named metal `metal-NAME-eta` /
/// `metal-NAME-k`, from the Mitsuba reader's tables.
fn metal(name: &str) -> Option<(Vec3, Vec3, bool)> {
    let rest = name.strip_prefix("metal-")?;
    let (metal, part) = rest.rsplit_once('-')?;
    let (eta, k) = spectra::conductor(metal)?;
    match part {
        "eta" => Some((eta, k, true)),
        "k" => Some((eta, k, false)),
        _ => None,
    }
}

/// The RGB of a blackbody at `kelvin`, scaled to luminance 1 (pbrt
/// normalises emission spectra to their photometric value): Planck's law
/// integrated against the CIE 1931 matching functions in the multi-lobe
/// fit of Wyman, Sloan and Shirley (JCGT 2013), then XYZ to linear sRGB.
pub fn blackbody_rgb(kelvin: f32) -> Option<Vec3> {
    if !(kelvin.is_finite() && kelvin > 0.0) {
        return None;
    }
    let g = |x: f64, mu: f64, s1: f64, s2: f64| {
        let t = (x - mu) / if x < mu { s1 } else { s2 };
        (-0.5 * t * t).exp()
    };
    let (c, h, kb) = (299_792_458.0f64, 6.626_070_15e-34f64, 1.380_649e-23f64);
    let mut xyz = [0.0f64; 3];
    let mut l = 360.0f64;
    while l <= 830.0 {
        let lm = l * 1e-9;
        let planck =
            2.0 * h * c * c / (lm.powi(5) * ((h * c / (lm * kb * kelvin as f64)).exp() - 1.0));
        let x = 1.056 * g(l, 599.8, 37.9, 31.0) + 0.362 * g(l, 442.0, 16.0, 26.7)
            - 0.065 * g(l, 501.1, 20.4, 26.2);
        let y = 0.821 * g(l, 568.8, 46.9, 40.5) + 0.286 * g(l, 530.9, 16.3, 31.1);
        let z = 1.217 * g(l, 437.0, 11.8, 36.0) + 0.681 * g(l, 459.0, 26.0, 13.8);
        xyz[0] += planck * x;
        xyz[1] += planck * y;
        xyz[2] += planck * z;
        l += 5.0;
    }
    if !(xyz[1] > 0.0 && xyz[1].is_finite()) {
        return None;
    }
    let [x, y, z] = xyz.map(|v| v / xyz[1]);
    // XYZ to linear sRGB (IEC 61966-2-1).
    let rgb = Vec3::new(
        (3.2406 * x - 1.5372 * y - 0.4986 * z) as f32,
        (-0.9689 * x + 1.8758 * y + 0.0415 * z) as f32,
        (0.0557 * x - 0.2040 * y + 1.0570 * z) as f32,
    );
    Some(rgb.max(Vec3::ZERO))
}

/// pbrt-v3's `RoughnessToAlpha` (a polynomial in `ln r`).
fn v3_alpha(r: f32) -> f32 {
    let x = r.max(1e-3).ln();
    1.62142 + 0.819955 * x + 0.1734 * x * x + 0.0171201 * x * x * x + 0.000640711 * x * x * x * x
}

impl Builder {
    /// A spectrum-valued parameter as an RGB constant or a texture; a
    /// named spectrum other than an illuminant is an error here.
    pub fn value(
        &mut self,
        p: &Params,
        name: &str,
        default: Vec3,
        loc: &Loc,
        what: &str,
    ) -> Result<TexValue> {
        let Some((s, at)) = p.spectrum(name)? else {
            return Ok(TexValue::Const(default));
        };
        match s {
            Spectrum::Texture(t) => self.texture_named(&t, &at),
            other => Ok(TexValue::Const(
                self.constant_spectrum(other, &at, loc, what)?,
            )),
        }
    }

    /// A constant spectrum reduced to RGB.
    pub fn constant_spectrum(
        &mut self,
        s: Spectrum,
        at: &Loc,
        loc: &Loc,
        what: &str,
    ) -> Result<Vec3> {
        match s {
            Spectrum::Rgb(c) => Ok(c),
            Spectrum::Blackbody(t, scale) => {
                let c = blackbody_rgb(t).ok_or_else(|| at.error(format!("blackbody temperature {t} K is not a positive number")))?;
                Ok(c * scale)
            }
            Spectrum::Pairs(pairs) => {
                let mean = pairs.iter().map(|p| p.1).sum::<f32>() / pairs.len().max(1) as f32;
                self.warn(loc, what, "approximate: a sampled spectrum is drawn as the grey of its mean value");
                Ok(Vec3::splat(mean))
            }
            Spectrum::Named(n) if n.starts_with("stdillum-") => {
                if n != "stdillum-D65" {
                    self.warn(loc, what, &format!("approximate: illuminant \"{n}\" is drawn white (as D65)"));
                }
                Ok(Vec3::ONE)
            }
            Spectrum::Named(n) => Err(at.error(format!(
                "the named spectrum \"{n}\" is not a colour chiaro reads here (named spectra are read for a conductor's eta and k, a dielectric's eta and a light's illuminant)"
            ))),
            Spectrum::Texture(t) => Err(at.error(format!("a texture (\"{t}\") is not allowed here"))),
        }
    }

    /// A float parameter that may be a float texture (an image one is
    /// drawn at its mean factor, with a warning).
    fn float_value(
        &mut self,
        p: &Params,
        name: &str,
        default: f32,
        loc: &Loc,
        what: &str,
    ) -> Result<f32> {
        match p.spectrum(name)? {
            None => Ok(default),
            Some((Spectrum::Rgb(c), _)) => Ok(c.x),
            Some((Spectrum::Texture(t), at)) => {
                match self.float_texture(&t, &at)? {
                    TexValue::Const(c) => Ok(c.x),
                    TexValue::Map { factor, .. } => {
                        self.warn(loc, what, &format!("approximate: the texture of \"{name}\" is drawn as its constant factor"));
                        Ok(factor.x)
                    }
                }
            }
            Some((_, at)) => {
                Err(at.error(format!("\"{name}\" must be a float or a float texture")))
            }
        }
    }

    /// A spectrum texture by name (a float texture is accepted as grey).
    fn texture_named(&mut self, name: &str, at: &Loc) -> Result<TexValue> {
        if let Some(t) = self.textures.get(&(false, name.to_owned())) {
            return Ok(t.clone());
        }
        self.float_texture(name, at)
    }

    fn float_texture(&mut self, name: &str, at: &Loc) -> Result<TexValue> {
        self.textures
            .get(&(true, name.to_owned()))
            .or_else(|| self.textures.get(&(false, name.to_owned())))
            .cloned()
            .ok_or_else(|| {
                at.error(format!(
                    "no texture named \"{name}\" is defined before this line"
                ))
            })
    }

    /// A `Texture "name" "spectrum"|"float" "class" ...` directive.
    pub fn texture(&mut self, loc: &Loc, lx: &mut Lexer) -> Result<()> {
        let name = lx.string("a texture name")?;
        let kind = lx.string("the texture's type (spectrum or float)")?;
        let class = lx.string("a texture class")?;
        let p = Params::read(lx)?;
        let is_float = match kind.text.as_str() {
            "float" => true,
            "spectrum" | "color" | "rgb" => false,
            other => {
                return Err(kind.loc.error(format!(
                    "texture type \"{other}\": expected spectrum or float (pbrt-v3: color)"
                )));
            }
        };
        let what = format!("Texture \"{}\"", class.text);
        let value = match class.text.as_str() {
            "constant" => self.value(&p, "value", Vec3::ONE, loc, &what)?,
            "scale" => {
                let (a, b) = if p.has("tex1") || p.has("tex2") {
                    (
                        self.value(&p, "tex1", Vec3::ONE, loc, &what)?,
                        self.value(&p, "tex2", Vec3::ONE, loc, &what)?,
                    )
                } else {
                    (
                        self.value(&p, "tex", Vec3::ONE, loc, &what)?,
                        self.value(&p, "scale", Vec3::ONE, loc, &what)?,
                    )
                };
                match (a, b) {
                    (TexValue::Const(x), TexValue::Const(y)) => TexValue::Const(x * y),
                    (TexValue::Map { id, factor }, TexValue::Const(c))
                    | (TexValue::Const(c), TexValue::Map { id, factor }) => TexValue::Map {
                        id,
                        factor: factor * c,
                    },
                    (m @ TexValue::Map { .. }, TexValue::Map { .. }) => {
                        self.warn(
                            loc,
                            &what,
                            "approximate: a product of two textures is drawn as the first",
                        );
                        m
                    }
                }
            }
            "imagemap" => self.imagemap(&p, loc, &what)?,
            "checkerboard" => {
                let dim = p.int("dimension", 2)?;
                if dim != 2 {
                    return Err(p
                        .loc_of("dimension")
                        .error("only a 2D checkerboard is read"));
                }
                let a = self.value(&p, "tex1", Vec3::ONE, loc, &what)?;
                let b = self.value(&p, "tex2", Vec3::ZERO, loc, &what)?;
                let constant = |v: &TexValue| match v {
                    TexValue::Const(c) => (*c, false),
                    TexValue::Map { factor, .. } => (*factor, true),
                };
                let ((a, ta), (b, tb)) = (constant(&a), constant(&b));
                if ta || tb {
                    self.warn(
                        loc,
                        &what,
                        "approximate: textured checks are drawn in their constant factors",
                    );
                }
                let (su, sv) = (p.float("uscale", 1.0)?, p.float("vscale", 1.0)?);
                let (du, dv) = (p.float("udelta", 0.0)?, p.float("vdelta", 0.0)?);
                p.skip("mapping");
                if su != sv || du != 0.0 || dv != 0.0 || su.fract() != 0.0 {
                    self.warn(loc, &what, "approximate: chiaro's checker takes one whole-number scale and no offset (uscale is used)");
                }
                // chiaro's uv has v flipped (1 - v): with an even scale the
                // parity of the cell turns, so the colours swap.
                let even = (su.round() as i64).rem_euclid(2) == 0;
                let (color_a, color_b) = if even { (b, a) } else { (a, b) };
                let id = self.scene.add_texture(Texture::Procedural(Procedural {
                    kind: ProceduralKind::Checker,
                    scale: su,
                    color_a,
                    color_b,
                    use_uv: true,
                }));
                TexValue::Map {
                    id,
                    factor: Vec3::ONE,
                }
            }
            "bilerp" | "directionmix" | "dots" | "fbm" | "marble" | "mix" | "ptex" | "windy"
            | "wrinkled" | "uv" => {
                return Err(class.loc.error(format!(
                    "texture \"{}\" is refused: chiaro reads {}",
                    class.text,
                    TEXTURES.join(", ")
                )));
            }
            other => {
                return Err(class.loc.error(format!(
                    "unknown texture \"{other}\" (chiaro reads {})",
                    TEXTURES.join(", ")
                )));
            }
        };
        self.warn_unused(loc, &what, &p);
        self.textures.insert((is_float, name.text), value);
        Ok(())
    }

    fn imagemap(&mut self, p: &Params, loc: &Loc, what: &str) -> Result<TexValue> {
        let name = p
            .string("filename")?
            .ok_or_else(|| loc.error("Texture \"imagemap\" needs a \"string filename\""))?;
        // pbrt-v4: 8-bit files are sRGB unless `encoding` says otherwise;
        // pbrt-v3: `gamma` (bool).
        let srgb = match p.string("encoding")? {
            None => p.boolean("gamma", true)?,
            Some(e) if e == "sRGB" => true,
            Some(e) if e == "linear" => false,
            Some(e) => {
                self.warn(
                    loc,
                    what,
                    &format!("approximate: encoding \"{e}\" is decoded as sRGB"),
                );
                true
            }
        };
        let path = self.resolve(&name);
        let key = format!("{}|{srgb}", path.display());
        let mut img = match self.images.get(&key) {
            Some(img) => img.clone(),
            None => {
                let img = crate::images::load_texture_within(
                    &path,
                    srgb,
                    self.scene.render.memory_budget(),
                )
                .map_err(|e| loc.error(format!("imagemap: {e}")))?;
                self.images.insert(key, img.clone());
                img
            }
        };
        img.wrap = match p.string("wrap")?.as_deref().unwrap_or("repeat") {
            "repeat" => WrapMode::Repeat,
            "clamp" => WrapMode::Clamp,
            "black" => {
                self.warn(loc, what, "approximate: wrap \"black\" is drawn clamped");
                WrapMode::Clamp
            }
            other => {
                return Err(p
                    .loc_of("wrap")
                    .error(format!("wrap \"{other}\": expected repeat, clamp or black")));
            }
        };
        img.wrap_t = None;
        let filter = p.string("filter")?;
        let trilinear = p.boolean("trilinear", false)?;
        match (filter.as_deref(), trilinear) {
            (Some("point"), _) => {
                img.mag_filter = Filter::Nearest;
                img.min_filter = Filter::Nearest;
                img.mip_filter = None;
            }
            (None | Some("bilinear"), false) => {
                img.mag_filter = Filter::Linear;
                img.min_filter = Filter::Linear;
                img.mip_filter = None;
            }
            (Some("trilinear") | None | Some("bilinear"), true) | (Some("trilinear"), false) => {
                img.mip_filter = Some(Filter::Linear);
            }
            (Some("ewa"), _) => {
                img.mip_filter = Some(Filter::Linear);
                self.warn(loc, what, "approximate: EWA filtering is drawn trilinear");
            }
            (Some(other), _) => {
                return Err(p.loc_of("filter").error(format!(
                    "filter \"{other}\": expected point, bilinear, trilinear or ewa"
                )));
            }
        }
        p.skip("maxanisotropy");
        p.skip("mapping");
        if p.boolean("invert", false)? {
            self.warn(loc, what, "approximate: invert is ignored");
        }
        let (su, sv) = (p.float("uscale", 1.0)?, p.float("vscale", 1.0)?);
        let (du, dv) = (p.float("udelta", 0.0)?, p.float("vdelta", 0.0)?);
        // pbrt looks up (s, 1 - t) with s = su u + du, t = sv v + dv, on
        // the file's uv; chiaro's meshes hold (u, 1 - v).
        img.uv_transform = UvTransform {
            offset: Vec2::new(du, 1.0 - sv - dv),
            rotation: 0.0,
            scale: Vec2::new(su, sv),
        };
        let scale = p.float("scale", 1.0)?;
        let id = self.scene.add_texture(Texture::Image(img));
        Ok(TexValue::Map {
            id,
            factor: Vec3::splat(scale),
        })
    }

    /// The chiaro material of material spec `index` (`depth` deep in
    /// `mix`es).
    pub fn build_material(&mut self, index: usize, depth: usize) -> Result<Material> {
        let spec = self.materials[index].clone();
        let loc = &spec.loc;
        if depth > 16 {
            return Err(loc.error("materials mixed more than 16 deep"));
        }
        let p = &spec.params;
        let ty = spec.ty.as_str();
        let what = match &spec.name {
            Some(n) => format!("MakeNamedMaterial \"{n}\" (\"{ty}\")"),
            None => format!("Material \"{ty}\""),
        };
        let mut m = Material {
            name: spec.name.clone().unwrap_or_else(|| {
                if loc.line == 0 {
                    "pbrt-default".to_owned()
                } else {
                    format!("{ty} {}:{}", loc.line, loc.column)
                }
            }),
            ambient: Vec3::ZERO,
            specular: Vec3::ZERO,
            // pbrt's BSDFs reflect on both sides.
            sidedness: Sidedness::TwoSided,
            ..Material::default()
        };
        let v3 = matches!(
            ty,
            "matte"
                | "metal"
                | "mirror"
                | "glass"
                | "plastic"
                | "substrate"
                | "uber"
                | "translucent"
        );
        for k in ["displacement", "bumpmap"] {
            if p.has(k) {
                self.warn(loc, &what, &format!("approximate: \"{k}\" is ignored"));
            }
        }
        if let Some(n) = p.string("normalmap")? {
            let path = self.resolve(&n);
            let img =
                crate::images::load_texture_within(&path, false, self.scene.render.memory_budget())
                    .map_err(|e| loc.error(format!("normalmap: {e}")))?;
            m.normal_map = Some(self.scene.add_texture(Texture::Image(img)));
            self.warn(
                loc,
                &what,
                "approximate: chiaro's tangent frame (from the mesh's uv) may differ from pbrt's",
            );
        }
        match ty {
            "diffuse" | "matte" => {
                let name = if ty == "diffuse" { "reflectance" } else { "Kd" };
                let r = self.value(p, name, Vec3::splat(0.5), loc, &what)?;
                set_diffuse(&mut m, r);
                if ty == "matte" && self.float_value(p, "sigma", 0.0, loc, &what)? > 0.0 {
                    self.warn(
                        loc,
                        &what,
                        "approximate: drawn Lambertian (Oren-Nayar sigma ignored)",
                    );
                }
            }
            "conductor" | "metal" | "coatedconductor" => {
                let prefix = if ty == "coatedconductor" {
                    "conductor."
                } else {
                    ""
                };
                // The complex IOR: `eta` and `k` (named spectra or values),
                // or pbrt-v4's `reflectance` r as eta = 1, k = 2 sqrt(r) /
                // sqrt(1 - r), r clamped to 0.9999 (`ConductorMaterial`).
                let (eta, k) = match p.spectrum("reflectance")? {
                    Some((s, at)) if ty != "metal" => {
                        let r = match s {
                            Spectrum::Texture(t) => match self.texture_named(&t, &at)? {
                                TexValue::Const(c) => c,
                                TexValue::Map { factor, .. } => {
                                    self.warn(loc, &what, "approximate: a textured reflectance is drawn as its constant factor");
                                    factor
                                }
                            },
                            other => self.constant_spectrum(other, &at, loc, &what)?,
                        };
                        let r = r.clamp(Vec3::ZERO, Vec3::splat(0.9999));
                        (Vec3::ONE, 2.0 * r.sqrt() / (Vec3::ONE - r).sqrt())
                    }
                    _ => (
                        self.ior_spectrum(p, &format!("{prefix}eta"), loc, &what, true)?,
                        self.ior_spectrum(p, &format!("{prefix}k"), loc, &what, false)?,
                    ),
                };
                let alpha = self.alpha(
                    p,
                    prefix,
                    if ty == "metal" { 0.01 } else { 0.0 },
                    v3,
                    loc,
                    &what,
                )?;
                m.diffuse = Vec3::ZERO;
                // The conductor's Fresnel on the mirror (smooth) or on the
                // Trowbridge-Reitz (GGX) microfacet lobe; pbrt draws alpha
                // below 1e-3 as smooth (`EffectivelySmooth`).
                m.conductor = Some(ComplexIor { eta, k });
                if alpha < 1e-3 {
                    m.reflect = Vec3::ONE;
                } else {
                    m.model = ReflectanceModel::TorranceSparrow;
                    m.distribution = Distribution::Ggx;
                    m.roughness = alpha.min(1.0);
                    m.specular = Vec3::ONE;
                }
                if ty == "coatedconductor" {
                    for k in [
                        "interface.eta",
                        "interface.roughness",
                        "interface.uroughness",
                        "interface.vroughness",
                        "thickness",
                        "albedo",
                        "g",
                        "maxdepth",
                        "nsamples",
                    ] {
                        p.skip(k);
                    }
                    self.warn(
                        loc,
                        &what,
                        "approximate: drawn as the bare conductor (the coat is ignored)",
                    );
                }
            }
            "mirror" => {
                let kr = self.value(p, "Kr", Vec3::splat(0.9), loc, &what)?;
                m.diffuse = Vec3::ZERO;
                m.reflect = self.constant_of(kr, loc, &what, "Kr");
            }
            "dielectric" | "glass" | "thindielectric" => {
                let eta = self.eta(p, if ty == "glass" { "index" } else { "eta" }, loc, &what)?;
                let alpha = self.alpha(p, "", 0.0, v3, loc, &what)?;
                m.diffuse = Vec3::ZERO;
                m.transmit = Vec3::ONE;
                if ty == "glass" {
                    let kr = self.value(p, "Kr", Vec3::ONE, loc, &what)?;
                    let kr = self.constant_of(kr, loc, &what, "Kr");
                    let kt = self.value(p, "Kt", Vec3::ONE, loc, &what)?;
                    m.transmit = self.constant_of(kt, loc, &what, "Kt");
                    if kr != Vec3::ONE {
                        self.warn(
                            loc,
                            &what,
                            "approximate: Kr is ignored (chiaro's Fresnel split reflects F)",
                        );
                    }
                }
                if ty == "thindielectric" {
                    // A thin sheet: light passes unbent; reflection sums the
                    // sheet's inter-reflections, R' = R + T^2 R / (1 - R^2).
                    let r = spectra::dielectric_f0(eta);
                    let r_thin = r + (1.0 - r) * (1.0 - r) * r / (1.0 - r * r);
                    m.ior = 1.0;
                    m.reflect = Vec3::splat(r_thin);
                    m.transmit = Vec3::splat(1.0 - r_thin);
                    self.warn(loc, &what, "approximate: fixed reflect/transmit weights from the sheet's normal-incidence reflectance (no angular Fresnel)");
                } else {
                    m.ior = eta;
                    m.fresnel = true;
                    // Rough: chiaro's rough dielectric lobe with pbrt's
                    // Trowbridge-Reitz (GGX) alpha; smooth below 1e-3.
                    if alpha >= 1e-3 {
                        m.model = ReflectanceModel::TorranceSparrow;
                        m.distribution = Distribution::Ggx;
                        m.roughness = alpha.min(1.0);
                        if alpha < MIN_ROUGH_ALPHA {
                            self.warn(loc, &what, &format!("approximate: an alpha below {MIN_ROUGH_ALPHA} is drawn as a smooth dielectric"));
                        }
                    }
                }
            }
            "coateddiffuse" | "substrate" | "plastic" | "uber" => {
                let (kd_name, kd_default) = match ty {
                    "coateddiffuse" => ("reflectance", 0.5),
                    "substrate" => ("Kd", 0.5),
                    _ => ("Kd", 0.25),
                };
                let r = self.value(p, kd_name, Vec3::splat(kd_default), loc, &what)?;
                set_diffuse(&mut m, r);
                let default_rough = if ty == "coateddiffuse" { 0.0 } else { 0.1 };
                let alpha = self.alpha(p, "", default_rough, v3, loc, &what)?;
                // The coat's colour at normal incidence: F(0) of its IOR
                // (v4), pbrt-v3's Ks (substrate: Schlick's F0 itself).
                let f0 = match ty {
                    "coateddiffuse" => {
                        let eta = self.eta(p, "eta", loc, &what)?;
                        for k in ["thickness", "albedo", "g", "maxdepth", "nsamples"] {
                            p.skip(k);
                        }
                        Vec3::splat(spectra::dielectric_f0(eta))
                    }
                    "substrate" => {
                        let ks = self.value(p, "Ks", Vec3::splat(0.5), loc, &what)?;
                        self.constant_of(ks, loc, &what, "Ks")
                    }
                    _ => {
                        let ks = self.value(p, "Ks", Vec3::splat(0.25), loc, &what)?;
                        let eta = if ty == "uber" {
                            self.eta(p, "index", loc, &what)?
                        } else {
                            1.5
                        };
                        self.constant_of(ks, loc, &what, "Ks") * spectra::dielectric_f0(eta)
                    }
                };
                if ty == "uber" {
                    let kr = self.value(p, "Kr", Vec3::ZERO, loc, &what)?;
                    m.reflect = self.constant_of(kr, loc, &what, "Kr");
                    let kt = self.value(p, "Kt", Vec3::ZERO, loc, &what)?;
                    m.transmit = self.constant_of(kt, loc, &what, "Kt");
                    m.ior = 1.0;
                    if p.has("opacity") {
                        self.warn(loc, &what, "approximate: opacity is ignored");
                    }
                }
                if alpha < 1e-3 {
                    m.reflect += f0;
                    self.warn(loc, &what, "approximate: diffuse base plus a fixed mirror weight F(0) (no Fresnel angle dependence or interreflection in the coat)");
                } else {
                    m.model = ReflectanceModel::TorranceSparrow;
                    m.distribution = Distribution::Ggx;
                    m.roughness = alpha.clamp(1e-3, 1.0);
                    m.specular = f0;
                    self.warn(loc, &what, "approximate: diffuse base plus a microfacet coat with Schlick's Fresnel (no interreflection in the coat)");
                }
            }
            "diffusetransmission" | "translucent" => {
                let (rn, tn, d) = if ty == "translucent" {
                    ("reflect", "transmit", 0.5)
                } else {
                    ("reflectance", "transmittance", 0.25)
                };
                let r = self.value(p, rn, Vec3::splat(d), loc, &what)?;
                let t = self.value(p, tn, Vec3::splat(d), loc, &what)?;
                let scale = p.float("scale", 1.0)?;
                let r = self.constant_of(r, loc, &what, rn);
                let t = self.constant_of(t, loc, &what, tn);
                if ty == "translucent" {
                    let kd = self.value(p, "Kd", Vec3::splat(0.25), loc, &what)?;
                    let kd = self.constant_of(kd, loc, &what, "Kd");
                    for k in ["Ks", "roughness", "remaproughness"] {
                        p.skip(k);
                    }
                    m.diffuse = kd * r;
                    m.transmit = kd * t;
                } else {
                    m.diffuse = r * scale;
                    m.transmit = t * scale;
                }
                m.ior = 1.0;
                self.warn(loc, &what, "approximate: the transmitted part passes straight through (chiaro has no diffuse transmission)");
            }
            "interface" | "" | "none" => {
                m.diffuse = Vec3::ZERO;
                m.transmit = Vec3::ONE;
                m.ior = 1.0;
                self.warn(
                    loc,
                    &what,
                    "approximate: an invisible surface is drawn as a clear sheet of IOR 1",
                );
            }
            "mix" => {
                let names = p.strings("materials")?.ok_or_else(|| {
                    loc.error("Material \"mix\" needs \"string materials\" [two names]")
                })?;
                let [a, b] = names.as_slice() else {
                    return Err(p.loc_of("materials").error(format!(
                        "\"materials\" names two materials, found {}",
                        names.len()
                    )));
                };
                let find = |n: &str| {
                    self.named_materials.get(n).copied().ok_or_else(|| {
                        p.loc_of("materials").error(format!(
                            "no material named \"{n}\" is defined before this line"
                        ))
                    })
                };
                let (ia, ib) = (find(a)?, find(b)?);
                let amount = self
                    .float_value(p, "amount", 0.5, loc, &what)?
                    .clamp(0.0, 1.0);
                let ma = self.build_material(ia, depth + 1)?;
                let mb = self.build_material(ib, depth + 1)?;
                let lambert = |m: &Material| {
                    m.specular == Vec3::ZERO
                        && m.reflect == Vec3::ZERO
                        && m.transmit == Vec3::ZERO
                        && m.texture.is_none()
                };
                // pbrt picks the second material with probability `amount`.
                let mut out = if amount < 0.5 { ma.clone() } else { mb.clone() };
                if lambert(&ma) && lambert(&mb) {
                    out.diffuse = ma.diffuse.lerp(mb.diffuse, amount);
                } else {
                    let which = if amount < 0.5 { "first" } else { "second" };
                    self.warn(loc, &what, &format!("approximate: only a mix of two diffuse materials maps; the {which} (the larger weight) is used"));
                }
                out.name = m.name.clone();
                m = out;
            }
            "measured" | "hair" | "subsurface" | "kdsubsurface" | "fourier" | "disney" => {
                return Err(loc.error(format!(
                    "material \"{ty}\" is refused: chiaro reads {}",
                    MATERIALS.join(", ")
                )));
            }
            other => {
                return Err(loc.error(format!(
                    "unknown material \"{other}\" (chiaro reads {})",
                    MATERIALS.join(", ")
                )));
            }
        }
        p.skip("type");
        self.warn_unused(loc, &what, p);
        Ok(m)
    }

    /// A constant, or a texture's factor with a warning (where chiaro's
    /// material takes no texture).
    fn constant_of(&mut self, v: TexValue, loc: &Loc, what: &str, name: &str) -> Vec3 {
        match v {
            TexValue::Const(c) => c,
            TexValue::Map { factor, .. } => {
                self.warn(
                    loc,
                    what,
                    &format!(
                        "approximate: the texture of \"{name}\" is drawn as its constant factor"
                    ),
                );
                factor
            }
        }
    }

    /// The microfacet alpha of `roughness` (or the mean of `uroughness` and
    /// `vroughness`), remapped as pbrt-v4 (`sqrt`) or pbrt-v3 does.
    fn alpha(
        &mut self,
        p: &Params,
        prefix: &str,
        default: f32,
        v3: bool,
        loc: &Loc,
        what: &str,
    ) -> Result<f32> {
        let r = self.float_value(p, &format!("{prefix}roughness"), default, loc, what)?;
        let u = self.float_value(p, &format!("{prefix}uroughness"), r, loc, what)?;
        let v = self.float_value(p, &format!("{prefix}vroughness"), r, loc, what)?;
        if (u - v).abs() > 1e-6 {
            self.warn(loc, what, "approximate: anisotropic roughness drawn isotropic (the mean of uroughness and vroughness)");
        }
        let r = 0.5 * (u + v);
        if r <= 0.0 {
            return Ok(0.0);
        }
        let remap = p.boolean("remaproughness", true)?;
        Ok(match (remap, v3) {
            (false, _) => r,
            (true, false) => r.sqrt(),
            (true, true) => v3_alpha(r),
        })
    }

    /// A dielectric's IOR: a float, or a named glass (its d-line index).
    fn eta(&mut self, p: &Params, name: &str, loc: &Loc, what: &str) -> Result<f32> {
        let eta = match p.spectrum(name)? {
            None => 1.5,
            Some((Spectrum::Rgb(c), _)) => c.x,
            Some((Spectrum::Named(n), at)) => {
                let (_, v) = GLASSES.iter().find(|(g, _)| *g == n).ok_or_else(|| {
                    at.error(format!(
                        "unknown glass spectrum \"{n}\" (chiaro knows {})",
                        GLASSES.iter().map(|g| g.0).collect::<Vec<_>>().join(", ")
                    ))
                })?;
                self.warn(
                    loc,
                    what,
                    "approximate: the named glass is drawn at its d-line index (no dispersion)",
                );
                *v
            }
            Some((Spectrum::Pairs(pairs), _)) => {
                self.warn(
                    loc,
                    what,
                    "approximate: a sampled IOR spectrum is drawn at its mean (no dispersion)",
                );
                pairs.iter().map(|p| p.1).sum::<f32>() / pairs.len().max(1) as f32
            }
            Some((Spectrum::Texture(t), at)) => match self.float_texture(&t, &at)? {
                TexValue::Const(c) => c.x,
                TexValue::Map { factor, .. } => factor.x,
            },
            Some((_, at)) => {
                return Err(at.error(format!("\"{name}\" must be a number or a named glass")));
            }
        };
        if !(eta.is_finite() && eta > 0.0) {
            return Err(p
                .loc_of(name)
                .error(format!("{name} = {eta} is not a positive number")));
        }
        // pbrt treats eta 1 as no interface at all.
        Ok(eta)
    }

    /// A conductor's `eta` (`is_eta`) or `k` as RGB: a named metal, an
    /// RGB or float, or pbrt's default copper.
    fn ior_spectrum(
        &mut self,
        p: &Params,
        name: &str,
        loc: &Loc,
        what: &str,
        is_eta: bool,
    ) -> Result<Vec3> {
        let pick = |(eta, k, _): (Vec3, Vec3, bool)| if is_eta { eta } else { k };
        match p.spectrum(name)? {
            None => Ok(metal("metal-Cu-eta").map(pick).unwrap_or(Vec3::ONE)),
            Some((Spectrum::Named(n), at)) => metal(&n).map(pick).ok_or_else(|| {
                at.error(format!(
                    "unknown metal spectrum \"{n}\" (chiaro knows metal-NAME-eta and metal-NAME-k for NAME in {})",
                    spectra::conductor_names().join(", ")
                ))
            }),
            Some((Spectrum::Texture(t), at)) => match self.texture_named(&t, &at)? {
                TexValue::Const(c) => Ok(c),
                TexValue::Map { factor, .. } => Ok(factor),
            },
            Some((other, at)) => self.constant_spectrum(other, &at, loc, what),
        }
    }
}

/// The diffuse colour of a material from a value.
fn set_diffuse(m: &mut Material, v: TexValue) {
    match v {
        TexValue::Const(c) => m.diffuse = c,
        TexValue::Map { id, factor } => {
            m.diffuse = factor;
            m.texture = Some(id);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blackbody_colours() {
        let warm = blackbody_rgb(2700.0).expect("2700 K");
        let d65ish = blackbody_rgb(6500.0).expect("6500 K");
        assert!(warm.x > warm.y && warm.y > warm.z, "{warm}");
        // Near 6500 K a blackbody is near white.
        assert!(
            (d65ish / d65ish.max_element()).min_element() > 0.8,
            "{d65ish}"
        );
        let lum = 0.2126 * d65ish.x + 0.7152 * d65ish.y + 0.0722 * d65ish.z;
        assert!((lum - 1.0).abs() < 0.02, "{lum}");
        assert!(blackbody_rgb(-1.0).is_none());
    }

    #[test]
    fn named_metals_and_v3_roughness() {
        let (eta, k, is_eta) = metal("metal-Cu-eta").expect("copper");
        assert!(is_eta && eta.x < eta.z && k.x > k.z);
        assert!(metal("metal-Cu-x").is_none() && metal("Cu").is_none());
        // pbrt-v3's remap is increasing and near 1 at r = 1.
        assert!((v3_alpha(1.0) - 1.62142).abs() < 1e-5);
        assert!(v3_alpha(0.01) < v3_alpha(0.1));
    }
}
