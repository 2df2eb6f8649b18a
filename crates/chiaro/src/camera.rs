//! Choosing the camera from outside the scene file: `--camera NAME`,
//! `--eye X,Y,Z`, `--look-at X,Y,Z`, `--fov DEG`, `--up y|z` on the
//! command line, the same keywords in Python, the same in `chiaro serve`.
//!
//! The rules, applied in this order:
//! - `name` picks one of `Scene::cameras` (by name, or by index when no
//!   camera has that name);
//! - `up` alone (no name, eye or look-at) frames the scene again with that
//!   axis vertical ([`chiaro_core::framing`]; an orthographic camera stays
//!   orthographic, framed as the perspective view is at its target); with
//!   any of them it sets the camera's up vector;
//! - `eye`, `look_at` and `fov` replace the camera's, the rest is kept (the
//!   clip range grows when the scene reaches beyond `far`); `fov` makes an
//!   orthographic camera a perspective one;
//! - lights that a loader supplied for the old camera
//!   ([`chiaro_io::framed_lights`]) are supplied again for the new one.

use crate::Scene;
use chiaro_core::Vec3;
use chiaro_core::framing;
pub use chiaro_core::framing::UpAxis;
use chiaro_core::scene::Camera;
use thiserror::Error;

/// A camera request; every field is optional, and the empty request keeps
/// the scene's camera.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct CameraChoice {
    /// `--camera NAME`: one of the scene's named cameras.
    pub name: Option<String>,
    /// `--eye X,Y,Z`.
    pub eye: Option<Vec3>,
    /// `--look-at X,Y,Z`.
    pub look_at: Option<Vec3>,
    /// `--fov DEG`: the vertical field of view in degrees.
    pub fov: Option<f32>,
    /// `--up y|z`.
    pub up: Option<UpAxis>,
}

/// A camera request that cannot be met; the message names the flag.
#[derive(Debug, Clone, PartialEq, Error)]
#[error("{0}")]
pub struct CameraError(pub String);

impl CameraChoice {
    /// Parses the flags' text (each `None` when the flag is absent).
    ///
    /// # Errors
    /// A [`CameraError`] naming the first flag whose value is malformed.
    pub fn from_flags(
        name: Option<&str>,
        eye: Option<&str>,
        look_at: Option<&str>,
        fov: Option<&str>,
        up: Option<&str>,
    ) -> Result<Self, CameraError> {
        Ok(Self {
            name: name.map(str::to_owned),
            eye: eye.map(|t| parse_point("--eye", t)).transpose()?,
            look_at: look_at.map(|t| parse_point("--look-at", t)).transpose()?,
            fov: fov.map(|t| parse_fov("--fov", t)).transpose()?,
            up: up.map(|t| parse_up("--up", t)).transpose()?,
        })
    }

    /// True when nothing is requested.
    pub fn is_empty(&self) -> bool {
        *self == Self::default()
    }
}

/// `X,Y,Z` as three finite numbers, or an error naming `flag`.
///
/// # Errors
/// `--eye needs three numbers like 1,2,3, got "1,2"`.
pub fn parse_point(flag: &str, text: &str) -> Result<Vec3, CameraError> {
    let parts: Vec<Option<f32>> = text
        .split(',')
        .map(|p| p.trim().parse::<f32>().ok().filter(|x| x.is_finite()))
        .collect();
    match parts[..] {
        [Some(x), Some(y), Some(z)] => Ok(Vec3::new(x, y, z)),
        _ => Err(CameraError(format!(
            "{flag} needs three numbers like 1,2,3, got {text:?}"
        ))),
    }
}

/// A field of view in degrees, `0 < fov < 180`, or an error naming `flag`.
///
/// # Errors
/// `--fov needs degrees between 0 and 180, like 45, got "200"`.
pub fn parse_fov(flag: &str, text: &str) -> Result<f32, CameraError> {
    match text.trim().parse::<f32>() {
        Ok(f) if f > 0.0 && f < 180.0 => Ok(f),
        _ => Err(CameraError(format!(
            "{flag} needs degrees between 0 and 180, like 45, got {text:?}"
        ))),
    }
}

/// `y` or `z` (any case), or an error naming `flag`.
///
/// # Errors
/// `--up needs y or z, got "x"`.
pub fn parse_up(flag: &str, text: &str) -> Result<UpAxis, CameraError> {
    match text.trim().to_ascii_lowercase().as_str() {
        "y" | "+y" => Ok(UpAxis::Y),
        "z" | "+z" => Ok(UpAxis::Z),
        _ => Err(CameraError(format!("{flag} needs y or z, got {text:?}"))),
    }
}

