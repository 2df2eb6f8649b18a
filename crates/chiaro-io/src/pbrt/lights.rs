//! `LightSource` (`point`, `spot`, `distant`, `infinite`) and
//! `AreaLightSource "diffuse"`.
//!
//! chiaro's point-like lights give the irradiance
//! `pi * intensity * color * cos / d^2` (ARCHITECTURE.md, "Radiometric
//! conventions"), so pbrt's radiant intensity `I` and a distant light's
//! `L` (its irradiance) become `intensity * color = I / pi` and `L / pi`.
//! pbrt-v4 scales an emission spectrum to its photometric value, which
//! leaves an RGB value as it is and a blackbody at luminance 1.
//!
//! An `infinite` light's image is resampled into chiaro's lat-long
//! environment through its `world_from_light` (and the world's mirroring,
//! `super`): pbrt-v4's square equal-area octahedral maps and pbrt-v3's
//! lat-long ones (+z up in light space) alike.

use super::lexer::{Lexer, Loc};
use super::params::{Params, Spectrum};
use super::{AreaSpec, Builder, PendingEnv};
use crate::Result;
use chiaro_core::scene::{Attenuation, Environment, ImageTexture, Light, SpotLight, Texture};
use chiaro_core::{Mat3, Mat4, Vec2, Vec3};
use std::f32::consts::PI;

/// The largest environment the resampling writes (texels on a side).
const MAX_ENV_WIDTH: u32 = 4096;

impl Builder {
    /// A spectrum parameter of a light (with pbrt-v3's `rgb scale`).
    fn emission(&mut self, p: &Params, name: &str, loc: &Loc, what: &str) -> Result<Vec3> {
        let l = match p.spectrum(name)? {
            None => Vec3::ONE,
            Some((Spectrum::Texture(_), at)) => {
                return Err(at.error(format!("\"{name}\" of a light must be a constant")));
            }
            Some((s, at)) => self.constant_spectrum(s, &at, loc, what)?,
        };
        let scale = match p.spectrum("scale")? {
            None => Vec3::ONE,
            Some((Spectrum::Texture(_), at)) => {
                return Err(at.error("\"scale\" of a light must be a constant"));
            }
            Some((s, at)) => self.constant_spectrum(s, &at, loc, what)?,
        };
        if p.has("power") || p.has("illuminance") {
            self.warn(loc, what, "approximate: \"power\" / \"illuminance\" is ignored (the light's L or I is used as given)");
        }
        Ok(l * scale)
    }

    /// A `LightSource` directive.
    pub fn light_source(&mut self, loc: &Loc, lx: &mut Lexer) -> Result<()> {
        let ty = lx.string("a light type")?;
        let p = Params::read(lx)?;
        let what = format!("LightSource \"{}\"", ty.text);
        let m = self.ctm();
        let light = match ty.text.as_str() {
            "point" => {
                let i = self.emission(&p, "I", loc, &what)?;
                let from = p.vec3("from", Vec3::ZERO)?;
                Some(Light::Point {
                    position: m.transform_point3(from),
                    color: i,
                    intensity: 1.0 / PI,
                    attenuation: Attenuation::InverseSquare,
                })
            }
            "spot" => {
                let i = self.emission(&p, "I", loc, &what)?;
                let from = p.vec3("from", Vec3::ZERO)?;
                let to = p.vec3("to", Vec3::Z)?;
                let cone = p.float("coneangle", 30.0)?;
                let delta = p.float("conedelta", 5.0)?;
                if !(cone > 0.0 && cone <= 90.0) {
                    return Err(p
                        .loc_of("coneangle")
                        .error(format!("coneangle must be in (0, 90] degrees, got {cone}")));
                }
                let direction = m
                    .transform_vector3(to - from)
                    .try_normalize()
                    .ok_or_else(|| loc.error("spot light: from and to coincide"))?;
                self.warn(loc, &what, "approximate: pbrt's smoothstep fall-off over conedelta is drawn with chiaro's cone softness");
                Some(Light::Spot(SpotLight {
                    position: m.transform_point3(from),
                    direction,
                    color: i,
                    intensity: 1.0 / PI,
                    attenuation: Attenuation::InverseSquare,
                    exponent: 0.0,
                    cone_degrees: cone,
                    cone_softness_degrees: delta.clamp(0.0, cone),
                    flaps: Vec::new(),
                }))
            }
            "distant" => {
                let l = self.emission(&p, "L", loc, &what)?;
                let from = p.vec3("from", Vec3::ZERO)?;
                let to = p.vec3("to", Vec3::Z)?;
                // Light travels from `from` towards `to`.
                let direction = m
                    .transform_vector3(to - from)
                    .try_normalize()
                    .ok_or_else(|| loc.error("distant light: from and to coincide"))?;
                Some(Light::Directional {
                    direction,
                    color: l,
                    intensity: 1.0 / PI,
                })
            }
            "infinite" => {
                let file = match p.string("filename")? {
                    Some(f) => Some(f),
                    None => p.string("mapname")?,
                };
                let image = match file {
                    Some(name) => {
                        let path = self.resolve(&name);
                        Some(
                            crate::images::load_texture_within(
                                &path,
                                true,
                                self.scene.render.memory_budget(),
                            )
                            .map_err(|e| loc.error(format!("infinite light: {e}")))?,
                        )
                    }
                    None => None,
                };
                let scale = self.emission(&p, "L", loc, &what)?;
                p.skip("samples");
                p.skip("nsamples");
                p.skip("portal");
                if self.env.is_some() {
                    self.warn(loc, &what, "approximate: chiaro has one environment; the later one replaces the earlier");
                }
                self.env = Some(PendingEnv {
                    image,
                    scale,
                    world_from_light: m,
                    loc: loc.clone(),
                });
                None
            }
            "goniometric" | "projection" => {
                return Err(ty.loc.error(format!(
                    "LightSource \"{}\" is refused: chiaro reads point, spot, distant and infinite",
                    ty.text
                )));
            }
            other => {
                return Err(ty.loc.error(format!(
                    "unknown LightSource \"{other}\" (chiaro reads point, spot, distant and infinite)"
                )));
            }
        };
        if let Some(l) = light {
            self.scene.lights.push(l);
        }
        self.warn_unused(loc, &what, &p);
        Ok(())
    }

