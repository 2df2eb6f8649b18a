//! Two-pass object-precision shadows (Atherton, Weiler and Greenberg 1978,
//! "Polygon shadow generation", SIGGRAPH '78).
//!
//! The first pass works from the light: for every triangle (the
//! *receiver*) it finds the parts that the light sees, by subtracting from
//! the receiver the shadows of every triangle nearer to the light. The lit
//! parts are kept as *lit fragments*: convex polygons in the receiver's
//! plane, tagged with the light ([`ObjectShadows`] is built per light). The
//! second pass, the camera render, adds a light's direct term only where the
//! shaded point lies in one of that light's fragments
//! ([`ObjectShadows::lit_fraction`]); the ambient term is everywhere and
//! several lights simply add.
//!
//! # How the clipping is done
//! Atherton, Weiler and Greenberg transform the scene into the light's view
//! and clip polygons there. Here each receiver is clipped in its own plane
//! instead: the shadow of an occluder `Q` on the receiver's plane is the
//! central projection from the light (parallel projection for a directional
//! light) of the part of `Q` between the light and that plane. The light's
//! view and the receiver's plane are related by a projective map that is
//! defined on all of that part, so the clipped result is the same polygon
//! the light-view clipping gives, and no cube of light views (with polygons
//! split across faces) is needed.
//!
//! The polygon difference `fragment minus shadow` (both convex) is computed
//! by splitting the fragment successively along each edge of the shadow
//! (Sutherland and Hodgman 1974 half-plane clipping): the part outside edge
//! `i` but inside edges `0..i` is a convex piece. This gives at most `k`
//! convex pieces for a `k`-gon shadow, which tile `fragment \ shadow`
//! exactly (the two sides of every split share the same computed
//! intersection points). It replaces the Weiler-Atherton clipper, which
//! returns concave polygons with holes; every fragment here stays convex so
//! the per-sample test is a point-in-convex-polygon test.
//!
//! # Tolerances
//! Geometry is processed in `f64`. Occluder parts closer than
//! `1e-5 * scale` to the receiver's plane (the same offset the shadow rays of
//! [`chiaro_core::geometry::offset_ray_origin`] use, `scale` the largest
//! coordinate magnitude) are taken as lying in it, so touching and coplanar
//! polygons do not shadow each other. Fragments thinner than `1e-12` of the
//! receiver's area are dropped.
//!
//! # Limits
//! Point, spot (treated as a point: the cone is the shading's job) and
//! directional lights. An area light is treated as a point light at its
//! centre: its shadows are hard, with no penumbra (the exact soft shadow
//! would need the visible part of the light at every point; use shadow rays
//! or multi-sample shadow maps for that). Ambient lights cast nothing and
//! are refused.
//! Analytic spheres are refused (prepare with tessellated spheres).
//! Every occluder is opaque: filtering materials are not tinted. Objects
//! with `casts_shadows = false` cast nothing.

use chiaro_core::accel::bvh::{Bvh, Child};
use chiaro_core::error::CoreError;
use chiaro_core::geometry::Aabb;
use chiaro_core::prepared::PreparedScene;
use chiaro_core::scene::Light;
pub(crate) use dvec::{DVec2, DVec3};
use glam::Vec3;
use rayon::prelude::*;

/// A convex polygon in world space (counter-clockwise seen from the side
/// of the receiver that faces the light).
#[derive(Debug, Clone, PartialEq)]
pub struct Polygon {
    /// Vertices, world space.
    pub points: Vec<Vec3>,
}

impl Polygon {
    /// Area in square world units (Newell's vector area).
    pub fn area(&self) -> f32 {
        let n = self.points.len();
        let mut s = DVec3::ZERO;
        for i in 0..n {
            let a = DVec3::from(self.points[i]);
            let b = DVec3::from(self.points[(i + 1) % n]);
            s = s + a.cross(b);
        }
        (0.5 * s.length()) as f32
    }
}

/// The light as the shadow geometry sees it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum LightGeom {
    /// A point at this position.
    Point(DVec3),
    /// At infinity, in this unit direction (pointing towards the light).
    Directional(DVec3),
}

