//! Williams (1978) shadow z-buffers: a depth image of the scene from each
//! light, and several over an area light's surface (Heckbert and Herf 1997).

use crate::raster::{DepthKey, RasterTri, Rect, Viewport, rasterize};
use crate::shadows::Blocker;
use crate::shadows::blockers;
use crate::shadows::plan_budget;
use crate::shadows::rays::RayShadows;
use chiaro_core::accel::alpha::Coverage;
use chiaro_core::accel::{Hit, intersect_triangle};
use chiaro_core::geometry::{Frame, Ray};
use chiaro_core::prepared::PreparedScene;
use chiaro_core::scene::{AreaShape, Light, SHADOW_MAP_RESOLUTIONS, ShadowMapSettings};
use chiaro_core::shading::{LightSample, samples_for_light, stratum};
use glam::{Mat4, Vec2, Vec3, Vec4};
use rayon::prelude::*;

/// One depth image from a light position (or direction).
pub(crate) struct MapView {
    /// `view_from_world`: the light looks down `-z`.
    pub(crate) view: Mat4,
    /// `clip_from_world`.
    pub(crate) clip_from_world: Mat4,
    /// Orthographic half-extent in scene units; 0 for a perspective view.
    pub(crate) ortho_half: f32,
    /// `tan(fov / 2)` of a perspective view.
    pub(crate) tan_half: f32,
    /// Texels per side.
    pub(crate) res: u32,
    /// Distance along the view axis of the nearest opaque caster, per texel
    /// (`INFINITY` where none).
    pub(crate) depth: Vec<f32>,
    /// Distance of the nearest transparent caster in front of the opaque
    /// one, and the product of the transmit colours of all transparent
    /// casters in front of it (empty when the scene has none).
    pub(crate) trans_depth: Vec<f32>,
    pub(crate) trans_tint: Vec<Vec3>,
}

impl MapView {
    pub(crate) fn perspective(
        eye: Vec3,
        forward: Vec3,
        up_hint: Vec3,
        fov_deg: f32,
        res: u32,
    ) -> Self {
        let cam = chiaro_core::scene::Camera {
            eye,
            look_at: eye + forward,
            up: up_hint,
            fov_y_degrees: fov_deg,
            near: 1e-4,
            far: 1e30,
            ..Default::default()
        };
        let view = cam.view_matrix();
        Self {
            view,
            clip_from_world: cam.projection_matrix(1.0) * view,
            ortho_half: 0.0,
            tan_half: (fov_deg.to_radians() * 0.5).tan(),
            res,
            depth: Vec::new(),
            trans_depth: Vec::new(),
            trans_tint: Vec::new(),
        }
    }

    pub(crate) fn orthographic(center: Vec3, dir: Vec3, radius: f32, res: u32) -> Self {
        let eye = center - dir * (2.0 * radius);
        let cam = chiaro_core::scene::Camera {
            eye,
            look_at: center,
            ..Default::default()
        };
        let view = cam.view_matrix();
        let s = 1.0 / radius;
        // x, y scaled to [-1, 1]; z_clip = -z_view (the distance along the
        // axis, >= 0 in front), w = 1.
        let proj = Mat4::from_cols(
            Vec4::new(s, 0.0, 0.0, 0.0),
            Vec4::new(0.0, s, 0.0, 0.0),
            Vec4::new(0.0, 0.0, -1.0, 0.0),
            Vec4::new(0.0, 0.0, 0.0, 1.0),
        );
        Self {
            view,
            clip_from_world: proj * view,
            ortho_half: radius,
            tan_half: 0.0,
            res,
            depth: Vec::new(),
            trans_depth: Vec::new(),
            trans_tint: Vec::new(),
        }
    }

