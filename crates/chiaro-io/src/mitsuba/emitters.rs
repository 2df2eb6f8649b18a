//! `<emitter>` plugins: `point`, `spot`, `directional`, `envmap` and
//! `constant` become chiaro lights and environments; `area` (inside a
//! `<shape>`) becomes the shape material's emitted radiance.
//!
//! chiaro's point-like lights give the irradiance
//! `pi * intensity * color * cos / d^2` (ARCHITECTURE.md, "Radiometric
//! conventions"), so Mitsuba's radiant intensity `I` (W/sr) and irradiance
//! `E` become `intensity * color = I / pi` and `E / pi`.

use super::Builder;
use super::bsdfs::Value;
use super::props::Props;
use super::xml::Element;
use crate::Result;
use chiaro_core::scene::{
    Attenuation, Environment, ImageTexture, Light, SpotLight, Texture, WrapMode,
};
use chiaro_core::{Mat4, Vec3};
use std::f32::consts::PI;

impl Builder<'_> {
    /// A top-level `<emitter>`.
    pub fn emitter(&mut self, el: &Element) -> Result<()> {
        let ty = Self::plugin_type(el)?;
        let p = Props::new(el);
        let m = p.transform("to_world")?;
        match ty {
            "point" => {
                let position = match p.named("position") {
                    Some(_) => p.vector("position", Vec3::ZERO)?,
                    None => m.transform_point3(Vec3::ZERO),
                };
                let i = self.constant(el, &p, "intensity", Vec3::ONE)?;
                self.scene.lights.push(Light::Point {
                    position,
                    color: i,
                    intensity: 1.0 / PI,
                    attenuation: Attenuation::InverseSquare,
                });
            }
            "spot" => {
                let i = self.constant(el, &p, "intensity", Vec3::ONE)?;
                let cutoff = p.float("cutoff_angle", 20.0)?;
                let beam = p.float("beam_width", cutoff * 0.75)?;
                if !(cutoff > 0.0 && cutoff <= 90.0) {
                    return Err(el.loc.error(format!(
                        "cutoff_angle must be in (0, 90] degrees, got {cutoff}"
                    )));
                }
                if p.named("texture").is_some() {
                    self.warn(el, "approximate: the projected texture is ignored");
                }
                self.warn(el, "approximate: Mitsuba's smooth fall-off between beam_width and cutoff_angle is drawn with chiaro's cone softness");
                self.scene.lights.push(Light::Spot(SpotLight {
                    position: m.transform_point3(Vec3::ZERO),
                    direction: m.transform_vector3(Vec3::Z).normalize_or(Vec3::Z),
                    color: i,
                    intensity: 1.0 / PI,
                    attenuation: Attenuation::InverseSquare,
                    exponent: 0.0,
                    cone_degrees: cutoff,
                    cone_softness_degrees: (cutoff - beam.clamp(0.0, cutoff)).max(0.0),
                    flaps: Vec::new(),
                }));
            }
            "directional" => {
                let e = self.constant(el, &p, "irradiance", Vec3::ONE)?;
                let d = match p.named("direction") {
                    Some(_) => p.vector("direction", Vec3::Z)?,
                    None => m.transform_vector3(Vec3::Z),
                };
                let d = d
                    .try_normalize()
                    .ok_or_else(|| el.loc.error("the directional emitter's direction is zero"))?;
                self.scene.lights.push(Light::Directional {
                    direction: d,
                    color: e,
                    intensity: 1.0 / PI,
                });
            }
            "envmap" => self.envmap(el, &p, m)?,
            "constant" => {
                let l = self.constant(el, &p, "radiance", Vec3::ONE)?;
                let tex = self.scene.add_texture(Texture::Image(ImageTexture::new(
                    format!("constant emitter at {}", el.loc.describe()),
                    1,
                    1,
                    vec![[l.x, l.y, l.z, 1.0]],
                )));
                self.set_environment(el, tex, 1.0, 0.0);
            }
            "area" => {
                return Err(el.loc.error("an area emitter must be nested in a <shape>"));
            }
            other => {
                return Err(el.loc.error(format!(
                    "unknown emitter plugin \"{other}\" (chiaro reads point, spot, directional, area, envmap and constant)"
                )));
            }
        }
        self.warn_unused(&p);
        Ok(())
    }

    /// The radiance of an `area` emitter nested in a shape.
    pub fn area_radiance(&mut self, el: &Element) -> Result<Vec3> {
        let ty = Self::plugin_type(el)?;
        if ty != "area" {
            return Err(el.loc.error(format!(
                "a shape's emitter must be \"area\", found \"{ty}\""
            )));
        }
        let p = Props::new(el);
        let l = self.constant(el, &p, "radiance", Vec3::ONE)?;
        self.warn_unused(&p);
        Ok(l)
    }

    /// A constant spectrum-valued parameter (a texture is refused here).
    fn constant(&mut self, el: &Element, p: &Props, name: &str, default: Vec3) -> Result<Vec3> {
        match self.value(p, name, default)? {
            Value::Const(c) => Ok(c),
            _ => Err(el.loc.error(format!(
                "`{name}` of an emitter must be a constant (an <rgb>, <spectrum> or <float>)"
            ))),
        }
    }

    /// `envmap`: a lat-long image, `scale`, and `to_world` where it turns
    /// about +y. Mitsuba puts `-z` at `u = 0`, chiaro at `u = 0.5`: a half
    /// turn apart. Both put column i at `u = (i + 0.5) / W` and `+y` at
    /// `v = 0`; the rows are resampled ([`mitsuba_envmap_rows`]).
    fn envmap(&mut self, el: &Element, p: &Props, m: Mat4) -> Result<()> {
        let name = p.string("filename")?.ok_or_else(|| {
            el.loc
                .error("<emitter type=\"envmap\"> needs a <string name=\"filename\">")
        })?;
        let path = self.resolve(name);
        let img =
            crate::images::load_texture_within(&path, false, self.scene.render.memory_budget())
                .map_err(|e| el.loc.error(format!("envmap: {e}")))?;
        if img.width < 2
            || img.height < 3
            || img.texel_count() < img.width as usize * img.height as usize
        {
            return Err(el.loc.error(format!(
                "envmap: the map must be at least 2x3 texels (as Mitsuba requires), got {}x{}",
                img.width, img.height
            )));
        }
        let img = mitsuba_envmap_rows(img);
        let scale = p.float("scale", 1.0)?;
        let _ = p.named("mis_compensation");
        // A rotation about +y by `a` keeps +y and sends +z to (sin a, 0, cos a).
        let y = m.transform_vector3(Vec3::Y);
        let z = m.transform_vector3(Vec3::Z);
        let about_y =
            (y - Vec3::Y).length() < 1e-4 && z.y.abs() < 1e-4 && (z.length() - 1.0).abs() < 1e-4;
        let a = if about_y {
            z.x.atan2(z.z).to_degrees()
        } else {
            self.warn(
                el,
                "approximate: only a rotation about +y is kept from to_world; the rest is ignored",
            );
            0.0
        };
        let tex = self.scene.add_texture(Texture::Image(img));
        self.set_environment(el, tex, scale, a + 180.0);
        Ok(())
    }

    fn set_environment(
        &mut self,
        el: &Element,
        texture: chiaro_core::scene::TextureId,
        intensity: f32,
        rotate: f32,
    ) {
        if self.scene.environment.is_some() {
            self.warn(
                el,
                "approximate: chiaro has one environment; the later one replaces the earlier",
            );
        }
        self.scene.environment = Some(Environment {
            texture,
            intensity,
            rotate_y_degrees: rotate,
            as_background: true,
        });
    }
}

