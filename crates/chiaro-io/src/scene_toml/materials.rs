//! `[material.NAME]` and the textures they name.

use super::Ctx;
use super::raw::{Opt, RawConductor, RawMaterial, Sp, Splat3, TextureSpec};
use crate::Result;
use chiaro_core::Vec3;
use chiaro_core::scene::{
    Bump, ComplexIor, Material, Procedural, ProceduralKind, Scene, Sidedness, Texture, TextureId,
    WrapMode,
};

impl Ctx<'_> {
    pub(super) fn material(
        &mut self,
        scene: &mut Scene,
        name: &str,
        m: &RawMaterial,
    ) -> Result<Material> {
        let d = Material::default();
        // Ranges (colours >= 0, shininess, ior, roughness) are
        // `Scene::validate`'s, placed at the key by `finish`.
        let rgb = |v: &Opt<Splat3>, def: Vec3| v.as_ref().map_or(def, |v| v.get_ref().vec3());
        let num = |v: &Opt<f32>, def: f32| v.as_ref().map_or(def, |v| *v.get_ref());
        let mut mat = Material {
            name: name.to_string(),
            ambient: rgb(&m.ambient, d.ambient),
            diffuse: rgb(&m.diffuse, d.diffuse),
            specular: rgb(&m.specular, d.specular),
            shininess: num(&m.shininess, d.shininess),
            model: m.model.unwrap_or(d.model),
            roughness: num(&m.roughness, d.roughness),
            distribution: m.distribution.unwrap_or(d.distribution),
            reflect: rgb(&m.reflect, d.reflect),
            transmit: rgb(&m.transmit, d.transmit),
            ior: num(&m.ior, d.ior),
            absorption: rgb(&m.absorption, d.absorption),
            fresnel: m.fresnel.unwrap_or(d.fresnel),
            transparency: m.transparency.unwrap_or(d.transparency),
            emission: rgb(&m.emission, d.emission),
            // `sidedness`, else the older keys (`cull_backface = true`,
            // `two_sided = false`), else two-sided.
            sidedness: m.sidedness.unwrap_or(match (m.cull_backface, m.two_sided) {
                (Some(true), _) => Sidedness::Culled,
                (_, Some(false)) => Sidedness::OneSided,
                _ => d.sidedness,
            }),
            emission_two_sided: m
                .emission_two_sided
                .or(m.two_sided)
                .unwrap_or(d.emission_two_sided),
            ..d
        };
        if let Some(c) = &m.conductor {
            mat.conductor = Some(match c.get_ref() {
                RawConductor::Ior(ior) => ComplexIor {
                    eta: ior.eta.vec3(),
                    k: ior.k.vec3(),
                },
                RawConductor::Named(name) => {
                    let (eta, k) = crate::mitsuba::spectra::conductor(name).ok_or_else(|| {
                        self.at(
                            c.span(),
                            format!(
                                "unknown metal \"{name}\" (known: {})",
                                crate::mitsuba::spectra::conductor_names().join(", ")
                            ),
                        )
                    })?;
                    ComplexIor { eta, k }
                }
            });
        }
        if let Some(t) = &m.texture {
            mat.texture = Some(self.texture(scene, t, true, false)?.0);
        }
        if let Some(t) = &m.emission_texture {
            mat.emission_texture = Some(self.texture(scene, t, true, false)?.0);
        }
        if let Some(t) = &m.normal_map {
            mat.normal_map = Some(self.texture(scene, t, false, false)?.0);
        }
        if let Some(t) = &m.bump {
            let (texture, height) = self.texture(scene, t, false, true)?;
            mat.bump = Some(Bump {
                texture,
                height: height.unwrap_or(0.02),
            });
        }
        Ok(mat)
    }

    /// Builds a texture from its spec; returns its id and the bump `height`
    /// when given (only accepted when `allow_height`).
    pub(super) fn texture(
        &mut self,
        scene: &mut Scene,
        spec: &Sp<TextureSpec>,
        srgb: bool,
        allow_height: bool,
    ) -> Result<(TextureId, Option<f32>)> {
        let span = spec.span();
        match spec.get_ref() {
            TextureSpec::Path(p) => {
                let id = self.image(
                    scene,
                    &Sp::new(span, p.clone()),
                    srgb,
                    WrapMode::Repeat,
                    None,
                )?;
                Ok((id, None))
            }
            TextureSpec::Table(t) => {
                if t.height.is_some() && !allow_height {
                    return Err(self.at(span, "`height` applies only to `bump` textures"));
                }
                if let Some(h) = t.height
                    && !h.is_finite()
                {
                    return Err(self.at(span, "bump height must be a finite number"));
                }
                match (&t.procedural, &t.image) {
                    (Some(_), Some(_)) | (None, None) => Err(self.at(
                        span,
                        "a texture table needs exactly one of `procedural` or `image`",
                    )),
                    (None, Some(path)) => {
                        if t.scale.is_some()
                            || t.color_a.is_some()
                            || t.color_b.is_some()
                            || t.use_uv.is_some()
                        {
                            return Err(self.at(
                                span,
                                "`scale`, `color_a`, `color_b` and `use_uv` apply only to procedural textures",
                            ));
                        }
                        let id = self.image(
                            scene,
                            &Sp::new(span, path.clone()),
                            srgb,
                            t.wrap.unwrap_or_default(),
                            t.wrap_t,
                        )?;
                        Ok((id, t.height))
                    }
                    (Some(kind), None) => {
                        if t.wrap.is_some() || t.wrap_t.is_some() {
                            return Err(
                                self.at(span, "`wrap` and `wrap_t` apply only to image textures")
                            );
                        }
                        let scale = t.scale.unwrap_or(1.0);
                        if scale <= 0.0 {
                            return Err(self.at(
                                span,
                                format!("texture scale: expected a number > 0, got {scale}"),
                            ));
                        }
                        let (a, b) = default_colors(*kind);
                        let color_a = t.color_a.map_or(a, Splat3::vec3);
                        let color_b = t.color_b.map_or(b, Splat3::vec3);
                        if color_a.min_element() < 0.0 || color_b.min_element() < 0.0 {
                            return Err(self.at(span, "texture colours must be >= 0"));
                        }
                        let id = scene.add_texture(Texture::Procedural(Procedural {
                            kind: *kind,
                            scale,
                            color_a,
                            color_b,
                            use_uv: t.use_uv.unwrap_or(false),
                        }));
                        Ok((id, t.height))
                    }
                }
            }
        }
    }

    /// Loads (once) the image file named by `rel`, relative to the scene file.
    pub(super) fn image(
        &mut self,
        scene: &mut Scene,
        rel: &Sp<String>,
        srgb: bool,
        wrap: WrapMode,
        wrap_t: Option<WrapMode>,
    ) -> Result<TextureId> {
        let path = crate::resolve(self.base, rel.get_ref());
        let key = (path.clone(), srgb, wrap, wrap_t);
        if let Some(id) = self.images.get(&key) {
            return Ok(*id);
        }
        self.check_file(rel, &path, "texture file", "cannot load texture")?;
        let mut img = crate::images::load_texture_within(&path, srgb, self.budget)
            .map_err(|e| self.at(rel.span(), format!("cannot load texture: {e}")))?;
        img.wrap = wrap;
        img.wrap_t = wrap_t;
        let id = scene.add_texture(Texture::Image(img));
        self.images.insert(key, id);
        Ok(id)
    }
}

/// Default colours of the procedural textures.
fn default_colors(kind: ProceduralKind) -> (Vec3, Vec3) {
    match kind {
        ProceduralKind::Wood => (Vec3::new(0.55, 0.33, 0.15), Vec3::new(0.3, 0.16, 0.06)),
        ProceduralKind::Marble => (Vec3::new(0.9, 0.9, 0.88), Vec3::new(0.25, 0.25, 0.3)),
        _ => (Vec3::splat(0.1), Vec3::splat(0.9)),
    }
}
