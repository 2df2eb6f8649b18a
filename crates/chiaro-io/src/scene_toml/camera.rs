//! `[camera]` and `[cameras.NAME]`.

use super::raw::{Opt, RawCamera, Sp};
use super::{Ctx, span_of};
use crate::Result;
use chiaro_core::Vec3;
use chiaro_core::scene::Camera;

impl Ctx<'_> {
    pub(super) fn camera(&self, raw: Sp<RawCamera>) -> Result<Camera> {
        let span = raw.span();
        let c = raw.into_inner();
        let d = Camera::default();
        let v3 =
            |v: &Opt<[f32; 3]>, def: Vec3| v.as_ref().map_or(def, |v| Vec3::from(*v.get_ref()));
        let cam = Camera {
            eye: v3(&c.eye, d.eye),
            look_at: v3(&c.look_at, d.look_at),
            up: v3(&c.up, d.up),
            fov_y_degrees: c.fov.as_ref().map_or(d.fov_y_degrees, |f| *f.get_ref()),
            near: match &c.near {
                Some(n) => self.finite_positive(n, "camera.near")?,
                None => d.near,
            },
            far: c.far.as_ref().map_or(d.far, |f| *f.get_ref()),
        };
        if let Some(f) = &c.fov
            && !(cam.fov_y_degrees > 0.0 && cam.fov_y_degrees < 180.0)
        {
            return Err(self.at(
                f.span(),
                format!(
                    "camera.fov: expected 0 < fov < 180 degrees, got {}",
                    cam.fov_y_degrees
                ),
            ));
        }
        if cam.far <= cam.near {
            return Err(self.at(
                span_of(&c.far).unwrap_or(span),
                format!(
                    "camera: expected far > near, got near {} far {}",
                    cam.near, cam.far
                ),
            ));
        }
        if cam.eye == cam.look_at {
            return Err(self.at(
                span_of(&c.look_at).unwrap_or(span),
                "camera: eye and look_at are the same point",
            ));
        }
        if cam.up.cross(cam.look_at - cam.eye).length_squared() == 0.0 {
            return Err(self.at(
                span_of(&c.up).unwrap_or(span),
                "camera: `up` is zero or parallel to the viewing direction",
            ));
        }
        Ok(cam)
    }
}