/// Applies `choice` to `scene` (see the module documentation); `aspect`
/// (width / height of the image to render) is used when the scene is
/// framed again. Leaves `scene` unchanged on error.
///
/// # Errors
/// A [`CameraError`] naming the flag: an unknown camera name (listing the
/// scene's), an eye equal to the point looked at, an up axis parallel to
/// the view.
pub fn apply_camera(
    scene: &mut Scene,
    choice: &CameraChoice,
    aspect: f32,
) -> Result<(), CameraError> {
    if choice.is_empty() {
        return Ok(());
    }
    let old = scene.camera;
    let mut cam = match &choice.name {
        Some(name) => named(scene, name)?,
        None => old,
    };
    let placed = choice.name.is_some() || choice.eye.is_some() || choice.look_at.is_some();
    let mut framed = None;
    if let Some(up) = choice.up {
        if placed {
            cam.up = up.vector();
        } else {
            let f = framing::frame_scene(scene, up, aspect, choice.fov);
            cam = f.camera;
            // An orthographic camera stays orthographic, seeing at the
            // target what the framed view sees there.
            if old.orthographic_half_height().is_some() && choice.fov.is_none() {
                cam = framing::orthographic_view(&cam);
            }
            framed = Some(f);
        }
    }
    if let Some(eye) = choice.eye {
        cam.eye = eye;
    }
    if let Some(at) = choice.look_at {
        cam.look_at = at;
    }
    if let Some(fov) = choice.fov {
        // A field of view makes the camera a perspective one.
        cam.fov_y_degrees = fov;
        cam.projection = chiaro_core::scene::Projection::Perspective;
    }
    check(&cam, choice)?;
    if choice.eye.is_some() || choice.look_at.is_some() {
        let b = framing::world_bounds(scene);
        if !b.is_empty() {
            let reach = (cam.eye - b.center()).length() + 0.5 * b.diagonal();
            if cam.far < reach {
                cam.far = 2.0 * reach;
            }
            // The near plane too: the old one (automatic framing puts it
            // just short of the model) would clip a model the new eye is
            // closer to, so the scan converter drew nothing.
            let gap = (cam.eye.clamp(b.min, b.max) - cam.eye).length();
            cam.near = cam.near.min((0.5 * gap).max(1e-4 * cam.far));
            if cam.near.is_nan() || cam.near <= 0.0 {
                cam.near = old.near.min(0.01);
            }
        }
    }
    if cam != old {
        let supplied = scene.lights == chiaro_io::default_lights(&old);
        scene.camera = cam;
        if supplied {
            scene.lights = match framed {
                Some(f) => chiaro_io::framed_lights(&f),
                None => chiaro_io::default_lights(&cam),
            };
        }
    }
    Ok(())
}

/// The scene's camera called `name`, else the one at index `name`.
fn named(scene: &Scene, name: &str) -> Result<Camera, CameraError> {
    if let Some(c) = scene.cameras.iter().find(|c| c.name == name) {
        return Ok(c.camera);
    }
    if let Some(c) = name
        .parse::<usize>()
        .ok()
        .and_then(|i| scene.cameras.get(i))
    {
        return Ok(c.camera);
    }
    let known = if scene.cameras.is_empty() {
        "the scene has no named cameras".to_owned()
    } else {
        let names: Vec<&str> = scene.cameras.iter().map(|c| c.name.as_str()).collect();
        format!("the scene's cameras: {}", names.join(", "))
    };
    Err(CameraError(format!(
        "--camera: no camera named {name:?} ({known})"
    )))
}

/// The checks a requested camera must pass, naming the flags involved.
fn check(cam: &Camera, choice: &CameraChoice) -> Result<(), CameraError> {
    let view = cam.look_at - cam.eye;
    if view.length_squared() == 0.0 {
        return Err(CameraError(format!(
            "--eye and --look-at are the same point ({}, {}, {}): the camera would look nowhere",
            cam.eye.x, cam.eye.y, cam.eye.z
        )));
    }
    if view.cross(cam.up).length_squared() <= 1e-12 * view.length_squared() {
        let up = choice.up.map_or("the camera's up", UpAxis::name);
        return Err(CameraError(format!(
            "--up {up}: the view from --eye to --look-at is parallel to the up axis; \
             choose another --up or move --eye"
        )));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The message of a result that must be an error.
    fn refusal<T: std::fmt::Debug>(r: Result<T, CameraError>) -> String {
        r.expect_err("an error").0
    }

    #[test]
    fn flags_parse_or_name_themselves() {
        assert_eq!(
            parse_point("--eye", "1,-2, 3.5"),
            Ok(Vec3::new(1.0, -2.0, 3.5))
        );
        let e = parse_point("--eye", "1,2").expect_err("an error");
        assert_eq!(e.0, "--eye needs three numbers like 1,2,3, got \"1,2\"");
        assert!(refusal(parse_point("--look-at", "1,2,nan")).starts_with("--look-at needs"));
        assert!(parse_point("--eye", "1,2,3,4").is_err());
        assert!(refusal(parse_fov("--fov", "180")).starts_with("--fov needs"));
        assert_eq!(parse_fov("--fov", "30"), Ok(30.0));
        assert_eq!(parse_up("--up", "Z"), Ok(UpAxis::Z));
        assert!(refusal(parse_up("--up", "x")).contains("--up needs y or z"));
    }

    #[test]
    fn an_unknown_name_lists_the_cameras_and_changes_nothing() {
        let mut s = Scene::default();
        s.cameras.push(chiaro_core::scene::NamedCamera {
            name: "top".into(),
            camera: Camera {
                eye: Vec3::new(0.0, 5.0, 0.1),
                ..Camera::default()
            },
        });
        let before = s.clone();
        let choice = CameraChoice {
            name: Some("side".into()),
            ..Default::default()
        };
        let e = apply_camera(&mut s, &choice, 1.0).expect_err("an error");
        assert!(e.0.contains("\"side\"") && e.0.contains("top"), "{e}");
        assert_eq!(s, before);
        let by_index = CameraChoice {
            name: Some("0".into()),
            ..Default::default()
        };
        apply_camera(&mut s, &by_index, 1.0).expect("index");
        assert_eq!(s.camera.eye, Vec3::new(0.0, 5.0, 0.1));
    }

    #[test]
    fn a_degenerate_view_is_refused() {
        let mut s = Scene::default();
        let same = CameraChoice {
            eye: Some(Vec3::ZERO),
            ..Default::default()
        };
        assert!(refusal(apply_camera(&mut s, &same, 1.0)).contains("same point"));
        let parallel = CameraChoice {
            eye: Some(Vec3::new(0.0, 0.0, 5.0)),
            up: Some(UpAxis::Z),
            ..Default::default()
        };
        assert!(refusal(apply_camera(&mut s, &parallel, 1.0)).starts_with("--up z"));
    }
}
