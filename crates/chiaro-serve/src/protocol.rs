//! The messages between the page and the server, and their validation.
//!
//! The page sends JSON text messages over the WebSocket:
//!
//! ```json
//! {"type": "render", "id": 3, "width": 256, "height": 256,
//!  "orbit": {"yaw": 0.2, "pitch": -0.1, "zoom": 1.0}, "progressive": true,
//!  "refine": true,
//!  "views": [{"technique": "phong", "shadows": "ray", "transparency": "scene",
//!             "model": "scene", "samples": 1, "light_samples": 0},
//!            {"technique": "whitted"}]}
//! {"type": "save", "view": 0, "format": "exr"}
//! ```
//!
//! A render request names one view, or two for the split view (then the
//! server also sends the ꟻLIP map and the metrics of the first view
//! against the second, those of `chiaro compare`). Every field but `type` has a default;
//! sizes and samples beyond [`Limits`] are refused with an error message,
//! not clamped, so the page knows. The server answers with binary frames
//! (see [`encode_frame`]) and JSON text messages (`pass`, `first`, `done`,
//! `metrics`, `error`).
//!
//! While the camera moves the page asks for drafts (one sample per pixel
//! and per area light, half resolution); when it stops, for `refine`: the
//! server first renders a quick pass at full resolution (one sample per
//! pixel and per area light, see [`draft_settings`]), then the requested
//! quality, announcing each with `{"type": "pass", "pass": k, "of": n}`.

use chiaro::scene::{ReflectanceModel, ShadowMethod, TransparencyMode};
use chiaro::{RenderSettings, Scene, Technique, Vec3};
use serde::{Deserialize, Serialize};

/// Bounds on what a page may ask for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct Limits {
    /// Largest width or height in pixels.
    pub max_side: u32,
    /// Largest samples per pixel.
    pub max_samples: u32,
    /// Largest incoming WebSocket message in bytes.
    pub max_message_bytes: usize,
}

impl Default for Limits {
    fn default() -> Self {
        Self {
            max_side: 1024,
            max_samples: 256,
            max_message_bytes: 16 * 1024,
        }
    }
}

/// The camera relative to the scene's own: yaw about the up axis and pitch
/// towards it (radians), and a zoom factor dividing the eye distance.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Orbit {
    /// Rotation about the camera's up axis around `look_at`, radians.
    pub yaw: f32,
    /// Elevation change, radians (the result is kept within ±85°).
    pub pitch: f32,
    /// Distance factor: the eye moves to `look_at + (eye - look_at) / zoom`.
    pub zoom: f32,
}

impl Default for Orbit {
    fn default() -> Self {
        Self {
            yaw: 0.0,
            pitch: 0.0,
            zoom: 1.0,
        }
    }
}

/// One side of the split view.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct View {
    /// Technique name (`phong`, `whitted`, ...).
    pub technique: String,
    /// Shadow method name, or `scene` for the scene's setting.
    pub shadows: String,
    /// Transparency mode name, or `scene`.
    pub transparency: String,
    /// Illumination (reflectance) model for every material, or `scene`.
    pub model: String,
    /// Samples per pixel; 0 keeps the scene's.
    pub samples: u32,
    /// Samples per area light per shading point; 0 keeps the scene's.
    pub light_samples: u32,
}

impl Default for View {
    fn default() -> Self {
        Self {
            technique: "phong".into(),
            shadows: "scene".into(),
            transparency: "scene".into(),
            model: "scene".into(),
            samples: 0,
            light_samples: 0,
        }
    }
}

/// A message from the page.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(tag = "type", rename_all = "kebab-case", deny_unknown_fields)]
pub enum Request {
    /// Render one or two views.
    Render {
        /// Echoed in every answer so the page can drop stale frames.
        #[serde(default)]
        id: u64,
        /// Image width; 0 keeps the scene's.
        #[serde(default)]
        width: u32,
        /// Image height; 0 keeps the scene's.
        #[serde(default)]
        height: u32,
        /// Camera relative to the scene's.
        #[serde(default)]
        orbit: Orbit,
        /// Send bands as they complete (where the technique supports crop).
        #[serde(default)]
        progressive: bool,
        /// Render a quick draft pass first when it is cheaper than the
        /// requested quality.
        #[serde(default)]
        refine: bool,
        /// One or two views.
        views: Vec<View>,
    },
    /// Send the last finished render of view `view` as a file.
    Save {
        /// 0 (left) or 1 (right).
        #[serde(default)]
        view: usize,
        /// `png` or `exr`.
        format: String,
    },
}