impl LightGeom {
    /// The light's shadow-casting geometry, or why there is none.
    pub(crate) fn of(ps: &PreparedScene<'_>, light_index: usize) -> Result<Self, CoreError> {
        if !ps.spheres.is_empty() {
            return Err(CoreError::Unsupported(
                "object-precision and scan-line shadows need tessellated spheres".into(),
            ));
        }
        match ps.lights.get(light_index) {
            Some(Light::Point { position, .. }) => Ok(LightGeom::Point(position.into())),
            Some(Light::Spot(s)) => Ok(LightGeom::Point(s.position.into())),
            Some(Light::Area { shape, .. }) => Ok(LightGeom::Point(shape.center().into())),
            Some(Light::Directional { direction, .. }) => {
                match (-DVec3::from(direction)).try_normalize() {
                    Some(d) => Ok(LightGeom::Directional(d)),
                    None => Err(CoreError::Unsupported(
                        "directional light with a zero direction".into(),
                    )),
                }
            }
            Some(Light::Ambient { .. }) => Err(CoreError::Unsupported(
                "an ambient light casts no shadow".into(),
            )),
            None => Err(CoreError::Unsupported(format!(
                "light index {light_index} out of range ({} lights)",
                ps.lights.len()
            ))),
        }
    }
}

/// A receiver triangle's plane and 2D frame, oriented so the light is on
/// the positive side of the plane.
#[derive(Debug, Clone, Copy)]
pub(crate) struct ReceiverFrame {
    /// Origin (the first vertex).
    pub o: DVec3,
    /// In-plane unit axes.
    pub u: DVec3,
    pub v: DVec3,
    /// Unit normal towards the light side.
    pub n: DVec3,
    /// Height of a point light above the plane, or `n . to_light` for a
    /// directional light; `<= 0` when the light is in the plane.
    pub h: f64,
    /// The receiver in 2D, counter-clockwise.
    pub tri: [DVec2; 3],
    /// Distance under which a point counts as lying in the plane.
    pub eps: f64,
}

impl ReceiverFrame {
    /// The frame of triangle `[a, b, c]`, `None` when degenerate.
    pub fn new(p: [DVec3; 3], light: LightGeom, eps: f64) -> Option<Self> {
        let o = p[0];
        let mut n = (p[1] - p[0]).cross(p[2] - p[0]).try_normalize()?;
        let side = match light {
            LightGeom::Point(l) => n.dot(l - o),
            LightGeom::Directional(d) => n.dot(d),
        };
        if side < 0.0 {
            n = -n;
        }
        let u = (p[1] - p[0]).try_normalize()?;
        let v = n.cross(u);
        let h = side.abs();
        let to2 = |q: DVec3| DVec2::new((q - o).dot(u), (q - o).dot(v));
        let mut tri = p.map(to2);
        if cross2(tri[1] - tri[0], tri[2] - tri[0]) < 0.0 {
            tri.swap(1, 2);
        }
        Some(Self {
            o,
            u,
            v,
            n,
            h,
            tri,
            eps,
        })
    }

    /// 2D coordinates of world point `q` (projected onto the plane).
    pub fn plane_2d(&self, q: DVec3) -> DVec2 {
        DVec2::new((q - self.o).dot(self.u), (q - self.o).dot(self.v))
    }

    /// World point of 2D coordinates `q`.
    pub fn world_of(&self, q: DVec2) -> DVec3 {
        self.o + self.u * q.x + self.v * q.y
    }

    /// The shadow that occluder triangle `q` casts on this plane, as a
    /// counter-clockwise convex polygon in 2D; `None` when it casts none
    /// (entirely behind the plane, beyond a point light, or degenerate).
    /// Allocates only for a shadow that exists.
    pub fn shadow_of(&self, q: [DVec3; 3], light: LightGeom) -> Option<Vec<DVec2>> {
        if self.h <= self.eps {
            return None; // light (nearly) in the plane: nothing to shadow
        }
        let dist = |x: DVec3| self.n.dot(x - self.o);
        // Keep the part strictly between the plane and the light (at most
        // five corners: a triangle cut by two planes).
        let mut a = [DVec3::ZERO; MAX_CLIP];
        let mut n = clip3_into(&q, |x| dist(x) - self.eps, &mut a);
        if n < 3 {
            return None;
        }
        let mut b = [DVec3::ZERO; MAX_CLIP];
        let poly: &[DVec3] = if let LightGeom::Point(_) = light {
            n = clip3_into(&a[..n], |x| self.h - self.eps - dist(x), &mut b);
            if n < 3 {
                return None;
            }
            &b[..n]
        } else {
            &a[..n]
        };
        // Central (or parallel) projection onto the plane.
        let mut s = [DVec2::default(); MAX_CLIP];
        for (o, &x) in s.iter_mut().zip(poly) {
            let d = dist(x);
            let p = match light {
                LightGeom::Point(l) => l + (x - l) * (self.h / (self.h - d)),
                LightGeom::Directional(t) => x - t * (d / self.h),
            };
            *o = self.plane_2d(p);
        }
        let s = &mut s[..poly.len()];
        let a = area2(s);
        if a.abs() <= 1e-14 * area2(&self.tri).abs() {
            return None;
        }
        if a < 0.0 {
            s.reverse();
        }
        Some(s.to_vec())
    }