    /// An `AreaLightSource` directive: the emission of the shapes that
    /// follow in the attribute block.
    pub fn area_light(&mut self, loc: &Loc, lx: &mut Lexer) -> Result<()> {
        let ty = lx.string("an area light type")?;
        let p = Params::read(lx)?;
        let what = format!("AreaLightSource \"{}\"", ty.text);
        if ty.text != "diffuse" {
            return Err(ty.loc.error(format!(
                "unknown AreaLightSource \"{}\" (chiaro reads diffuse)",
                ty.text
            )));
        }
        let radiance = self.emission(&p, "L", loc, &what)?;
        let two_sided = p.boolean("twosided", false)?;
        if p.has("filename") {
            self.warn(
                loc,
                &what,
                "approximate: the emission image is ignored (L is used)",
            );
        }
        self.warn_unused(loc, &what, &p);
        self.areas.push(AreaSpec {
            radiance,
            two_sided,
        });
        self.set_area(Some(self.areas.len() - 1));
        Ok(())
    }

    /// Places the environment: resampled into chiaro's lat-long layout
    /// through `world_from_light` and the world's `mirror`.
    pub fn place_environment(&mut self, env: &PendingEnv, mirror: Mat4) -> Result<()> {
        let what = "LightSource \"infinite\"";
        let texture = match &env.image {
            None => ImageTexture::new(
                format!("infinite light at {}", env.loc.describe()),
                1,
                1,
                vec![[1.0, 1.0, 1.0, 1.0]],
            ),
            Some(img) => {
                let light_from_world = Mat3::from_mat4(env.world_from_light).inverse();
                if !light_from_world.is_finite() {
                    return Err(env.loc.error("the infinite light's transform is singular"));
                }
                let to_light = light_from_world * Mat3::from_mat4(mirror);
                let octahedral = img.width == img.height;
                let width =
                    if octahedral { 2 * img.width } else { img.width }.clamp(2, MAX_ENV_WIDTH);
                let height = (width / 2).max(1);
                let mut texels = Vec::new();
                texels
                    .try_reserve_exact((width * height) as usize)
                    .map_err(|_| env.loc.error("the environment does not fit in memory"))?;
                for j in 0..height {
                    let theta = (j as f32 + 0.5) / height as f32 * PI;
                    for i in 0..width {
                        let phi = ((i as f32 + 0.5) / width as f32 - 0.5) * 2.0 * PI;
                        // chiaro's lat-long direction: +y up, u = 0.5 looks down -z.
                        let d = Vec3::new(
                            theta.sin() * phi.sin(),
                            theta.cos(),
                            -theta.sin() * phi.cos(),
                        );
                        let l = (to_light * d).normalize_or(Vec3::Z);
                        let uv = if octahedral {
                            equal_area_sphere_to_square(l)
                        } else {
                            // pbrt-v3: theta from +z, phi from +x towards +y.
                            let phi = l.y.atan2(l.x).rem_euclid(2.0 * PI);
                            Vec2::new(phi / (2.0 * PI), l.z.clamp(-1.0, 1.0).acos() / PI)
                        };
                        texels.push(bilinear(img, uv, !octahedral));
                    }
                }
                if octahedral {
                    self.warn(
                        &env.loc.clone(),
                        what,
                        "approximate: the equal-area map is resampled to a lat-long one",
                    );
                }
                ImageTexture::new(format!("{} (resampled)", img.source), width, height, texels)
            }
        };
        let scale = env.scale;
        let intensity = scale.max_element().max(0.0);
        let mut texture = texture;
        if intensity > 0.0 && scale != Vec3::splat(intensity) {
            // A coloured scale tints the texels.
            let tint = scale / intensity;
            for t in &mut texture.texels {
                t[0] *= tint.x;
                t[1] *= tint.y;
                t[2] *= tint.z;
            }
        }
        let id = self.scene.add_texture(Texture::Image(texture));
        self.scene.environment = Some(Environment {
            texture: id,
            intensity,
            rotate_y_degrees: 0.0,
            as_background: true,
        });
        Ok(())
    }
}