/// A validated render job.
#[derive(Debug, Clone)]
pub struct Job {
    /// The request id.
    pub id: u64,
    /// The camera of every view: the scene's, orbited.
    pub camera: chiaro::scene::Camera,
    /// The illumination model per view that replaces every material's
    /// ([`with_model`]); `None` keeps the scene's.
    pub models: Vec<Option<ReflectanceModel>>,
    /// The settings per view.
    pub settings: Vec<RenderSettings>,
    /// Send bands as they complete.
    pub progressive: bool,
    /// Render a quick draft pass first.
    pub refine: bool,
}

/// The quick pass of a refining render: `s` with one sample per pixel and
/// one sample per area light.
pub fn draft_settings(s: &RenderSettings) -> RenderSettings {
    RenderSettings {
        samples: 1,
        light_samples: 1,
        ..s.clone()
    }
}

/// A count of `what` the page asks for: `None` for 0 (keep the scene's),
/// an error above `max`.
fn page_count(requested: u32, what: &str, max: u32) -> Result<Option<u32>, String> {
    if requested > max {
        return Err(format!("{requested} {what} exceed the page limit of {max}"));
    }
    Ok((requested > 0).then_some(requested))
}

fn parse_named<T: for<'de> Deserialize<'de>>(what: &str, name: &str) -> Result<T, String> {
    serde_json::from_value(serde_json::Value::String(name.into()))
        .map_err(|_| format!("unknown {what} `{name}`"))
}

/// The camera of `base` orbited by `orbit` (see [`Orbit`]).
///
/// # Errors
/// A message if a number is not finite or the zoom is not in `[0.05, 20]`.
pub fn orbit_camera(
    base: &chiaro::scene::Camera,
    orbit: Orbit,
) -> Result<chiaro::scene::Camera, String> {
    if !(orbit.yaw.is_finite() && orbit.pitch.is_finite() && orbit.zoom.is_finite()) {
        return Err("orbit values must be finite numbers".into());
    }
    if !(0.05..=20.0).contains(&orbit.zoom) {
        return Err(format!("zoom {} is outside [0.05, 20]", orbit.zoom));
    }
    let offset = base.eye - base.look_at;
    let dist = offset.length();
    let up = base.up.normalize_or(Vec3::Y);
    if dist <= 0.0 || !dist.is_finite() {
        return Ok(*base);
    }
    let d = offset / dist;
    let el0 = d.dot(up).clamp(-1.0, 1.0).asin();
    let horizontal = d - up * d.dot(up);
    let e1 = if horizontal.length_squared() > 1e-10 {
        horizontal.normalize()
    } else {
        up.any_orthonormal_vector()
    };
    let e2 = up.cross(e1);
    let limit = 85f32.to_radians();
    let el = (el0 + orbit.pitch).clamp(-limit, limit);
    let (sy, cy) = orbit.yaw.sin_cos();
    let nd = (e1 * cy + e2 * sy) * el.cos() + up * el.sin();
    let mut cam = *base;
    cam.eye = base.look_at + nd * (dist / orbit.zoom);
    // An orthographic view zooms by its film, not by its distance.
    if let chiaro::scene::Projection::Orthographic { half_height } = base.projection {
        cam.projection = chiaro::scene::Projection::Orthographic {
            half_height: half_height / orbit.zoom,
        };
    }
    Ok(cam)
}

impl Request {
    /// Parses a text message.
    ///
    /// # Errors
    /// A message naming what is wrong with the JSON.
    pub fn parse(text: &str) -> Result<Self, String> {
        serde_json::from_str(text).map_err(|e| format!("bad request: {e}"))
    }
}

/// Turns a render request into a [`Job`] for `scene`, refusing anything
/// beyond `limits`.
///
/// # Errors
/// A message naming the offending field.
pub fn make_job(
    scene: &Scene,
    limits: &Limits,
    id: u64,
    width: u32,
    height: u32,
    orbit: Orbit,
    progressive: bool,
    refine: bool,
    views: &[View],
) -> Result<Job, String> {
    if views.is_empty() || views.len() > 2 {
        return Err(format!("a render needs 1 or 2 views, not {}", views.len()));
    }
    let width = if width == 0 {
        scene.render.width
    } else {
        width
    };
    let height = if height == 0 {
        scene.render.height
    } else {
        height
    };
    if width > limits.max_side || height > limits.max_side {
        return Err(format!(
            "{width}x{height} exceeds the page limit of {0}x{0} pixels",
            limits.max_side
        ));
    }
    let camera = orbit_camera(&scene.camera, orbit)?;
    let mut models = Vec::new();
    let mut settings = Vec::new();
    for v in views {
        let technique = Technique::from_name(&v.technique).ok_or_else(|| {
            format!(
                "unknown technique `{}` (available: {})",
                v.technique,
                chiaro::technique_list()
            )
        })?;
        let mut s = scene.render.clone();
        s.technique = technique;
        s.width = width;
        s.height = height;
        s.crop = None;
        if let Some(n) = page_count(v.samples, "samples", limits.max_samples)? {
            s.samples = n;
        }
        s.samples = s.samples.min(limits.max_samples);
        if let Some(n) = page_count(v.light_samples, "light samples", limits.max_samples)? {
            s.light_samples = n;
        }
        if v.shadows != "scene" {
            s.shadows = parse_named::<ShadowMethod>("shadow method", &v.shadows)?;
        }
        if v.transparency != "scene" {
            s.transparency = Some(parse_named::<TransparencyMode>(
                "transparency mode",
                &v.transparency,
            )?);
        }
        let model = if v.model == "scene" {
            None
        } else {
            Some(parse_named::<ReflectanceModel>(
                "illumination model",
                &v.model,
            )?)
        };
        chiaro::check_settings(&s).map_err(settings_message)?;
        models.push(model);
        settings.push(s);
    }
    Ok(Job {
        id,
        camera,
        models,
        settings,
        progressive,
        refine,
    })
}