    /// Rasterizes the casters, one sample at each texel centre.
    pub(crate) fn render(
        &mut self,
        ps: &PreparedScene<'_>,
        blockers: &[Blocker],
        any_filter: bool,
    ) {
        let res = self.res;
        let n = (res * res) as usize;
        let ortho = self.ortho_half > 0.0;
        let vp = Viewport {
            width: res,
            height: res,
            cull_back: false,
            depth_key: if ortho {
                DepthKey::ZOverW
            } else {
                DepthKey::InvW
            },
        };
        let rect = Rect {
            x0: 0,
            y0: 0,
            x1: res,
            y1: res,
        };
        let centre = [[
            (crate::raster::SUBPIXEL / 2) as i32,
            (crate::raster::SUBPIXEL / 2) as i32,
        ]];
        let m = self.clip_from_world;
        let mut key = vec![f32::NEG_INFINITY; n];
        let mut scratch = Vec::new();
        let mut tris: Vec<RasterTri> = Vec::new();
        let mut filters: Vec<(u32, Vec3)> = Vec::new();
        // MASK: a texel whose centre ray meets a masked caster on a cut-out
        // point is not covered by it (the same `Coverage` as the ray tracers).
        let coverage = Coverage::new(ps);
        let clip_to_world = m.inverse();
        let cut_out = |c: &Coverage, t: u32, x: u32, y: u32| {
            let nx = 2.0 * (x as f32 + 0.5) / res as f32 - 1.0;
            let ny = 1.0 - 2.0 * (y as f32 + 0.5) / res as f32;
            let a = clip_to_world * Vec4::new(nx, ny, 0.25, 1.0);
            let b = clip_to_world * Vec4::new(nx, ny, 0.75, 1.0);
            let (a, b) = (a.truncate() / a.w, b.truncate() / b.w);
            let mut ray = Ray::new(a, b - a);
            ray.t_min = f32::NEG_INFINITY;
            ray.t_max = f32::INFINITY;
            let [p0, p1, p2] = ps.triangles[t as usize].map(|i| ps.positions[i as usize]);
            intersect_triangle(&ray, p0, p1, p2).is_some_and(|(th, u, v)| {
                !c.covers(&Hit {
                    t: th,
                    prim: t,
                    u,
                    v,
                })
            })
        };
        for (t, tri) in ps.triangles.iter().enumerate() {
            let b = blockers[t];
            if b == Blocker::Ignore {
                continue;
            }
            let c = tri.map(|i| m * ps.positions[i as usize].extend(1.0));
            tris.clear();
            vp.setup(c, t as u32, &mut scratch, &mut tris);
            match b {
                Blocker::Opaque => {
                    let masked = coverage.as_ref().filter(|c| c.is_masked(t as u32));
                    for rt in &tris {
                        rasterize(rt, rect, &centre, |x, y, _, k| {
                            if masked.is_some_and(|c| cut_out(c, t as u32, x, y)) {
                                return;
                            }
                            let i = (y * res + x) as usize;
                            if k > key[i] {
                                key[i] = k;
                            }
                        });
                    }
                }
                Blocker::Filter(kt) => {
                    // Deferred until the opaque depth is complete.
                    filters.push((t as u32, kt));
                }
                Blocker::Ignore => {}
            }
        }
        let to_depth = |k: f32| {
            if k == f32::NEG_INFINITY {
                f32::INFINITY
            } else if ortho {
                -k
            } else {
                1.0 / k
            }
        };
        if any_filter && !filters.is_empty() {
            let mut tkey = vec![f32::NEG_INFINITY; n];
            let mut tint = vec![Vec3::ONE; n];
            for &(t, kt) in &filters {
                let c = ps.triangles[t as usize].map(|i| m * ps.positions[i as usize].extend(1.0));
                tris.clear();
                vp.setup(c, t, &mut scratch, &mut tris);
                for rt in &tris {
                    rasterize(rt, rect, &centre, |x, y, _, k| {
                        let i = (y * res + x) as usize;
                        if k > key[i] {
                            tint[i] *= kt;
                            if k > tkey[i] {
                                tkey[i] = k;
                            }
                        }
                    });
                }
            }
            self.trans_depth = tkey.into_iter().map(to_depth).collect();
            self.trans_tint = tint;
        }
        self.depth = key.into_iter().map(to_depth).collect();
    }