    /// The shadow frustum of this receiver (corners `p`, those given to
    /// [`ReceiverFrame::new`]): half-spaces outside which an occluder
    /// cannot shadow any point of the receiver. For a point light they are
    /// the receiver's plane, the plane through the light parallel to it and
    /// the three planes through the light and each edge; for a directional
    /// light the receiver's plane and the three planes through each edge
    /// along the light direction. Each is loosened by `eps`, so the test
    /// only discards pairs that [`ReceiverFrame::shadow_of`] and the clip
    /// to the receiver would reduce to nothing. `None` when the light is in
    /// the plane (no shadow at all).
    pub fn frustum(&self, p: [DVec3; 3], light: LightGeom) -> Option<ShadowFrustum> {
        if self.h <= self.eps {
            return None;
        }
        let mut f = ShadowFrustum {
            planes: [HalfSpace {
                n: DVec3::ZERO,
                c: 0.0,
            }; 5],
            count: 0,
        };
        let mut push = |n: DVec3, c: f64| {
            f.planes[f.count] = HalfSpace { n, c };
            f.count += 1;
        };
        // In front of the receiver: dist(x) >= eps, loosened to >= eps / 2
        // (far more than the rounding of `dist`), so that neighbours
        // sharing a vertex with the receiver and bending away from the
        // light are discarded here.
        push(self.n, -self.n.dot(self.o) - 0.5 * self.eps);
        if let LightGeom::Point(_) = light {
            // Below the light: dist(x) <= h - eps, loosened to <= h - eps / 2.
            push(-self.n, self.n.dot(self.o) + self.h - 0.5 * self.eps);
        }
        for i in 0..3 {
            let (a, b, c) = (p[i], p[(i + 1) % 3], p[(i + 2) % 3]);
            // The plane through the edge containing the light (or the light
            // direction), its normal turned towards the opposite corner.
            let (m, at) = match light {
                LightGeom::Point(l) => ((a - l).cross(b - l), l),
                LightGeom::Directional(d) => ((b - a).cross(d), a),
            };
            let Some(mut m) = m.try_normalize() else {
                continue; // degenerate: skip (the test stays conservative)
            };
            if m.dot(c - at) < 0.0 {
                m = -m;
            }
            push(m, -m.dot(at) + self.eps);
        }
        Some(f)
    }
}

/// Most corners of a triangle clipped by two planes, with room to spare.
const MAX_CLIP: usize = 8;

/// The half-space `n . x + c >= 0`.
#[derive(Debug, Clone, Copy)]
pub(crate) struct HalfSpace {
    n: DVec3,
    c: f64,
}

/// A receiver's shadow frustum: the intersection of up to five
/// half-spaces (see [`ReceiverFrame::frustum`]).
#[derive(Debug, Clone, Copy)]
pub(crate) struct ShadowFrustum {
    planes: [HalfSpace; 5],
    count: usize,
}

impl ShadowFrustum {
    /// Whether box `b` lies entirely outside one of the half-spaces (the
    /// corner furthest along each plane's normal is outside).
    fn excludes_box(&self, b: &Aabb) -> bool {
        let (lo, hi) = (DVec3::from(b.min), DVec3::from(b.max));
        self.planes[..self.count].iter().any(|h| {
            let x = if h.n.x >= 0.0 { hi.x } else { lo.x };
            let y = if h.n.y >= 0.0 { hi.y } else { lo.y };
            let z = if h.n.z >= 0.0 { hi.z } else { lo.z };
            h.n.dot(DVec3::new(x, y, z)) + h.c < 0.0
        })
    }