/// `scene` with `model` as every material's illumination model (a view's
/// `model` other than `scene`).
pub fn with_model(scene: &Scene, model: ReflectanceModel) -> Scene {
    let mut s = scene.clone();
    for m in &mut s.materials {
        m.model = model;
    }
    s
}

/// The settings errors of [`chiaro::check_settings`] for the page: each
/// naming its setting, on one line.
fn settings_message(e: chiaro_core::error::CoreError) -> String {
    match e {
        chiaro_core::error::CoreError::InvalidScene { issues } => {
            let issues: Vec<&str> = issues
                .iter()
                .map(|i| i.strip_prefix("error: ").unwrap_or(i))
                .collect();
            format!("invalid render settings: {}", issues.join("; "))
        }
        e => e.to_string(),
    }
}

/// Header of a binary frame sent to the page.
#[derive(Debug, Clone, Serialize)]
pub struct FrameHeader {
    /// `tile` (PNG of a band), `diff` (PNG of the difference image) or
    /// `file` (a saved file's bytes).
    pub kind: &'static str,
    /// The request id.
    pub id: u64,
    /// View index (0 or 1); 2 for the difference image.
    pub view: usize,
    /// Band position and size, pixels.
    pub x: u32,
    /// Band top row.
    pub y: u32,
    /// Band width.
    pub w: u32,
    /// Band height.
    pub h: u32,
    /// Whole image width.
    pub width: u32,
    /// Whole image height.
    pub height: u32,
    /// File name suggested for `file` frames.
    pub name: String,
}

