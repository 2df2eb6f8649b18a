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
        // Ranges (fov, near < far, eye != look_at) are `Scene::validate`'s,
        // placed at the key by `finish`.
        let cam = Camera {
            eye: v3(&c.eye, d.eye),
            look_at: v3(&c.look_at, d.look_at),
            up: v3(&c.up, d.up),
            fov_y_degrees: c.fov.as_ref().map_or(d.fov_y_degrees, |f| *f.get_ref()),
            near: c.near.as_ref().map_or(d.near, |n| *n.get_ref()),
            far: c.far.as_ref().map_or(d.far, |f| *f.get_ref()),
        };
        if cam.eye != cam.look_at && cam.up.cross(cam.look_at - cam.eye).length_squared() == 0.0 {
            return Err(self.at(
                span_of(&c.up).unwrap_or(span),
                "camera: `up` is zero or parallel to the viewing direction",
            ));
        }
        Ok(cam)
    }
}