/// A bilinear lookup at `uv` in `[0, 1]^2` (texel centres at half
/// integers), wrapping u when `wrap_u`, clamping otherwise.
fn bilinear(img: &ImageTexture, uv: Vec2, wrap_u: bool) -> [f32; 4] {
    let (w, h) = (img.width.max(1) as i64, img.height.max(1) as i64);
    let x = uv.x * w as f32 - 0.5;
    let y = uv.y * h as f32 - 0.5;
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = (x - x0, y - y0);
    let at = |xi: i64, yi: i64| {
        let xi = if wrap_u {
            xi.rem_euclid(w)
        } else {
            xi.clamp(0, w - 1)
        };
        let yi = yi.clamp(0, h - 1);
        let i = (yi * w + xi) as usize;
        if i < img.texel_count() {
            img.texel_at(i)
        } else {
            [0.0; 4]
        }
    };
    let (x0, y0) = (x0 as i64, y0 as i64);
    let mut out = [0.0f32; 4];
    for (dx, dy, wgt) in [
        (0, 0, (1.0 - fx) * (1.0 - fy)),
        (1, 0, fx * (1.0 - fy)),
        (0, 1, (1.0 - fx) * fy),
        (1, 1, fx * fy),
    ] {
        let t = at(x0 + dx, y0 + dy);
        for c in 0..4 {
            out[c] += wgt * t[c];
        }
    }
    out[3] = 1.0;
    out
}

/// Clarberg's equal-area octahedral map from the unit sphere to `[0,
/// 1]^2`, as pbrt-v4 lays out its environment images
/// (`EqualAreaSphereToSquare`, Clarberg 2008, "Fast Equal-Area Mapping of
/// the (Hemi)Sphere using SIMD").
pub fn equal_area_sphere_to_square(d: Vec3) -> Vec2 {
    let (x, y, z) = (d.x.abs(), d.y.abs(), d.z.abs());
    let r = (1.0 - z).max(0.0).sqrt();
    let a = x.max(y);
    let b = if a == 0.0 { 0.0 } else { x.min(y) / a };
    let mut phi = b.atan() * 2.0 / PI;
    if x < y {
        phi = 1.0 - phi;
    }
    let mut v = phi * r;
    let mut u = r - v;
    if d.z < 0.0 {
        std::mem::swap(&mut u, &mut v);
        u = 1.0 - u;
        v = 1.0 - v;
    }
    u = u.copysign(d.x);
    v = v.copysign(d.y);
    Vec2::new(0.5 * (u + 1.0), 0.5 * (v + 1.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn equal_area_poles_and_axes() {
        let c = |v: Vec2, x: f32, y: f32| (v - Vec2::new(x, y)).length() < 1e-5;
        assert!(c(equal_area_sphere_to_square(Vec3::Z), 0.5, 0.5));
        assert!(c(equal_area_sphere_to_square(Vec3::X), 1.0, 0.5));
        assert!(c(equal_area_sphere_to_square(Vec3::NEG_X), 0.0, 0.5));
        assert!(c(equal_area_sphere_to_square(Vec3::Y), 0.5, 1.0));
        // -z maps to a corner.
        let s = equal_area_sphere_to_square(Vec3::NEG_Z);
        assert!((s.x - 0.5).abs() > 0.49 && (s.y - 0.5).abs() > 0.49, "{s}");
    }
}