    /// Percentage-closer filtered visibility (Reeves, Salesin and Cook 1987)
    /// of the point `p` with unit geometric normal `ng`. Each tap compares
    /// the stored depth with the depth of the receiver's tangent plane along
    /// the tap's own light ray ("receiver plane depth bias"), plus a
    /// constant and a slope-scaled bias in texels of world size.
    pub(crate) fn lookup(&self, p: Vec3, ng: Vec3, wi: Vec3, sm: &ShadowMapSettings) -> Vec3 {
        let pv = self.view.transform_point3(p);
        let nv = self.view.transform_vector3(ng);
        let depth = -pv.z;
        if depth <= 0.0 {
            return Vec3::ONE;
        }
        let res = self.res as f32;
        let ortho = self.ortho_half > 0.0;
        // Position in texel units, and the world size of one texel there.
        let (ndc, texel) = if ortho {
            (
                Vec2::new(pv.x, pv.y) / self.ortho_half,
                2.0 * self.ortho_half / res,
            )
        } else {
            (
                Vec2::new(pv.x, pv.y) / (depth * self.tan_half),
                2.0 * depth * self.tan_half / res,
            )
        };
        let tx = (ndc.x * 0.5 + 0.5) * res;
        let ty = (0.5 - ndc.y * 0.5) * res;
        if !(tx.is_finite() && ty.is_finite()) {
            return Vec3::ONE;
        }
        let cos = ng.dot(wi).abs().max(0.05);
        let tan = (1.0 - cos * cos).max(0.0).sqrt() / cos;
        let bias = texel * (sm.bias + sm.slope_bias * tan.min(10.0));
        let r = sm.pcf_radius.min(8) as i32;
        let (cx, cy) = (tx.floor() as i32, ty.floor() as i32);
        let nz = nv.dot(pv);
        let mut sum = Vec3::ZERO;
        let mut taps = 0.0f32;
        for dy in -r..=r {
            for dx in -r..=r {
                let (x, y) = (cx + dx, cy + dy);
                let (xc, yc) = (
                    x.clamp(0, self.res as i32 - 1),
                    y.clamp(0, self.res as i32 - 1),
                );
                // Receiver plane depth along the ray through the texel centre.
                let u = Vec2::new(
                    (x as f32 + 0.5) / res * 2.0 - 1.0,
                    1.0 - (y as f32 + 0.5) / res * 2.0,
                );
                let d = if ortho {
                    let o = Vec3::new(u.x * self.ortho_half, u.y * self.ortho_half, 0.0);
                    let denom = -nv.z;
                    let t = nv.dot(pv - o) / denom;
                    if denom.abs() > 1e-6 && t.is_finite() {
                        t
                    } else {
                        depth
                    }
                } else {
                    let dir = Vec3::new(u.x * self.tan_half, u.y * self.tan_half, -1.0);
                    let denom = nv.dot(dir);
                    let t = nz / denom;
                    if denom.abs() > 1e-6 && t.is_finite() && t > 0.0 {
                        t
                    } else {
                        depth
                    }
                };
                // Never trust the plane more than a few texels away.
                let d = d.clamp(depth - 4.0 * bias - texel, depth + 4.0 * bias + texel);
                let i = (yc as u32 * self.res + xc as u32) as usize;
                let lit_opaque = d - bias <= self.depth[i];
                sum += if !lit_opaque {
                    Vec3::ZERO
                } else if !self.trans_depth.is_empty() && d - bias > self.trans_depth[i] {
                    self.trans_tint[i]
                } else {
                    Vec3::ONE
                };
                taps += 1.0;
            }
        }
        sum / taps
    }
}

/// The shadow maps of one light: a single view (directional light, narrow
/// spot), a cube (six views: point light, wide spot), or for an area light
/// several cubes over its surface.
pub(crate) struct LightMaps {
    /// Views, grouped by 6 for cubes.
    pub(crate) views: Vec<MapView>,
    /// Cube centres (one per group of six views); empty for a single view.
    pub(crate) cube_centres: Vec<Vec3>,
    /// For area lights: samples per side of the map grid (`k x k` maps).
    pub(crate) grid: u32,
}

/// Shadow z-buffers of every light of a scene.
pub(crate) struct ShadowMaps {
    /// Per light: its maps (`None` for ambient lights and for lights past
    /// the budget).
    lights: Vec<Option<LightMaps>>,
    /// Per light: true when it uses shadow rays (its maps did not fit the
    /// budget).
    by_ray: Vec<bool>,
    /// The shadow rays of the lights in `by_ray`, built when there is one.
    rays: Option<RayShadows>,
    settings: ShadowMapSettings,
    /// Bytes of the maps built (depth and transparency buffers).
    pub(crate) bytes: u64,
    /// Which lights fell back to shadow rays and why, when any did.
    pub(crate) warning: Option<String>,
}

/// Bytes per texel of a shadow-map view: the opaque depth (`f32`), and with
/// transparent casters their depth and tint (`f32` + `Vec3`).
pub(crate) fn texel_bytes(any_filter: bool) -> u64 {
    if any_filter { 4 + 4 + 12 } else { 4 }
}

/// The most cube maps built over one area light.
pub(crate) const MAX_AREA_MAPS_PER_SIDE: u32 = 4;
/// The most area-light cube maps built in total (beyond that, one per light).
pub(crate) const MAX_AREA_MAPS: usize = 64;

