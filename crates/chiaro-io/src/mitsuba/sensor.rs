//! `<sensor>` (the camera), its `<film>` (image size, reconstruction
//! filter), `<sampler>` (samples per pixel), and `<integrator>` (the path
//! tracer's depth).

use super::Builder;
use super::props::Props;
use super::xml::Element;
use crate::Result;
use chiaro_core::scene::{Camera, PixelFilter, Projection, Technique};
use chiaro_core::{Mat4, Vec3};

/// Mitsuba's perspective field of view along x from `fov` and `fov_axis`,
/// or from `focal_length` (35 mm film, along the diagonal; "50mm" by
/// default), for an image of aspect `width / height`. Returns degrees, or
/// a message naming the bad value.
pub fn fov_x_degrees(
    fov: Option<f32>,
    axis: &str,
    focal_mm: Option<f32>,
    aspect: f32,
) -> std::result::Result<f32, String> {
    let (fov, axis) = match (fov, focal_mm) {
        (Some(f), None) => (f, axis),
        (None, f) => {
            let f = f.unwrap_or(50.0);
            if f <= 0.0 {
                return Err(format!("focal_length must be positive, got {f}"));
            }
            let diagonal = (36.0f32 * 36.0 + 24.0 * 24.0).sqrt();
            (
                (2.0 * (diagonal / (2.0 * f)).atan()).to_degrees(),
                "diagonal",
            )
        }
        (Some(_), Some(_)) => return Err("give either fov or focal_length, not both".into()),
    };
    if !(fov > 0.0 && fov < 180.0) {
        return Err(format!("fov must be in (0, 180) degrees, got {fov}"));
    }
    let tan_half = (0.5 * fov.to_radians()).tan();
    // tan(fov_x / 2) from the given axis.
    let tan_x = match axis {
        "x" => tan_half,
        "y" => tan_half * aspect,
        "diagonal" => tan_half / (1.0 + 1.0 / (aspect * aspect)).sqrt(),
        "smaller" if aspect > 1.0 => tan_half * aspect,
        "smaller" => tan_half,
        "larger" if aspect > 1.0 => tan_half,
        "larger" => tan_half * aspect,
        other => {
            return Err(format!(
                "unknown fov_axis \"{other}\" (expected x, y, diagonal, smaller or larger)"
            ));
        }
    };
    Ok((2.0 * tan_x.atan()).to_degrees())
}

/// chiaro's vertical field of view for Mitsuba's horizontal one.
pub fn fov_y_from_x(fov_x_degrees: f32, aspect: f32) -> f32 {
    (2.0 * ((0.5 * fov_x_degrees.to_radians()).tan() / aspect).atan()).to_degrees()
}