/// Most texels [`mitsuba_envmap_rows`] makes (16 M: 256 MiB of `f32` RGBA).
const ENVMAP_TEXELS: usize = 1 << 24;

/// Mitsuba's `envmap` in chiaro's lat-long lookup. Mitsuba places row `j`
/// of an `H`-row map at `v = j / (H - 1)` (the first and last rows on the
/// poles) and interpolates linearly in `v` between rows, clamped at the
/// poles (`eval_spectrum` in `src/emitters/envmap.cpp`); chiaro places row
/// `k` of an `H'`-row map at `v = (k + 0.5) / H'`. The result has
/// `H' = n (H - 1)` rows, row `k` Mitsuba's value at chiaro's `v` of that
/// row, and v clamped: chiaro's bilinear lookup then equals Mitsuba's
/// except within half a row of each of Mitsuba's rows (where Mitsuba's
/// interpolation bends, chiaro's cuts the corner by at most 1/(4n) of the
/// second difference of the rows) and in the caps of half a row at the
/// poles. `n` is 8, fewer where the map would exceed [`ENVMAP_TEXELS`].
/// Columns are kept (both place column `i` at `u = (i + 0.5) / W`, both
/// wrap in `u`).
fn mitsuba_envmap_rows(img: ImageTexture) -> ImageTexture {
    let (w, h) = (img.width as usize, img.height as usize);
    let n = (ENVMAP_TEXELS / (w * (h - 1))).clamp(1, 8);
    let rows = n * (h - 1);
    let mut texels = Vec::with_capacity(w * rows);
    for k in 0..rows {
        // Mitsuba's row coordinate of chiaro's row k.
        let y = (k as f64 + 0.5) / rows as f64 * (h - 1) as f64;
        let j = (y.floor() as usize).min(h - 2);
        let t = (y - j as f64) as f32;
        for i in 0..w {
            let a = img.texel_at(j * w + i);
            let b = img.texel_at((j + 1) * w + i);
            texels.push(std::array::from_fn(|c| (1.0 - t) * a[c] + t * b[c]));
        }
    }
    ImageTexture {
        width: img.width,
        height: rows as u32,
        texels,
        texels8: None,
        wrap: WrapMode::Repeat,
        wrap_t: Some(WrapMode::Clamp),
        ..img
    }
}
