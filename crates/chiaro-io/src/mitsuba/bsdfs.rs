//! `<bsdf>` plugins as chiaro materials, and the textures their
//! parameters take (`bitmap`, `checkerboard`, `mesh_attribute`).
//!
//! chiaro's material is one set of coefficients: Lambert `kd`, a glossy
//! Torrance-Sparrow lobe with Schlick's Fresnel from `ks` (F0), a fixed
//! mirror weight `kr`, the Fresnel of a conductor's complex IOR on both
//! (`Material::conductor`), and Fresnel-split glass. Mitsuba's `diffuse`,
//! `conductor`, `roughconductor`, `dielectric` and `roughdielectric` (on
//! the rough dielectric lobe) land on it exactly; the rest are
//! approximations, each saying so once.

use super::Builder;
use super::props::{Props, numbers};
use super::spectra;
use super::xml::Element;
use crate::Result;
use chiaro_core::scene::{
    Bump, ComplexIor, Distribution, Filter, Material, MaterialId, Procedural, ProceduralKind,
    ReflectanceModel, Sidedness, Texture, TextureId, UvTransform, WrapMode,
};
use chiaro_core::shading::dielectric::MIN_ROUGH_ALPHA;
use chiaro_core::{Mat4, Vec2, Vec3};

/// The BSDF plugins this module reads.
pub const BSDF_TYPES: &[&str] = &[
    "diffuse",
    "roughdiffuse",
    "conductor",
    "roughconductor",
    "dielectric",
    "roughdielectric",
    "thindielectric",
    "plastic",
    "roughplastic",
    "twosided",
    "normalmap",
    "bumpmap",
    "mask",
    "blendbsdf",
    "principled",
    "null",
];

/// The texture plugins this module reads.
pub const TEXTURE_TYPES: &[&str] = &["bitmap", "checkerboard", "mesh_attribute"];

/// A spectrum-valued parameter: a constant, a texture, or a per-vertex or
/// per-face attribute of the mesh it is used on.
#[derive(Debug, Clone, PartialEq)]
pub enum Value {
    /// One RGB value.
    Const(Vec3),
    /// A texture (times 1).
    Texture(TextureId),
    /// Mitsuba's `mesh_attribute` texture: the mesh's attribute of this name.
    Attribute(String),
}

impl Value {
    /// The constant, or `fallback` for a texture or an attribute.
    pub fn constant_or(&self, fallback: Vec3) -> Vec3 {
        match self {
            Value::Const(c) => *c,
            _ => fallback,
        }
    }
}

/// A material with what the shapes using it must supply.
#[derive(Debug, Clone, PartialEq)]
pub struct Built {
    /// The material.
    pub material: Material,
    /// The mesh attribute giving the diffuse colour (`vertex_color`,
    /// `face_color`), which the shape turns into vertex colours.
    pub attribute: Option<AttributeUse>,
}

/// How a mesh attribute feeds the diffuse colour.
#[derive(Debug, Clone, PartialEq)]
pub enum AttributeUse {
    /// The attribute is the reflectance.
    Color(String),
    /// `blendbsdf` of two diffuse colours by a scalar attribute:
    /// `(1 - w) a + w b`.
    Blend { weight: String, a: Vec3, b: Vec3 },
}