/// A point of an area light's surface for the 2D sample `u` (the same
/// parameterisation as [`chiaro_core::shading::sample_light`]; a sphere
/// gives its centre).
pub(crate) fn area_point(shape: &AreaShape, u: Vec2) -> Vec3 {
    match *shape {
        AreaShape::Quad {
            corner,
            edge_u,
            edge_v,
        } => corner + u.x * edge_u + u.y * edge_v,
        AreaShape::Disk {
            center,
            normal,
            radius,
        } => {
            let d = chiaro_core::sampling::sample_concentric_disk(u) * radius;
            let f = Frame::from_normal(normal.normalize_or_zero());
            center + f.to_world(Vec3::new(d.x, d.y, 0.0))
        }
        AreaShape::Sphere { center, .. } => center,
        AreaShape::Triangle { a, b, c } => {
            let bary = chiaro_core::sampling::sample_uniform_triangle(u);
            a * bary.x + b * bary.y + c * (1.0 - bary.x - bary.y)
        }
    }
}

/// The six 90-degree views of a cube map centred at `c`, in the order
/// `+x, -x, +y, -y, +z, -z` (see [`cube_face`]).
pub(crate) fn cube_views(c: Vec3, res: u32) -> Vec<MapView> {
    let faces = [
        (Vec3::X, Vec3::Y),
        (Vec3::NEG_X, Vec3::Y),
        (Vec3::Y, Vec3::Z),
        (Vec3::NEG_Y, Vec3::Z),
        (Vec3::Z, Vec3::Y),
        (Vec3::NEG_Z, Vec3::Y),
    ];
    faces
        .iter()
        .map(|&(f, up)| MapView::perspective(c, f, up, 90.0, res))
        .collect()
}

/// The cube face whose view contains direction `d`.
pub(crate) fn cube_face(d: Vec3) -> usize {
    let a = d.abs();
    if a.x >= a.y && a.x >= a.z {
        if d.x >= 0.0 { 0 } else { 1 }
    } else if a.y >= a.z {
        if d.y >= 0.0 { 2 } else { 3 }
    } else if d.z >= 0.0 {
        4
    } else {
        5
    }
}