impl Builder<'_> {
    /// The camera, image size, filter and samples of a `<sensor>`.
    pub fn sensor(&mut self, el: &Element) -> Result<()> {
        let ty = Self::plugin_type(el)?;
        match ty {
            "perspective" | "orthographic" => {}
            "thinlens" => self.warn(
                el,
                "approximate: drawn as a pinhole perspective camera (no depth of field)",
            ),
            "telecentric" => {
                return Err(el.loc.error(
                    "sensor \"telecentric\" is refused: chiaro has perspective and orthographic cameras",
                ));
            }
            other => {
                return Err(el.loc.error(format!(
                    "unknown sensor plugin \"{other}\" (chiaro reads perspective, orthographic and thinlens)"
                )));
            }
        }
        let p = Props::new(el);
        for film in p.children("film") {
            self.film(film)?;
        }
        for sampler in p.children("sampler") {
            self.sampler(sampler)?;
        }
        let world_from_camera = p.transform("to_world")?;
        let aspect = self.scene.render.width as f32 / self.scene.render.height.max(1) as f32;
        if ty == "orthographic" {
            let near = p.float("near_clip", 0.01)?;
            let far = p.float("far_clip", 10_000.0)?;
            if !(near > 0.0 && far > near) {
                return Err(el.loc.error(format!(
                    "near_clip and far_clip must satisfy 0 < near < far, got {near} and {far}"
                )));
            }
            let _ = p.string("srf")?;
            self.set_orthographic(el, world_from_camera, aspect, near, far);
            self.warn_unused(&p);
            return Ok(());
        }
        let fov = match p.named("fov") {
            Some(_) => Some(p.float("fov", 0.0)?),
            None => None,
        };
        let axis = p.string("fov_axis")?.unwrap_or("x").to_ascii_lowercase();
        let focal = match p.string("focal_length")? {
            Some(s) => Some(parse_mm(s).ok_or_else(|| {
                el.loc.error(format!(
                    "focal_length: expected a length such as \"50mm\", found {s:?}"
                ))
            })?),
            None => None,
        };
        let fov_x = fov_x_degrees(fov, &axis, focal, aspect).map_err(|m| el.loc.error(m))?;
        // A vertical fov is chiaro's own: kept as written, not through fov_x.
        let vertical = match axis.as_str() {
            "y" => true,
            "smaller" => aspect > 1.0,
            "larger" => aspect <= 1.0,
            _ => false,
        };
        let fov_y = match fov {
            Some(f) if vertical && focal.is_none() => f,
            _ => fov_y_from_x(fov_x, aspect),
        };
        let near = p.float("near_clip", 0.01)?;
        let far = p.float("far_clip", 10_000.0)?;
        if !(near > 0.0 && far > near) {
            return Err(el.loc.error(format!(
                "near_clip and far_clip must satisfy 0 < near < far, got {near} and {far}"
            )));
        }
        if ty == "thinlens" {
            // Read so they are not reported as unknown; the warning above covers them.
            let _ = p.float("aperture_radius", 0.0)?;
            let _ = p.float("focus_distance", 0.0)?;
        }
        for key in ["principal_point_offset_x", "principal_point_offset_y"] {
            if p.float(key, 0.0)? != 0.0 {
                self.warn(el, "approximate: the principal point offset is ignored");
            }
        }
        // The sensor's spectral response: chiaro renders RGB.
        let _ = p.string("srf")?;
        self.set_camera(el, world_from_camera, fov_y, near, far);
        self.warn_unused(&p);
        Ok(())
    }

    /// Mitsuba's camera when the scene has no sensor: at the origin looking
    /// down +z, fov 39.3077 degrees along x, on a 768 x 576 film.
    pub fn default_sensor(&mut self) {
        let aspect = self.scene.render.width as f32 / self.scene.render.height as f32;
        self.scene.camera = Camera {
            eye: Vec3::ZERO,
            look_at: Vec3::Z,
            up: Vec3::Y,
            fov_y_degrees: fov_y_from_x(39.3077, aspect),
            near: 0.01,
            far: 10_000.0,
            ..Default::default()
        };
    }

    /// Mitsuba's `orthographic` sensor: a film `[-1, 1]` wide along camera
    /// x and `[-1/aspect, 1/aspect]` high along y, scaled by `to_world`
    /// (mitsuba3 `orthographic_projection` in `sensor.h`); its rays start
    /// on the near plane, chiaro's on the film through the eye, which only
    /// differs for surfaces closer than `near_clip`.
    fn set_orthographic(&mut self, el: &Element, m: Mat4, aspect: f32, near: f32, far: f32) {
        let [eye, forward, up, left] = self.sensor_frame(el, m);
        // The film's half-width is |to_world x|, its half-height
        // |to_world y| / aspect; chiaro's film has the image's aspect.
        let (half_w, half_h) = (left.length(), up.length() / aspect);
        if (half_w - half_h * aspect).abs() > 1e-4 * half_w.max(half_h * aspect) {
            self.warn(
                el,
                "approximate: the camera transform scales x and y differently; the film's height is kept, its width follows the image's aspect",
            );
        }
        self.scene.camera = Camera {
            eye,
            look_at: eye + forward.normalize_or(Vec3::Z),
            up: up.normalize_or(Vec3::Y),
            near,
            far,
            projection: Projection::Orthographic {
                half_height: half_h,
            },
            ..Default::default()
        };
    }

    /// The sensor's `to_world` frame: eye, forward (+z), up (+y) and left
    /// (+x), unnormalised. A look_at frame has det > 0 (left = up x dir); a
    /// mirrored one (e.g. `<scale x="-1"/>`) flips the image, which chiaro's
    /// camera cannot: that is warned of here.
    fn sensor_frame(&mut self, el: &Element, m: Mat4) -> [Vec3; 4] {
        let eye = m.transform_point3(Vec3::ZERO);
        let forward = m.transform_vector3(Vec3::Z);
        let up = m.transform_vector3(Vec3::Y);
        let left = m.transform_vector3(Vec3::X);
        if left.dot(up.cross(forward)) < 0.0 {
            self.warn(
                el,
                "approximate: the camera transform mirrors the image; rendered unmirrored",
            );
        }
        [eye, forward, up, left]
    }

    fn set_camera(&mut self, el: &Element, m: Mat4, fov_y: f32, near: f32, far: f32) {
        let [eye, forward, up, _] = self.sensor_frame(el, m);
        let scale = forward.length();
        if (scale - 1.0).abs() > 1e-3 || (up.length() - 1.0).abs() > 1e-3 {
            self.warn(el, "approximate: the camera transform scales; only its position and directions are used");
        }
        self.scene.camera = Camera {
            eye,
            look_at: eye + forward.normalize_or(Vec3::Z),
            up: up.normalize_or(Vec3::Y),
            fov_y_degrees: fov_y,
            near,
            far,
            ..Default::default()
        };
    }

    /// `<film>`: width, height and the reconstruction filter.
    fn film(&mut self, el: &Element) -> Result<()> {
        let ty = Self::plugin_type(el)?;
        if ty != "hdrfilm" && ty != "specfilm" {
            return Err(el.loc.error(format!(
                "unknown film plugin \"{ty}\" (chiaro reads hdrfilm)"
            )));
        }
        let p = Props::new(el);
        let dim = |name: &str, d: i64| -> Result<u32> {
            let v = p.int(name, d)?;
            u32::try_from(v).ok().filter(|v| *v > 0).ok_or_else(|| {
                el.loc
                    .error(format!("film {name} must be a positive integer, got {v}"))
            })
        };
        self.scene.render.width = dim("width", 768)?;
        self.scene.render.height = dim("height", 576)?;
        // Output formats: chiaro picks them from the output file's name.
        for key in ["pixel_format", "component_format", "file_format"] {
            let _ = p.string(key)?;
        }
        let _ = p.boolean("sample_border", false)?;
        if p.named("crop_width").is_some() || p.named("crop_offset_x").is_some() {
            self.warn(
                el,
                "approximate: the crop window is ignored (use --set crop=...)",
            );
            for key in [
                "crop_width",
                "crop_height",
                "crop_offset_x",
                "crop_offset_y",
            ] {
                let _ = p.named(key);
            }
        }
        let filters = p.children("rfilter");
        match filters.first() {
            Some(f) => self.rfilter(f)?,
            // Mitsuba's default: the Gaussian of stddev 0.5.
            None => self.scene.render.filter = PixelFilter::Gaussian,
        }
        self.warn_unused(&p);
        Ok(())
    }

    fn rfilter(&mut self, el: &Element) -> Result<()> {
        let ty = Self::plugin_type(el)?;
        let p = Props::new(el);
        self.scene.render.filter = match ty {
            "box" => PixelFilter::Box,
            "tent" => {
                if (p.float("radius", 1.0)? - 1.0).abs() > 1e-6 {
                    self.warn(el, "approximate: chiaro's tent has radius 1 pixel");
                }
                PixelFilter::Tent
            }
            "gaussian" => {
                let stddev = p.float("stddev", 0.5)?;
                if (stddev - 0.5).abs() > 1e-6 {
                    self.warn(
                        el,
                        "approximate: drawn with chiaro's Gaussian of stddev 0.5 pixel",
                    );
                }
                PixelFilter::Gaussian
            }
            "mitchell" | "catmullrom" | "lanczos" => {
                self.warn(
                    el,
                    "approximate: drawn with chiaro's tent filter (radius 1)",
                );
                PixelFilter::Tent
            }
            other => {
                return Err(el.loc.error(format!(
                    "unknown rfilter plugin \"{other}\" (expected box, tent or gaussian)"
                )));
            }
        };
        self.warn_unused(&p);
        Ok(())
    }

    /// `<sampler>`: its sample count; the sequence is chiaro's own.
    fn sampler(&mut self, el: &Element) -> Result<()> {
        let ty = Self::plugin_type(el)?;
        const SAMPLERS: [&str; 6] = [
            "independent",
            "stratified",
            "multijitter",
            "orthogonal",
            "ldsampler",
            "ldsampler",
        ];
        if !SAMPLERS.contains(&ty) {
            return Err(el.loc.error(format!(
                "unknown sampler plugin \"{ty}\" (expected independent, stratified, multijitter, orthogonal or ldsampler)"
            )));
        }
        let p = Props::new(el);
        let n = p.int("sample_count", 4)?;
        self.scene.render.samples = u32::try_from(n).ok().filter(|n| *n > 0).ok_or_else(|| {
            el.loc
                .error(format!("sample_count must be a positive integer, got {n}"))
        })?;
        let _ = p.int("seed", 0)?;
        let _ = p.boolean("jitter", true)?;
        let _ = p.int("strength", 2)?;
        self.warn_unused(&p);
        Ok(())
    }

    /// `<integrator>`: `path` and `direct` become chiaro's path tracer;
    /// wrappers (`moment`, `aov`, ...) are unwrapped.
    pub fn integrator(&mut self, el: &Element) -> Result<()> {
        let ty = Self::plugin_type(el)?;
        let p = Props::new(el);
        self.scene.render.technique = Technique::Path;
        match ty {
            "moment" | "aov" | "stokes" | "depth" => {
                self.warn(
                    el,
                    "approximate: the wrapper is unwrapped; chiaro renders its inner integrator",
                );
                let inner = p.children("integrator");
                match inner.first() {
                    Some(i) => self.integrator(i)?,
                    None => self.scene.render.path.max_depth = 8,
                }
                let _ = p.string("aovs")?;
                return Ok(());
            }
            "path" | "volpath" | "volpathmis" | "prb" => {
                if ty != "path" {
                    self.warn(
                        el,
                        "approximate: drawn by chiaro's path tracer (no participating media)",
                    );
                }
                // Mitsuba counts the camera segment: max_depth 2 is direct
                // light, chiaro's 1; -1 (no limit) becomes chiaro's 64.
                let d = p.int("max_depth", -1)?;
                self.scene.render.path.max_depth = match d {
                    -1 => 64,
                    d if d >= 2 => u32::try_from(d - 1).unwrap_or(u32::MAX).min(1024),
                    d => {
                        return Err(el.loc.error(format!(
                            "max_depth {d}: chiaro renders paths of at least one bounce (max_depth >= 2, or -1)"
                        )));
                    }
                };
                let rr = p.int("rr_depth", 5)?;
                self.scene.render.path.rr_depth = u32::try_from(rr - 1).unwrap_or(1).max(1);
                let _ = p.boolean("hide_emitters", false)?;
            }
            "direct" => {
                self.scene.render.path.max_depth = 1;
                for key in ["emitter_samples", "bsdf_samples", "shading_samples"] {
                    let _ = p.int(key, 1)?;
                }
                let _ = p.boolean("hide_emitters", false)?;
            }
            other => {
                return Err(el.loc.error(format!(
                    "integrator \"{other}\" is refused: chiaro reads path, direct and volpath (and unwraps moment, aov)"
                )));
            }
        }
        self.warn_unused(&p);
        Ok(())
    }
}