impl Builder<'_> {
    /// The material of a shape's BSDF element (an inline `<bsdf>` or a
    /// `<ref>` to one), added to the scene once per declared id.
    pub fn material_of(&mut self, el: &Element) -> Result<(MaterialId, Built)> {
        let (target, key) = if el.tag == "ref" {
            let t = self.lookup(el)?;
            if t.tag != "bsdf" {
                return Err(el.loc.error(format!(
                    "<ref id=\"{}\"> names a <{}>, where a <bsdf> was expected",
                    el.attr("id").unwrap_or_default(),
                    t.tag
                )));
            }
            (t, format!("bsdf:{}", el.attr("id").unwrap_or_default()))
        } else {
            // An inline BSDF is one material however often its shape is
            // placed (a shape group instanced several times).
            (el, format!("at:{}", el.loc.describe()))
        };
        if let Some((id, built)) = self.built.get(&key) {
            return Ok((*id, built.clone()));
        }
        let mut built = self.bsdf(target, 0)?;
        if built.material.name == "default" || built.material.name.is_empty() {
            built.material.name = target.attr("id").map_or_else(
                || format!("{}@{}", target.plugin_name(), target.loc.line),
                str::to_owned,
            );
        }
        let id = self.scene.add_material(built.material.clone());
        self.built.insert(key, (id, built.clone()));
        Ok((id, built))
    }

    /// Maps one `<bsdf>` (depth counts nesting, bounded).
    fn bsdf(&mut self, el: &Element, depth: usize) -> Result<Built> {
        if depth > 32 {
            return Err(el.loc.error("BSDFs nested more than 32 deep"));
        }
        let el = self.plugin_of(el, "bsdf")?;
        let ty = Self::plugin_type(el)?;
        let p = Props::new(el);
        let mut m = Material {
            name: el.attr("id").unwrap_or_default().to_owned(),
            ambient: Vec3::ZERO,
            specular: Vec3::ZERO,
            // Mitsuba's BSDFs are one-sided: the back face is black (the
            // dielectrics, `null` and `twosided` say otherwise below).
            sidedness: Sidedness::OneSided,
            ..Material::default()
        };
        let mut attribute = None;
        match ty {
            "diffuse" | "roughdiffuse" => {
                if ty == "roughdiffuse" {
                    self.warn(
                        el,
                        "approximate: drawn Lambertian (Oren-Nayar roughness ignored)",
                    );
                    let _ = p.named("alpha");
                    let _ = p.string("distribution")?;
                    let _ = p.boolean("use_fast_approx", false)?;
                }
                let r = self.value(&p, "reflectance", Vec3::splat(0.5))?;
                attribute = self.set_diffuse(&mut m, r);
            }
            "conductor" | "roughconductor" => {
                // Mitsuba's F = specular_reflectance x the conductor's
                // Fresnel: the tint goes to kr (smooth) or ks (rough).
                let (eta, k) = self.conductor_ior(el, &p)?;
                let tint = self
                    .value(&p, "specular_reflectance", Vec3::ONE)?
                    .constant_or(Vec3::ONE);
                m.diffuse = Vec3::ZERO;
                // Mitsuba's ideal mirror `none` (eta 0, k 1) reflects 1 at
                // every angle: chiaro's plain kr.
                m.conductor =
                    ((eta, k) != (Vec3::ZERO, Vec3::ONE)).then_some(ComplexIor { eta, k });
                if ty == "conductor" {
                    m.reflect = tint;
                } else {
                    self.rough(el, &p, &mut m)?;
                    m.specular = tint;
                    if m.distribution == Distribution::Beckmann {
                        self.warn(el, "approximate: Beckmann masking by Walter et al.'s rational fit of Smith's G1 (Mitsuba evaluates it exactly)");
                    }
                }
            }
            "dielectric" | "roughdielectric" | "thindielectric" => {
                let eta = self.ior_ratio(el, &p, "bk7")?;
                let refl = self
                    .value(&p, "specular_reflectance", Vec3::ONE)?
                    .constant_or(Vec3::ONE);
                let trans = self
                    .value(&p, "specular_transmittance", Vec3::ONE)?
                    .constant_or(Vec3::ONE);
                if refl != Vec3::ONE {
                    self.warn(el, "approximate: specular_reflectance is ignored (chiaro's Fresnel split reflects F)");
                }
                m.diffuse = Vec3::ZERO;
                m.transmit = trans;
                m.sidedness = Sidedness::TwoSided;
                match ty {
                    "dielectric" => {
                        m.ior = eta;
                        m.fresnel = true;
                    }
                    "roughdielectric" => {
                        // chiaro's rough dielectric lobe (Walter et al. 2007):
                        // a Fresnel dielectric with a Torrance-Sparrow alpha.
                        m.ior = eta;
                        m.fresnel = true;
                        self.rough(el, &p, &mut m)?;
                        if m.distribution == Distribution::Beckmann {
                            self.warn(el, "approximate: Beckmann masking by Walter et al.'s rational fit of Smith's G1 (Mitsuba evaluates it exactly)");
                        }
                        if m.roughness < MIN_ROUGH_ALPHA {
                            self.warn(el, &format!("approximate: an alpha below {MIN_ROUGH_ALPHA} is drawn as a smooth dielectric"));
                        }
                    }
                    _ => {
                        // A thin sheet: light passes unbent; reflection sums the
                        // sheet's inter-reflections, R' = R + T^2 R / (1 - R^2).
                        let r = spectra::dielectric_f0(eta);
                        let r_thin = r + (1.0 - r) * (1.0 - r) * r / (1.0 - r * r);
                        m.ior = 1.0;
                        m.fresnel = false;
                        m.reflect = Vec3::splat(r_thin) * refl;
                        m.transmit = Vec3::splat(1.0 - r_thin) * trans;
                        self.warn(el, "approximate: fixed reflect/transmit weights from the sheet's normal-incidence reflectance (no angular Fresnel)");
                    }
                }
            }
            "plastic" | "roughplastic" => {
                let eta = self.ior_ratio(el, &p, "polypropylene")?;
                let r = self.value(&p, "diffuse_reflectance", Vec3::splat(0.5))?;
                attribute = self.set_diffuse(&mut m, r);
                let ks = self
                    .value(&p, "specular_reflectance", Vec3::ONE)?
                    .constant_or(Vec3::ONE);
                let f0 = spectra::dielectric_f0(eta);
                let _ = p.boolean("nonlinear", false)?;
                if ty == "plastic" {
                    m.reflect = Vec3::splat(f0) * ks;
                    self.warn(el, "approximate: diffuse base plus a fixed mirror weight F(0) (no Fresnel angle dependence or internal scattering)");
                } else {
                    self.rough(el, &p, &mut m)?;
                    m.specular = Vec3::splat(f0) * ks;
                    self.warn(el, "approximate: diffuse base plus a microfacet coat with Schlick's Fresnel (no internal scattering)");
                }
            }
            "twosided" => {
                let all = p.nested_bsdfs(ty)?;
                if all.len() == 2 {
                    self.warn(el, "approximate: a different back BSDF is ignored; the front one is used on both sides");
                }
                let front = all[0];
                let mut b = self.bsdf(front, depth + 1)?;
                b.material.sidedness = Sidedness::TwoSided;
                self.warn_unused(&p);
                return Ok(b);
            }
            "normalmap" | "bumpmap" => {
                let inner = p.nested_bsdfs(ty)?[0];
                let mut b = self.bsdf(inner, depth + 1)?;
                let map = match p
                    .named("normalmap")
                    .or_else(|| p.children("texture").first().copied())
                {
                    Some(t) => t,
                    None => {
                        return Err(el
                            .loc
                            .error(format!("<bsdf type=\"{ty}\"> needs a <texture>")));
                    }
                };
                let tex = self.texture_id(map, true)?;
                if ty == "normalmap" {
                    b.material.normal_map = Some(tex);
                    self.warn(el, "approximate: chiaro's tangent frame (from the mesh's uv) may differ from Mitsuba's");
                } else {
                    let scale = p.float("scale", 1.0)?;
                    b.material.bump = Some(Bump {
                        texture: tex,
                        height: scale,
                    });
                    self.warn(el, "approximate: chiaro's bump map (height from the texture's luminance) may differ from Mitsuba's");
                }
                self.warn_unused(&p);
                return Ok(b);
            }
            "mask" => {
                let inner = p.nested_bsdfs(ty)?[0];
                let mut b = self.bsdf(inner, depth + 1)?;
                let opacity = self.value(&p, "opacity", Vec3::splat(0.5))?;
                match opacity {
                    Value::Const(o) => {
                        b.material.alpha = o.x.clamp(0.0, 1.0);
                        b.material.alpha_mode = chiaro_core::scene::AlphaMode::Blend;
                        self.warn(
                            el,
                            "approximate: a constant opacity is drawn as alpha BLEND",
                        );
                    }
                    _ => {
                        self.warn(
                            el,
                            "approximate: a textured opacity is ignored (the surface is opaque)",
                        );
                    }
                }
                self.warn_unused(&p);
                return Ok(b);
            }
            "blendbsdf" => {
                let inner: Vec<&Element> = p
                    .children("bsdf")
                    .into_iter()
                    .chain(p.children("ref"))
                    .collect();
                let [a, b] = inner.as_slice() else {
                    return Err(el
                        .loc
                        .error("<bsdf type=\"blendbsdf\"> needs two nested BSDFs"));
                };
                let a = self.bsdf(a, depth + 1)?;
                let b = self.bsdf(b, depth + 1)?;
                let w = self.value(&p, "weight", Vec3::splat(0.5))?;
                let both_diffuse = [&a.material, &b.material].iter().all(|m| {
                    m.specular == Vec3::ZERO
                        && m.reflect == Vec3::ZERO
                        && m.transmit == Vec3::ZERO
                        && m.texture.is_none()
                }) && a.attribute.is_none()
                    && b.attribute.is_none();
                let mut out = a.clone();
                match (w, both_diffuse) {
                    (Value::Const(w), true) => {
                        // A blend of two Lambertian BRDFs is the Lambertian of the blended albedo.
                        out.material.diffuse = a.material.diffuse.lerp(b.material.diffuse, w.x);
                    }
                    (Value::Attribute(name), true) => {
                        out.material.diffuse = Vec3::ONE;
                        out.attribute = Some(AttributeUse::Blend {
                            weight: name,
                            a: a.material.diffuse,
                            b: b.material.diffuse,
                        });
                    }
                    _ => {
                        self.warn(el, "approximate: only a blend of two diffuse BSDFs maps; the first BSDF is used");
                    }
                }
                self.warn_unused(&p);
                return Ok(out);
            }
            "principled" => {
                let base = self.value(&p, "base_color", Vec3::splat(0.8))?;
                let metallic = p.float("metallic", 0.0)?;
                let rough = p.float("roughness", 0.5)?;
                let (kd, ks, alpha) = chiaro_core::scene::MetallicRoughness::coefficients(
                    base.constant_or(Vec3::ONE),
                    metallic,
                    rough,
                );
                attribute = self.set_diffuse(&mut m, base);
                if m.texture.is_none() && attribute.is_none() {
                    m.diffuse = kd;
                }
                m.specular = ks;
                m.roughness = alpha;
                m.model = ReflectanceModel::TorranceSparrow;
                m.distribution = Distribution::Ggx;
                self.warn(el, "approximate: drawn as glTF metallic-roughness (base_color, metallic, roughness); other parameters are ignored");
                self.warn_unused(&p);
                return Ok(Built {
                    material: m,
                    attribute,
                });
            }
            "null" => {
                m.diffuse = Vec3::ZERO;
                m.transmit = Vec3::ONE;
                m.ior = 1.0;
                m.sidedness = Sidedness::TwoSided;
                self.warn(
                    el,
                    "approximate: an invisible surface is drawn as a clear sheet of IOR 1",
                );
            }
            other => {
                return Err(el.loc.error(format!(
                    "unknown bsdf plugin \"{other}\" (chiaro reads: {})",
                    BSDF_TYPES.join(", ")
                )));
            }
        }
        self.warn_unused(&p);
        Ok(Built {
            material: m,
            attribute,
        })
    }

    /// Sets the diffuse colour from a value; an attribute is returned for
    /// the shape to supply as vertex colours.
    fn set_diffuse(&mut self, m: &mut Material, v: Value) -> Option<AttributeUse> {
        match v {
            Value::Const(c) => {
                m.diffuse = c;
                None
            }
            Value::Texture(t) => {
                m.diffuse = Vec3::ONE;
                m.texture = Some(t);
                None
            }
            Value::Attribute(name) => {
                m.diffuse = Vec3::ONE;
                Some(AttributeUse::Color(name))
            }
        }
    }

    /// `alpha` (or `alpha_u`/`alpha_v`, averaged) and `distribution` of a
    /// rough BSDF onto the Torrance-Sparrow lobe.
    fn rough(&mut self, el: &Element, p: &Props, m: &mut Material) -> Result<()> {
        let alpha = match (p.named("alpha_u"), p.named("alpha_v")) {
            (Some(_), _) | (_, Some(_)) => {
                let u = p.float("alpha_u", 0.1)?;
                let v = p.float("alpha_v", 0.1)?;
                if (u - v).abs() > 1e-6 {
                    self.warn(el, "approximate: anisotropic roughness drawn isotropic (the mean of alpha_u and alpha_v)");
                }
                0.5 * (u + v)
            }
            _ => match self.value(p, "alpha", Vec3::splat(0.1))? {
                Value::Const(a) => a.x,
                _ => {
                    self.warn(el, "approximate: a textured alpha is drawn at 0.1");
                    0.1
                }
            },
        };
        m.model = ReflectanceModel::TorranceSparrow;
        m.roughness = alpha.clamp(1e-3, 1.0);
        m.distribution = match p.string("distribution")?.unwrap_or("beckmann") {
            "beckmann" => Distribution::Beckmann,
            "ggx" => Distribution::Ggx,
            other => {
                return Err(el.loc.error(format!(
                    "unknown distribution \"{other}\" (expected beckmann or ggx)"
                )));
            }
        };
        let _ = p.boolean("sample_visible", true)?;
        Ok(())
    }

    /// A conductor's RGB `(eta, k)`: `material` by name, else `eta` and `k`
    /// values; Mitsuba's default is the ideal mirror `none`.
    fn conductor_ior(&mut self, el: &Element, p: &Props) -> Result<(Vec3, Vec3)> {
        if let Some(name) = p.string("material")? {
            let named = spectra::conductor(name).ok_or_else(|| {
                el.loc.error(format!(
                    "unknown conductor material \"{name}\" (chiaro knows: {})",
                    spectra::conductor_names().join(", ")
                ))
            })?;
            return Ok(named);
        }
        if p.named("eta").is_none() && p.named("k").is_none() {
            return Ok(spectra::conductor("none").unwrap_or((Vec3::ZERO, Vec3::ONE)));
        }
        let eta = self.value(p, "eta", Vec3::ZERO)?.constant_or(Vec3::ZERO);
        let k = self.value(p, "k", Vec3::ONE)?.constant_or(Vec3::ONE);
        Ok((eta, k))
    }

    /// `int_ior / ext_ior` (numbers or Mitsuba's names).
    fn ior_ratio(&mut self, el: &Element, p: &Props, default_int: &str) -> Result<f32> {
        let int = match p.named("int_ior") {
            Some(e) => ior_of(e)?,
            None => spectra::ior(default_int).unwrap_or(1.5),
        };
        let ext = match p.named("ext_ior") {
            Some(e) => ior_of(e)?,
            None => spectra::ior("air").unwrap_or(1.0),
        };
        let eta = int / ext;
        if !(eta.is_finite() && eta > 0.0) {
            return Err(el.loc.error(format!(
                "int_ior / ext_ior = {eta} is not a positive number"
            )));
        }
        Ok(eta)
    }

    /// A spectrum-valued parameter by name (`<rgb>`, `<spectrum>`,
    /// `<float>`, a nested `<texture>` or a `<ref>` to one), else `default`.
    pub fn value(&mut self, p: &Props, name: &str, default: Vec3) -> Result<Value> {
        let Some(e) = p.named(name) else {
            return Ok(Value::Const(default));
        };
        self.value_of(e)
    }

    /// The value of one parameter element.
    pub fn value_of(&mut self, e: &Element) -> Result<Value> {
        match e.tag.as_str() {
            "rgb" => {
                let v = e.require("value")?;
                match numbers(e, v)?.as_slice() {
                    [x] => Ok(Value::Const(Vec3::splat(*x))),
                    [r, g, b] => Ok(Value::Const(Vec3::new(*r, *g, *b))),
                    _ => Err(e
                        .loc
                        .error(format!("<rgb>: expected one or three numbers, found {v:?}"))),
                }
            }
            "float" => Ok(Value::Const(Vec3::splat(super::props::number(
                e,
                e.require("value")?,
            )?))),
            "spectrum" => {
                if e.attr("filename").is_some() {
                    return Err(e
                        .loc
                        .error("<spectrum filename=...> is refused: give an <rgb> value"));
                }
                let v = e.require("value")?;
                if v.contains(':') {
                    // Wavelength:value pairs: their mean, as a grey.
                    let mut vals = Vec::new();
                    for pair in v.split(',') {
                        let Some((_, x)) = pair.split_once(':') else {
                            return Err(e.loc.error(format!(
                                "<spectrum>: expected \"wavelength:value, ...\", found {v:?}"
                            )));
                        };
                        vals.push(super::props::number(e, x)?);
                    }
                    let mean = vals.iter().sum::<f32>() / vals.len().max(1) as f32;
                    self.warn(
                        e,
                        "approximate: a sampled spectrum is drawn as the grey of its mean",
                    );
                    return Ok(Value::Const(Vec3::splat(mean)));
                }
                match numbers(e, v)?.as_slice() {
                    [x] => Ok(Value::Const(Vec3::splat(*x))),
                    _ => Err(e
                        .loc
                        .error(format!("<spectrum>: expected one number, found {v:?}"))),
                }
            }
            "texture" => self.texture_value(e),
            "ref" => {
                let t = self.lookup(e)?;
                if t.tag != "texture" {
                    return Err(e.loc.error(format!(
                        "<ref> names a <{}>, where a <texture> was expected",
                        t.tag
                    )));
                }
                self.texture_value(t)
            }
            other => Err(e.loc.error(format!(
                "`{}` must be an <rgb>, <spectrum>, <float> or <texture>, found <{other}>",
                e.attr("name").unwrap_or_default()
            ))),
        }
    }

    fn texture_value(&mut self, e: &Element) -> Result<Value> {
        if Self::plugin_type(e)? == "mesh_attribute" {
            let p = Props::new(e);
            let name = p.string("name")?.ok_or_else(|| {
                e.loc
                    .error("<texture type=\"mesh_attribute\"> needs a <string name=\"name\">")
            })?;
            let _ = p.float("scale", 1.0)?;
            self.warn_unused(&p);
            return Ok(Value::Attribute(name.to_owned()));
        }
        Ok(Value::Texture(self.texture_id(e, false)?))
    }

    /// A `bitmap` or `checkerboard` texture added to the scene (`raw`
    /// forces linear data for normal and bump maps).
    pub fn texture_id(&mut self, e: &Element, raw_data: bool) -> Result<TextureId> {
        let e = self.plugin_of(e, "texture")?;
        let ty = Self::plugin_type(e)?;
        let p = Props::new(e);
        let uv = p.transform("to_uv")?;
        let tex = match ty {
            "bitmap" => {
                let name = p.string("filename")?.ok_or_else(|| {
                    e.loc
                        .error("<texture type=\"bitmap\"> needs a <string name=\"filename\">")
                })?;
                let raw = p.boolean("raw", false)? || raw_data;
                let path = self.resolve(name);
                let key = format!("{}|{raw}", path.display());
                let mut img = match self.images.get(&key) {
                    Some(img) => img.clone(),
                    None => {
                        let img = crate::images::load_texture_within(
                            &path,
                            !raw,
                            self.scene.render.memory_budget(),
                        )
                        .map_err(|err| e.loc.error(format!("bitmap: {err}")))?;
                        self.images.insert(key, img.clone());
                        img
                    }
                };
                let filter = match p.string("filter_type")?.unwrap_or("bilinear") {
                    "bilinear" => Filter::Linear,
                    "nearest" => Filter::Nearest,
                    other => {
                        return Err(e.loc.error(format!(
                            "unknown filter_type \"{other}\" (expected bilinear or nearest)"
                        )));
                    }
                };
                img.wrap = match p.string("wrap_mode")?.unwrap_or("repeat") {
                    "repeat" => WrapMode::Repeat,
                    "mirror" => WrapMode::Mirror,
                    "clamp" => WrapMode::Clamp,
                    other => {
                        return Err(e.loc.error(format!(
                            "unknown wrap_mode \"{other}\" (expected repeat, mirror or clamp)"
                        )));
                    }
                };
                img.wrap_t = None;
                // Mitsuba looks up level 0 only, bilinear or nearest.
                img.mag_filter = filter;
                img.min_filter = filter;
                img.mip_filter = None;
                img.uv_transform = self.uv_transform(e, uv);
                let _ = p.string("format")?;
                let _ = p.boolean("accel", true)?;
                Texture::Image(img)
            }
            "checkerboard" => {
                let c0 = self
                    .value(&p, "color0", Vec3::splat(0.4))?
                    .constant_or(Vec3::splat(0.4));
                let c1 = self
                    .value(&p, "color1", Vec3::splat(0.2))?
                    .constant_or(Vec3::splat(0.2));
                if uv != Mat4::IDENTITY {
                    self.warn(
                        e,
                        "approximate: to_uv is ignored (chiaro's checker has no uv transform)",
                    );
                }
                Texture::Procedural(Procedural {
                    kind: ProceduralKind::Checker,
                    // Mitsuba's checks are half a uv unit.
                    scale: 2.0,
                    color_a: c0,
                    color_b: c1,
                    use_uv: true,
                })
            }
            "mesh_attribute" => {
                return Err(e.loc.error("a mesh_attribute texture is only read as a diffuse reflectance or a blendbsdf weight"));
            }
            other => {
                return Err(e.loc.error(format!(
                    "unknown texture plugin \"{other}\" (chiaro reads: {})",
                    TEXTURE_TYPES.join(", ")
                )));
            }
        };
        self.warn_unused(&p);
        Ok(self.scene.add_texture(tex))
    }

    /// Mitsuba's `to_uv` (its 2D part: the upper-left 2x2 and the x, y
    /// translation) as chiaro's scale-rotate-offset; a shear is warned.
    fn uv_transform(&mut self, e: &Element, m: Mat4) -> UvTransform {
        let c0 = Vec2::new(m.x_axis.x, m.x_axis.y);
        let c1 = Vec2::new(m.y_axis.x, m.y_axis.y);
        let offset = Vec2::new(m.w_axis.x, m.w_axis.y);
        let sx = c0.length();
        // chiaro's linear part is [[c, s], [-s, c]] (rows) times diag(sx, sy).
        let rotation = (-c0.y).atan2(c0.x);
        let (s, c) = rotation.sin_cos();
        let sy = Vec2::new(s, c).dot(c1);
        let t = UvTransform {
            offset,
            rotation,
            scale: Vec2::new(sx, sy),
        };
        if (t.linear().col(1) - c1).length() > 1e-4 * (1.0 + c1.length()) {
            self.warn(e, "approximate: a sheared to_uv is drawn without its shear");
        }
        t
    }
}

/// An IOR from a `<float>` or a `<string>` name.
fn ior_of(e: &Element) -> Result<f32> {
    let v = e.require("value")?;
    if e.tag == "string" {
        return spectra::ior(v).ok_or_else(|| e.loc.error(format!("unknown IOR name \"{v}\"")));
    }
    match v.trim().parse::<f32>() {
        Ok(x) if x.is_finite() && x > 0.0 => Ok(x),
        _ => spectra::ior(v).ok_or_else(|| {
            e.loc.error(format!(
                "expected an IOR (a positive number or a name such as bk7), found {v:?}"
            ))
        }),
    }
}