    /// Whether every corner of triangle `q` lies outside one of the
    /// half-spaces.
    pub(crate) fn excludes_tri(&self, q: &[DVec3; 3]) -> bool {
        self.planes[..self.count]
            .iter()
            .any(|h| q.iter().all(|&x| h.n.dot(x) + h.c < 0.0))
    }
}

/// The shadow casters of a scene for the exact shadow methods: a BVH over
/// the boxes of the triangles whose objects cast shadows (the lecture
/// notes' light-cube projection, which pairs polygons whose projections from the
/// light overlap, done instead as a frustum query against the BVH).
#[derive(Debug, Clone)]
pub(crate) struct Casters {
    bvh: Bvh,
    /// Per triangle, its corners in `f64`; `None` for triangles that cast
    /// nothing (their boxes in the BVH are empty).
    points: Vec<Option<[DVec3; 3]>>,
}

impl Casters {
    /// The casters of `ps`.
    pub(crate) fn new(ps: &PreparedScene<'_>) -> Self {
        let opaque = opaque_casters(ps);
        let points: Vec<Option<[DVec3; 3]>> = (0..ps.triangles.len())
            .map(|t| tri_points(ps, t).filter(|_| opaque[t]))
            .collect();
        let boxes: Vec<Aabb> = points
            .iter()
            .map(|p| p.map_or(Aabb::EMPTY, |p| Aabb::from_points(p.map(Vec3::from))))
            .collect();
        let bvh = Bvh::build(&boxes);
        Self { bvh, points }
    }

    /// Appends to `out` the shadows (2D, in `frame`) that the casters other
    /// than triangle `r` throw on receiver `r` with corners `p`, in BVH
    /// order. Returns the number of candidate occluders whose boxes met the
    /// receiver's shadow frustum. `stack` is scratch space.
    pub(crate) fn shadows_on(
        &self,
        r: usize,
        p: [DVec3; 3],
        frame: &ReceiverFrame,
        light: LightGeom,
        stack: &mut Vec<u32>,
        out: &mut Vec<Vec<DVec2>>,
    ) -> usize {
        let Some(fr) = frame.frustum(p, light) else {
            return 0;
        };
        let mut candidates = 0;
        self.query(&fr, stack, |o| {
            let o = o as usize;
            if o == r {
                return;
            }
            let Some(&Some(q)) = self.points.get(o) else {
                return;
            };
            candidates += 1;
            if !fr.excludes_tri(&q)
                && let Some(s) = frame.shadow_of(q, light)
            {
                out.push(s);
            }
        });
        candidates
    }

    /// Calls `visit(prim)` for every primitive whose leaf box the frustum
    /// does not exclude.
    fn query(&self, fr: &ShadowFrustum, stack: &mut Vec<u32>, mut visit: impl FnMut(u32)) {
        if self.bvh.node_count() == 0 {
            return;
        }
        stack.clear();
        stack.push(0);
        while let Some(i) = stack.pop() {
            for (b, c) in self.bvh.node(i as usize).children() {
                if fr.excludes_box(&b) {
                    continue;
                }
                match c {
                    Child::Node(k) => stack.push(k),
                    Child::Leaf { first, count } => {
                        for s in first..first + count {
                            if let Some(&prim) = self.bvh.prim_order().get(s as usize) {
                                visit(prim);
                            }
                        }
                    }
                }
            }
        }
    }
}

/// 2D cross product.
#[inline]
pub(crate) fn cross2(a: DVec2, b: DVec2) -> f64 {
    a.x * b.y - a.y * b.x
}

/// Twice the signed area of a 2D polygon (positive counter-clockwise).
pub(crate) fn area2(p: &[DVec2]) -> f64 {
    let n = p.len();
    (0..n).map(|i| cross2(p[i], p[(i + 1) % n])).sum()
}

/// Sutherland-Hodgman: writes to `out` the part of convex polygon `p`
/// where `f >= 0` (`f` affine) and returns its corner count (at most
/// `p.len() + 1`, capped at [`MAX_CLIP`]).
fn clip3_into(p: &[DVec3], f: impl Fn(DVec3) -> f64, out: &mut [DVec3; MAX_CLIP]) -> usize {
    let mut k = 0;
    let mut put = |x: DVec3| {
        if k < MAX_CLIP {
            out[k] = x;
            k += 1;
        }
    };
    let n = p.len();
    for i in 0..n {
        let (a, b) = (p[i], p[(i + 1) % n]);
        let (fa, fb) = (f(a), f(b));
        if fa >= 0.0 {
            put(a);
        }
        if (fa >= 0.0) != (fb >= 0.0) {
            put(a + (b - a) * (fa / (fa - fb)));
        }
    }
    k
}