/// `"50mm"` or `"50"` as millimetres.
fn parse_mm(s: &str) -> Option<f32> {
    let t = s.trim();
    let t = t.strip_suffix("mm").unwrap_or(t).trim();
    t.parse::<f32>().ok().filter(|v| v.is_finite())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fov_axes() {
        let aspect = 2.0;
        let x = fov_x_degrees(Some(60.0), "x", None, aspect).expect("test input");
        assert!((x - 60.0).abs() < 1e-4);
        // fov along y: tan(x/2) = aspect tan(y/2).
        let x = fov_x_degrees(Some(60.0), "y", None, aspect).expect("test input");
        let want = (2.0 * (aspect * 30f32.to_radians().tan()).atan()).to_degrees();
        assert!((x - want).abs() < 1e-4);
        // Diagonal of a 2:1 image: the x half-width is 2/sqrt(5) of the diagonal's.
        let x = fov_x_degrees(Some(60.0), "diagonal", None, aspect).expect("test input");
        let want = (2.0 * (30f32.to_radians().tan() * 2.0 / 5f32.sqrt()).atan()).to_degrees();
        assert!((x - want).abs() < 1e-4);
        // Wide image: smaller is y, larger is x; tall image the other way.
        assert_eq!(
            fov_x_degrees(Some(60.0), "smaller", None, 2.0),
            fov_x_degrees(Some(60.0), "y", None, 2.0)
        );
        assert_eq!(
            fov_x_degrees(Some(60.0), "larger", None, 2.0),
            fov_x_degrees(Some(60.0), "x", None, 2.0)
        );
        assert_eq!(
            fov_x_degrees(Some(60.0), "smaller", None, 0.5),
            fov_x_degrees(Some(60.0), "x", None, 0.5)
        );
        // 50 mm on 35 mm film: 46.8 degrees along the diagonal.
        let x = fov_x_degrees(None, "x", None, 1.5).expect("test input");
        let d = (2.0 * (x.to_radians() * 0.5).tan() * (1.0f32 + 1.0 / 2.25).sqrt() / 2.0).atan();
        assert!(((2.0 * d).to_degrees() - 46.793).abs() < 1e-2);
        assert!(fov_x_degrees(Some(60.0), "z", None, 1.0).is_err());
        assert!(fov_x_degrees(Some(200.0), "x", None, 1.0).is_err());
        // x to chiaro's vertical and back at aspect 1 is the identity.
        assert!((fov_y_from_x(45.0, 1.0) - 45.0).abs() < 1e-4);
        assert!(
            (fov_y_from_x(x, 1.5)
                - (2.0 * ((x.to_radians() * 0.5).tan() / 1.5).atan()).to_degrees())
            .abs()
                < 1e-5
        );
    }
}