impl ShadowMaps {
    /// Builds (in parallel over views) the maps of every light of `ps`.
    /// `area_samples` is the `light_samples` setting: an area light gets a
    /// grid of up to 4 x 4 cube maps at the strata of its samples, at a
    /// quarter of `settings.resolution`.
    ///
    /// Before anything is allocated, the lights' maps are sized in light
    /// order against `budget` bytes; a light whose maps do not fit in what
    /// is left uses shadow rays instead, and [`ShadowMaps::warning`] names
    /// those lights.
    pub(crate) fn new(
        ps: &PreparedScene<'_>,
        settings: &ShadowMapSettings,
        area_samples: u32,
        budget: u64,
    ) -> Self {
        let res = settings.resolution.clamp(
            *SHADOW_MAP_RESOLUTIONS.start(),
            *SHADOW_MAP_RESOLUTIONS.end(),
        );
        let centre = (ps.bounds.min + ps.bounds.max) * 0.5;
        let radius = ((ps.bounds.max - ps.bounds.min).length() * 0.5).max(1e-3);
        let radius = if radius.is_finite() { radius } else { 1.0 };
        // The lights of a grouped emissive mesh get no maps: the renderer
        // gives their samples shadow rays.
        let group = chiaro_core::shading::EmitterGroup::of_scene(ps, area_samples);
        let grouped = |li: usize| group.as_ref().is_some_and(|g| g.contains(li));
        let area_lights = ps
            .lights
            .iter()
            .enumerate()
            .filter(|&(li, l)| matches!(l, Light::Area { .. }) && !grouped(li))
            .count();
        let mut lights: Vec<Option<LightMaps>> = ps
            .lights
            .iter()
            .enumerate()
            .map(|(li, light)| match light {
                _ if grouped(li) => None,
                Light::Ambient { .. } => None,
                Light::Directional { direction, .. } => Some(LightMaps {
                    views: vec![MapView::orthographic(
                        centre,
                        direction.normalize_or(Vec3::NEG_Y),
                        radius,
                        res,
                    )],
                    cube_centres: Vec::new(),
                    grid: 0,
                }),
                Light::Point { position, .. } => Some(LightMaps {
                    views: cube_views(*position, res),
                    cube_centres: vec![*position],
                    grid: 0,
                }),
                Light::Spot(s) if s.cone_degrees <= 60.0 => Some(LightMaps {
                    views: vec![MapView::perspective(
                        s.position,
                        s.direction.normalize_or(Vec3::NEG_Y),
                        if s.direction.normalize_or(Vec3::NEG_Y).y.abs() > 0.9 {
                            Vec3::Z
                        } else {
                            Vec3::Y
                        },
                        2.0 * s.cone_degrees + 2.0,
                        res,
                    )],
                    cube_centres: Vec::new(),
                    grid: 0,
                }),
                Light::Spot(s) => Some(LightMaps {
                    views: cube_views(s.position, res),
                    cube_centres: vec![s.position],
                    grid: 0,
                }),
                Light::Area { shape, .. } => {
                    let count = samples_for_light(light, area_samples);
                    let k = (count as f32).sqrt().round().max(1.0) as u32;
                    let mut g = k.min(MAX_AREA_MAPS_PER_SIDE);
                    if matches!(shape, AreaShape::Sphere { .. })
                        || area_lights * (g * g) as usize > MAX_AREA_MAPS
                    {
                        g = 1;
                    }
                    let ares = (res / 4).max(64);
                    let mut views = Vec::new();
                    let mut cube_centres = Vec::new();
                    for j in 0..g * g {
                        let c = area_point(shape, stratum(j, g * g, Vec2::splat(0.5)));
                        cube_centres.push(c);
                        views.extend(cube_views(c, ares));
                    }
                    Some(LightMaps {
                        views,
                        cube_centres,
                        grid: g,
                    })
                }
            })
            .collect();
        let blockers = blockers(ps);
        let any_filter = blockers.iter().any(|b| matches!(b, Blocker::Filter(_)));
        // The budget, in light order.
        let per_texel = texel_bytes(any_filter);
        let needs: Vec<Option<u64>> = lights
            .iter()
            .map(|l| {
                l.as_ref().map(|l| {
                    l.views
                        .iter()
                        .map(|v| u64::from(v.res) * u64::from(v.res) * per_texel)
                        .sum()
                })
            })
            .collect();
        let (by_ray, bytes) = plan_budget(&needs, budget);
        let mut refused = Vec::new();
        for (li, slot) in lights.iter_mut().enumerate() {
            if by_ray[li] {
                *slot = None;
                refused.push((li, needs[li].unwrap_or(0)));
            }
        }
        let warning = (!refused.is_empty()).then(|| {
            let names: Vec<String> = refused.iter().map(|(li, _)| li.to_string()).collect();
            let largest = refused.iter().map(|r| r.1).max().unwrap_or(0);
            format!(
                "shadow maps: light{} {} use{} shadow rays: their maps ({} MiB for the largest, at {res} texels per side) do not fit in the {} MiB shadow-map budget (a quarter of the memory limit, at most 512 MiB) after the {} MiB of the lights before them",
                if refused.len() > 1 { "s" } else { "" },
                names.join(", "),
                if refused.len() > 1 { "" } else { "s" },
                largest.div_ceil(1 << 20),
                budget >> 20,
                bytes.div_ceil(1 << 20),
            )
        });
        let rays = (!refused.is_empty()).then(|| RayShadows::new(ps));
        lights
            .par_iter_mut()
            .flatten()
            .flat_map(|l| l.views.par_iter_mut())
            .for_each(|v| v.render(ps, &blockers, any_filter));
        Self {
            lights,
            by_ray,
            rays,
            settings: *settings,
            bytes,
            warning,
        }
    }

    /// Visibility of sample `sample` (of `count`) of light `li` from the
    /// point `p` with unit geometric normal `ng`.
    pub(crate) fn visibility(
        &self,
        li: usize,
        sample: u32,
        count: u32,
        p: Vec3,
        ng: Vec3,
        s: &LightSample,
    ) -> Vec3 {
        if self.by_ray.get(li) == Some(&true)
            && let Some(r) = &self.rays
        {
            return r.visibility(p, ng, s);
        }
        let Some(Some(maps)) = self.lights.get(li) else {
            return Vec3::ONE;
        };
        if maps.cube_centres.is_empty() {
            return maps.views[0].lookup(p, ng, s.wi, &self.settings);
        }
        // The cube of this sample's stratum (area lights), else the only one.
        let cube = if maps.grid > 1 {
            let k = (count as f32).sqrt().round().max(1.0) as u32;
            let (sx, sy) = (sample % k, sample / k);
            let g = maps.grid;
            ((sy * g / k) * g + sx * g / k) as usize
        } else {
            0
        };
        let c = maps.cube_centres[cube.min(maps.cube_centres.len() - 1)];
        let face = cube_face(p - c);
        maps.views[cube * 6 + face].lookup(p, ng, s.wi, &self.settings)
    }
}