/// Splits convex polygon `p` by the line through `a`, `b`: returns the part
/// on the left (`cross >= 0`) and the part on the right. Both parts use the
/// same intersection points, so together they tile `p` exactly.
pub(crate) fn split2(p: &[DVec2], a: DVec2, b: DVec2) -> (Vec<DVec2>, Vec<DVec2>) {
    let e = b - a;
    let s: Vec<f64> = p.iter().map(|&q| cross2(e, q - a)).collect();
    let (mut left, mut right) = (Vec::new(), Vec::new());
    let n = p.len();
    for i in 0..n {
        let j = (i + 1) % n;
        if s[i] >= 0.0 {
            left.push(p[i]);
        }
        if s[i] <= 0.0 {
            right.push(p[i]);
        }
        if (s[i] > 0.0 && s[j] < 0.0) || (s[i] < 0.0 && s[j] > 0.0) {
            let x = p[i] + (p[j] - p[i]) * (s[i] / (s[i] - s[j]));
            left.push(x);
            right.push(x);
        }
    }
    (left, right)
}

/// The intersection of convex polygon `p` with counter-clockwise convex
/// polygon `clip`.
pub(crate) fn intersect2(p: &[DVec2], clip: &[DVec2]) -> Vec<DVec2> {
    let mut cur = p.to_vec();
    let n = clip.len();
    for i in 0..n {
        if cur.len() < 3 {
            return Vec::new();
        }
        cur = split2(&cur, clip[i], clip[(i + 1) % n]).0;
    }
    if cur.len() < 3 { Vec::new() } else { cur }
}

/// Appends to `out` the convex pieces of `frag \ clip` (both convex, `clip`
/// counter-clockwise) with area above `min_area2` (twice the area).
fn subtract(frag: &[DVec2], clip: &[DVec2], min_area2: f64, out: &mut Vec<Vec<DVec2>>) {
    let n = clip.len();
    // Entirely outside one edge: untouched.
    for i in 0..n {
        let (a, b) = (clip[i], clip[(i + 1) % n]);
        if frag.iter().all(|&q| cross2(b - a, q - a) <= 0.0) {
            out.push(frag.to_vec());
            return;
        }
    }
    let mut rest = frag.to_vec();
    for i in 0..n {
        let (inside, outside) = split2(&rest, clip[i], clip[(i + 1) % n]);
        if outside.len() >= 3 && area2(&outside) > min_area2 {
            out.push(outside);
        }
        rest = inside;
        if rest.len() < 3 {
            return;
        }
    }
}

/// Bounding box of a 2D polygon as `[min, max]`.
fn bbox2(p: &[DVec2]) -> [DVec2; 2] {
    let mut lo = DVec2::splat(f64::INFINITY);
    let mut hi = DVec2::splat(f64::NEG_INFINITY);
    for &q in p {
        lo = lo.min(q);
        hi = hi.max(q);
    }
    [lo, hi]
}

/// Strict point-in-convex-polygon test with tolerance `tol` (distance).
fn inside_convex(p: &[DVec2], q: DVec2, tol: f64) -> bool {
    let n = p.len();
    (0..n).all(|i| {
        let (a, b) = (p[i], p[(i + 1) % n]);
        let e = b - a;
        let len = e.length();
        // Two corners that are one point up to rounding (the clipper makes
        // such pairs) give an edge of arbitrary direction: skip it, its
        // neighbours bound the polygon there.
        len <= 1e-3 * tol || cross2(e, q - a) >= -tol * len
    })
}

/// `q` itself when it lies in the counter-clockwise triangle `tri` (within
/// `tol`), else the nearest point of the triangle's edges.
fn nearest_in_triangle(tri: &[DVec2; 3], q: DVec2, tol: f64) -> DVec2 {
    if inside_convex(tri, q, tol) {
        return q;
    }
    let dot = |a: DVec2, b: DVec2| a.x * b.x + a.y * b.y;
    let mut best = (f64::INFINITY, q);
    for i in 0..3 {
        let (a, b) = (tri[i], tri[(i + 1) % 3]);
        let e = b - a;
        let t = (dot(q - a, e) / dot(e, e).max(f64::MIN_POSITIVE)).clamp(0.0, 1.0);
        let c = a + e * t;
        let d = (q - c).length();
        if d < best.0 {
            best = (d, c);
        }
    }
    best.1
}