/// A binary frame: a little-endian `u32` header length, the header as JSON,
/// then the payload (PNG or file bytes).
pub fn encode_frame(header: &FrameHeader, payload: &[u8]) -> Vec<u8> {
    let h = serde_json::to_vec(header).unwrap_or_default();
    let mut out = Vec::with_capacity(4 + h.len() + payload.len());
    out.extend_from_slice(&(h.len() as u32).to_le_bytes());
    out.extend_from_slice(&h);
    out.extend_from_slice(payload);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cam() -> chiaro::scene::Camera {
        chiaro::scene::Camera {
            eye: Vec3::new(0.0, 0.0, -10.0),
            look_at: Vec3::ZERO,
            up: Vec3::Y,
            ..Default::default()
        }
    }

    #[test]
    fn zero_orbit_keeps_the_camera() {
        let c = orbit_camera(&cam(), Orbit::default()).expect("valid");
        assert!((c.eye - cam().eye).length() < 1e-4, "{:?}", c.eye);
    }

    #[test]
    fn yaw_keeps_distance_and_height() {
        let c = orbit_camera(
            &cam(),
            Orbit {
                yaw: 1.0,
                ..Default::default()
            },
        )
        .expect("valid");
        assert!((c.eye.length() - 10.0).abs() < 1e-3);
        assert!(c.eye.y.abs() < 1e-4);
        let q = orbit_camera(
            &cam(),
            Orbit {
                yaw: std::f32::consts::FRAC_PI_2,
                ..Default::default()
            },
        )
        .expect("valid");
        assert!(
            q.eye.z.abs() < 1e-3 && (q.eye.x.abs() - 10.0).abs() < 1e-3,
            "{:?}",
            q.eye
        );
    }

    #[test]
    fn zoom_divides_an_orthographic_film() {
        let base = chiaro::scene::Camera {
            projection: chiaro::scene::Projection::Orthographic { half_height: 3.0 },
            ..cam()
        };
        let orbit = Orbit {
            zoom: 2.0,
            ..Default::default()
        };
        let c = orbit_camera(&base, orbit).expect("valid");
        assert_eq!(c.orthographic_half_height(), Some(1.5));
    }

    #[test]
    fn pitch_is_clamped_and_zoom_divides_distance() {
        let c = orbit_camera(
            &cam(),
            Orbit {
                pitch: 10.0,
                zoom: 2.0,
                yaw: 0.0,
            },
        )
        .expect("valid");
        assert!((c.eye.length() - 5.0).abs() < 1e-3);
        assert!(c.eye.y < 5.0 && c.eye.y > 4.9, "{:?}", c.eye);
        assert!(
            orbit_camera(
                &cam(),
                Orbit {
                    zoom: 0.0,
                    ..Default::default()
                }
            )
            .is_err()
        );
        assert!(
            orbit_camera(
                &cam(),
                Orbit {
                    yaw: f32::NAN,
                    ..Default::default()
                }
            )
            .is_err()
        );
    }

    /// [`make_job`] of `views` at `width` x `height`, the scene's own
    /// camera, neither progressive nor refining.
    fn job(
        scene: &Scene,
        limits: &Limits,
        width: u32,
        height: u32,
        views: &[View],
    ) -> Result<Job, String> {
        make_job(
            scene,
            limits,
            0,
            width,
            height,
            Orbit::default(),
            false,
            false,
            views,
        )
    }

    #[test]
    fn limits_refuse_large_requests() {
        let scene = Scene::default();
        let l = Limits::default();
        let v = [View::default()];
        assert!(job(&scene, &l, 100_000, 10, &v).is_err());
        let many = [View {
            samples: 1 << 20,
            ..View::default()
        }];
        assert!(job(&scene, &l, 16, 16, &many).is_err());
        let bad = [View {
            technique: "nope".into(),
            ..View::default()
        }];
        assert!(job(&scene, &l, 16, 16, &bad).is_err());
        let ok = job(&scene, &l, 16, 16, &v).expect("valid");
        assert_eq!(ok.settings[0].width, 16);
    }

    #[test]
    fn light_samples_override_and_draft() {
        let scene = Scene::default();
        let l = Limits::default();
        let v = [View {
            samples: 8,
            light_samples: 3,
            ..View::default()
        }];
        let j = make_job(&scene, &l, 0, 16, 16, Orbit::default(), false, true, &v).expect("valid");
        assert_eq!((j.settings[0].samples, j.settings[0].light_samples), (8, 3));
        assert!(j.refine);
        let d = draft_settings(&j.settings[0]);
        assert_eq!((d.samples, d.light_samples, d.width), (1, 1, 16));
        let keep = job(&scene, &l, 16, 16, &[View::default()]).expect("valid");
        assert_eq!(keep.settings[0].light_samples, scene.render.light_samples);
        let many = [View {
            light_samples: l.max_samples + 1,
            ..View::default()
        }];
        assert!(job(&scene, &l, 16, 16, &many).is_err());
    }

    /// A render setting is checked by the facade's one settings check,
    /// and its message names the setting: nothing is silently repaired.
    #[test]
    fn render_settings_are_checked_by_the_facade() {
        let mut scene = Scene::default();
        scene.render.samples = 0;
        scene.render.radiosity.tolerance = 2.0;
        let e = job(&scene, &Limits::default(), 16, 16, &[View::default()])
            .expect_err("invalid settings");
        assert_eq!(
            e,
            "invalid render settings: render.samples: expected 1..=65536, got 0; \
             render.radiosity.tolerance: expected a number in (0, 1), got 2"
        );
        let v = [View {
            samples: 4,
            ..View::default()
        }];
        scene.render.radiosity.tolerance = 0.5;
        let j = job(&scene, &Limits::default(), 16, 16, &v)
            .expect("the view's samples replace the scene's");
        assert_eq!(j.settings[0].samples, 4);
    }

    #[test]
    fn overrides_parse_names() {
        let scene = Scene::default();
        let v = [View {
            shadows: "map".into(),
            transparency: "screen-door".into(),
            model: "blinn".into(),
            ..View::default()
        }];
        let j = job(&scene, &Limits::default(), 8, 8, &v).expect("valid");
        assert_eq!(j.models, [Some(ReflectanceModel::Blinn)]);
        assert_eq!(j.settings[0].shadows, ShadowMethod::Map);
        assert_eq!(
            j.settings[0].transparency,
            Some(TransparencyMode::ScreenDoor)
        );
        let bad = [View {
            shadows: "sometimes".into(),
            ..View::default()
        }];
        assert!(job(&scene, &Limits::default(), 8, 8, &bad).is_err());
    }
}
