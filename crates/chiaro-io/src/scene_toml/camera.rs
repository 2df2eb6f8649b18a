//! `[camera]` and `[cameras.NAME]`.

use super::raw::{Opt, RawCamera, Sp};
use super::{Ctx, span_of};
use crate::Result;
use chiaro_core::Vec3;
use chiaro_core::scene::{Camera, Projection};

impl Ctx<'_> {
    pub(super) fn camera(&self, raw: Sp<RawCamera>) -> Result<Camera> {
        let span = raw.span();
        let c = raw.into_inner();
        let d = Camera::default();
        let v3 =
            |v: &Opt<[f32; 3]>, def: Vec3| v.as_ref().map_or(def, |v| Vec3::from(*v.get_ref()));
        // `projection = "orthographic"` takes `half_height` instead of `fov`.
        let projection = match c.projection.as_ref().map(|p| p.get_ref().as_str()) {
            None | Some("perspective") => {
                if let Some(h) = &c.half_height {
                    return Err(self.at(
                        h.span(),
                        "camera: `half_height` is for `projection = \"orthographic\"`",
                    ));
                }
                Projection::Perspective
            }
            Some("orthographic") => {
                if let Some(f) = &c.fov {
                    return Err(self.at(
                        f.span(),
                        "camera: an orthographic camera has no `fov` (give `half_height`)",
                    ));
                }
                let Some(h) = &c.half_height else {
                    return Err(self.at(
                        span_of(&c.projection).unwrap_or(span),
                        "camera: `projection = \"orthographic\"` needs `half_height` (half the film's height, scene units)",
                    ));
                };
                Projection::Orthographic {
                    half_height: *h.get_ref(),
                }
            }
            Some(other) => {
                return Err(self.at(
                    span_of(&c.projection).unwrap_or(span),
                    format!(
                        "camera: unknown projection {other:?} (expected perspective or orthographic)"
                    ),
                ));
            }
        };
        // Ranges (fov, half_height, near < far, eye != look_at) are
        // `Scene::validate`'s, placed at the key by `finish`.
        let cam = Camera {
            eye: v3(&c.eye, d.eye),
            look_at: v3(&c.look_at, d.look_at),
            up: v3(&c.up, d.up),
            fov_y_degrees: c.fov.as_ref().map_or(d.fov_y_degrees, |f| *f.get_ref()),
            near: c.near.as_ref().map_or(d.near, |n| *n.get_ref()),
            far: c.far.as_ref().map_or(d.far, |f| *f.get_ref()),
            projection,
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