/// Lit fragments of one triangle.
#[derive(Debug, Clone)]
struct TriFragments {
    frame: Option<ReceiverFrame>,
    /// Convex fragments in the frame's 2D coordinates, with their boxes.
    polys: Vec<(Vec<DVec2>, [DVec2; 2])>,
    /// The same fragments in world space.
    world: Vec<Polygon>,
}

/// The lit fragments of every triangle of a [`PreparedScene`] for one light:
/// the first pass of Atherton-Weiler-Greenberg shadows.
#[derive(Debug, Clone)]
pub struct ObjectShadows {
    tris: Vec<TriFragments>,
    tol: f64,
    light_index: usize,
}

/// Scale of the scene's coordinates (at least 1), for tolerances.
pub(crate) fn scene_scale(ps: &PreparedScene<'_>) -> f64 {
    if ps.bounds.is_empty() {
        1.0
    } else {
        f64::from(ps.bounds.min.abs().max(ps.bounds.max.abs()).max_element()).max(1.0)
    }
}

/// World-space corners of triangle `t` in `f64`, `None` for bad indices.
pub(crate) fn tri_points(ps: &PreparedScene<'_>, t: usize) -> Option<[DVec3; 3]> {
    let tri = ps.triangles.get(t)?;
    let mut out = [DVec3::ZERO; 3];
    for k in 0..3 {
        out[k] = ps.positions.get(tri[k] as usize)?.into();
    }
    Some(out)
}

/// Per triangle, whether it is an opaque caster by the shared shadow rule
/// ([`chiaro_core::shadow::ShadowCasters`]): transparent casters are left to
/// shadow rays that see only them (their tint is a colour, not a polygon),
/// and objects with `casts_shadows = false` cast nothing.
pub(crate) fn opaque_casters(ps: &PreparedScene<'_>) -> Vec<bool> {
    crate::shadows::blockers(ps)
        .into_iter()
        .map(|b| b == crate::shadows::Blocker::Opaque)
        .collect()
}

impl ObjectShadows {
    /// Runs the light pass for light `light_index` of `ps.lights`: the lit
    /// fragments of every triangle. Candidate occluders of a receiver are
    /// the triangles whose boxes meet the receiver's shadow frustum (the
    /// pyramid from the light through the receiver, cut by the receiver's
    /// plane; for a directional light the prism swept towards the light),
    /// found with a BVH over the casters' boxes.
    ///
    /// # Errors
    /// [`CoreError::Unsupported`] for an ambient light, an out-of-range
    /// index or a scene with analytic spheres.
    pub fn build(ps: &PreparedScene<'_>, light_index: usize) -> Result<Self, CoreError> {
        Self::build_with(ps, light_index, &Casters::new(ps))
    }

    /// [`Self::build`] with the casters' BVH built once for several lights.
    pub(crate) fn build_with(
        ps: &PreparedScene<'_>,
        light_index: usize,
        casters: &Casters,
    ) -> Result<Self, CoreError> {
        let light = LightGeom::of(ps, light_index)?;
        let scale = scene_scale(ps);
        let eps = 1e-5 * scale;
        let tris = (0..ps.triangles.len())
            .into_par_iter()
            .map_init(Vec::new, |stack, t| {
                let Some(p) = tri_points(ps, t) else {
                    return TriFragments {
                        frame: None,
                        polys: Vec::new(),
                        world: Vec::new(),
                    };
                };
                let frame = ReceiverFrame::new(p, light, eps);
                let mut polys = frame.map(|f| vec![f.tri.to_vec()]).unwrap_or_default();
                if let Some(f) = frame {
                    let min_area2 = 1e-12 * area2(&f.tri);
                    let mut shadows = Vec::new();
                    casters.shadows_on(t, p, &f, light, stack, &mut shadows);
                    for s in &shadows {
                        let sb = bbox2(s);
                        let mut next = Vec::with_capacity(polys.len());
                        for frag in polys {
                            let fb = bbox2(&frag);
                            if fb[1].x <= sb[0].x
                                || fb[0].x >= sb[1].x
                                || fb[1].y <= sb[0].y
                                || fb[0].y >= sb[1].y
                            {
                                next.push(frag);
                            } else {
                                subtract(&frag, s, min_area2, &mut next);
                            }
                        }
                        polys = next;
                        if polys.is_empty() {
                            break;
                        }
                    }
                }
                let world = match frame {
                    Some(f) => polys
                        .iter()
                        .map(|q| Polygon {
                            points: q.iter().map(|&x| Vec3::from(f.world_of(x))).collect(),
                        })
                        .collect(),
                    None => Vec::new(),
                };
                TriFragments {
                    frame,
                    polys: polys
                        .into_iter()
                        .map(|q| {
                            let b = bbox2(&q);
                            (q, b)
                        })
                        .collect(),
                    world,
                }
            })
            .collect();
        Ok(Self {
            tris,
            tol: 1e-6 * scale,
            light_index,
        })
    }

    /// The light these fragments belong to (index into `ps.lights`).
    pub fn light_index(&self) -> usize {
        self.light_index
    }

    /// 1 if world point `p` (on triangle `tri`) lies in a lit fragment of
    /// `tri`, else 0. `p` is projected onto the triangle's plane; points
    /// within `1e-6 * scale` of a fragment's boundary count as inside.
    /// Returns 1 for an out-of-range or degenerate triangle (no shadow
    /// information: it was never clipped).
    pub fn lit_fraction(&self, tri: u32, p: Vec3) -> f32 {
        let Some(t) = self.tris.get(tri as usize) else {
            return 1.0;
        };
        let Some(f) = &t.frame else {
            return 1.0;
        };
        let tol = self.tol;
        // The rasterizer's snapped edges give a sample near a shared edge to
        // either triangle; shade it as the nearest point of the one it got.
        let q = nearest_in_triangle(&f.tri, f.plane_2d(p.into()), tol);
        let hit = t.polys.iter().any(|(poly, b)| {
            q.x >= b[0].x - tol
                && q.x <= b[1].x + tol
                && q.y >= b[0].y - tol
                && q.y <= b[1].y + tol
                && inside_convex(poly, q, tol)
        });
        if hit { 1.0 } else { 0.0 }
    }

    /// The lit fragments of triangle `tri` (convex, world space); empty when
    /// it is entirely in shadow or out of range.
    pub fn fragments(&self, tri: u32) -> &[Polygon] {
        self.tris
            .get(tri as usize)
            .map(|t| t.world.as_slice())
            .unwrap_or(&[])
    }

    /// Total number of lit fragments (a measure of the light pass's work).
    pub fn fragment_count(&self) -> usize {
        self.tris.iter().map(|t| t.polys.len()).sum()
    }
}

/// Minimal `f64` vectors (the workspace builds glam without `f64`).
mod dvec {
    use glam::Vec3;
    use std::ops::{Add, Mul, Neg, Sub};

    /// A 3D `f64` vector.
    #[derive(Debug, Clone, Copy, PartialEq, Default)]
    pub struct DVec3 {
        pub x: f64,
        pub y: f64,
        pub z: f64,
    }

    /// A 2D `f64` vector.
    #[derive(Debug, Clone, Copy, PartialEq, Default)]
    pub struct DVec2 {
        pub x: f64,
        pub y: f64,
    }

    impl DVec3 {
        pub const ZERO: Self = Self::new(0.0, 0.0, 0.0);
        pub const fn new(x: f64, y: f64, z: f64) -> Self {
            Self { x, y, z }
        }
        pub fn dot(self, o: Self) -> f64 {
            self.x * o.x + self.y * o.y + self.z * o.z
        }
        pub fn cross(self, o: Self) -> Self {
            Self::new(
                self.y * o.z - self.z * o.y,
                self.z * o.x - self.x * o.z,
                self.x * o.y - self.y * o.x,
            )
        }
        pub fn length(self) -> f64 {
            self.dot(self).sqrt()
        }
        pub fn try_normalize(self) -> Option<Self> {
            let l = self.length();
            (l.is_finite() && l > 0.0).then(|| self * (1.0 / l))
        }
    }

    impl DVec2 {
        pub const fn new(x: f64, y: f64) -> Self {
            Self { x, y }
        }
        pub const fn splat(v: f64) -> Self {
            Self { x: v, y: v }
        }
        pub fn min(self, o: Self) -> Self {
            Self::new(self.x.min(o.x), self.y.min(o.y))
        }
        pub fn max(self, o: Self) -> Self {
            Self::new(self.x.max(o.x), self.y.max(o.y))
        }
        pub fn length(self) -> f64 {
            (self.x * self.x + self.y * self.y).sqrt()
        }
    }

    impl From<Vec3> for DVec3 {
        fn from(v: Vec3) -> Self {
            Self::new(v.x.into(), v.y.into(), v.z.into())
        }
    }

    impl From<&Vec3> for DVec3 {
        fn from(v: &Vec3) -> Self {
            (*v).into()
        }
    }

    impl From<DVec3> for Vec3 {
        fn from(v: DVec3) -> Self {
            Vec3::new(v.x as f32, v.y as f32, v.z as f32)
        }
    }

    macro_rules! ops {
        ($t:ident, $($f:ident),+) => {
            impl Add for $t {
                type Output = Self;
                fn add(self, o: Self) -> Self {
                    Self { $($f: self.$f + o.$f),+ }
                }
            }
            impl Sub for $t {
                type Output = Self;
                fn sub(self, o: Self) -> Self {
                    Self { $($f: self.$f - o.$f),+ }
                }
            }
            impl Mul<f64> for $t {
                type Output = Self;
                fn mul(self, k: f64) -> Self {
                    Self { $($f: self.$f * k),+ }
                }
            }
            impl Neg for $t {
                type Output = Self;
                fn neg(self) -> Self {
                    Self { $($f: -self.$f),+ }
                }
            }
        };
    }
    ops!(DVec3, x, y, z);
    ops!(DVec2, x, y);
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Seeded xorshift in `[-1, 1)`.
    fn rng(state: &mut u64) -> f64 {
        *state ^= *state << 13;
        *state ^= *state >> 7;
        *state ^= *state << 17;
        (*state >> 11) as f64 / (1u64 << 52) as f64 - 1.0
    }

    /// A fragment whose clipped corner came out twice, one rounding apart
    /// (as on mitsuba-cbox's back wall), still contains its inside: the
    /// tiny edge between the two copies points anywhere and must not cut
    /// the polygon (before the fix the whole square tested outside).
    #[test]
    fn inside_convex_ignores_an_edge_between_two_copies_of_a_corner() {
        let square = [
            DVec2::new(0.0, 0.0),
            DVec2::new(1.0, 0.0),
            DVec2::new(1.0, 1.0),
            DVec2::new(1.0 + 1e-12, 1.0),
            DVec2::new(0.0, 1.0),
        ];
        for q in [(0.5, 0.5), (0.1, 0.9), (0.9, 0.1)] {
            assert!(inside_convex(&square, DVec2::new(q.0, q.1), 1e-6), "{q:?}");
        }
        for q in [(1.1, 0.5), (0.5, 1.1), (-0.1, 0.5)] {
            assert!(!inside_convex(&square, DVec2::new(q.0, q.1), 1e-6), "{q:?}");
        }
    }

    /// The frustum cull is exact where it matters: every occluder it
    /// discards casts no shadow with area on the receiver, and it does
    /// discard a good share of random occluders (about 37% here).
    #[test]
    fn frustum_discards_only_occluders_without_shadow_on_the_receiver() {
        let mut s = 0x2545_f491_4f6c_dd1du64;
        let (mut culled, mut total) = (0, 0);
        for k in 0..4000 {
            let mut v = || DVec3::new(rng(&mut s), rng(&mut s), rng(&mut s));
            let recv = [v(), v(), v()];
            let occ = [v(), v(), v()];
            let light = if k % 2 == 0 {
                LightGeom::Point(DVec3::new(0.0, 3.0, 0.0) + v())
            } else {
                LightGeom::Directional(v().try_normalize().unwrap_or(DVec3::new(0.0, 1.0, 0.0)))
            };
            let Some(frame) = ReceiverFrame::new(recv, light, 1e-5) else {
                continue;
            };
            let Some(fr) = frame.frustum(recv, light) else {
                continue;
            };
            total += 1;
            if fr.excludes_tri(&occ) {
                culled += 1;
                let on = frame
                    .shadow_of(occ, light)
                    .map(|sh| intersect2(&sh, &frame.tri))
                    .map_or(0.0, |p| if p.len() < 3 { 0.0 } else { area2(&p) });
                assert!(
                    on <= 1e-9,
                    "case {k}: culled occluder shadows {on} of the receiver"
                );
            }
        }
        assert!(total > 3500, "{total} usable cases");
        assert!(culled * 4 > total, "only {culled} of {total} culled");
    }
}
