//! Shooting patches above elements (Cohen, Greenberg, Immel and Brock
//! 1986, "An efficient radiosity approach for realistic image synthesis":
//! patches shoot, elements receive).
//!
//! Meshing never merges input triangles, so a finely tessellated model
//! gives one element per input triangle however small. [`Patches::build`]
//! groups such elements into *patches*: elements of one object (or one area
//! light) whose normals fall in the same direction bin and whose centroids
//! fall in the same grid cell of side `patch_size / 2`, built in one hashed
//! pass over the elements. Only elements with edges under half the patch
//! size are grouped (fine input triangles, or small triangles that meshing
//! subdivided with a larger neighbour); any other element is a patch of its
//! own, so scenes of large input triangles (the Cornell box) keep their
//! element-by-element solution exactly.
//!
//! [`PatchShooter`] computes what a shot of progressive refinement sends:
//! between two single-element patches the element form factor as before;
//! to a receiving patch that is far from the shooting patch (centre
//! distance above [`FAR`] times the sum of their radii) one visibility
//! fraction per receiving patch (four rays) and, per element, the
//! point-to-disc form factor `A cos cos / (pi d^2 + A)` of the shooting
//! patch from geometry alone; to near patches the unoccluded element form
//! factors summed over the shooter's elements (the point-to-disc form
//! factor for a shooting element that is far from the receiving one by the
//! same criterion), times one visibility fraction per receiving element
//! (four rays to points of the shooter).

use crate::formfactor::sub_centroids;
use crate::mesh::{ElementMesh, SourceKind};
use crate::ray_cast::{PairRule, Visibility, pair};
use chiaro_core::error::CoreError;
use chiaro_core::progress::Progress;
use glam::Vec3;
use rayon::prelude::*;
use std::collections::HashMap;
use std::f32::consts::PI;

/// A receiving patch is far from the shooter when their centres are more
/// than `FAR` times the sum of their radii apart: every receiving point is
/// then at least two shooter radii away, where the point-to-disc form
/// factor of the whole patch is close to the sum over its elements (the
/// test against the element-by-element solution bounds the difference),
/// and the receiving patch spans under 30 degrees from the
/// shooter, so a few rays stand for its visibility.
pub(crate) const FAR: f32 = 2.0;

/// Visibility rays per far (shooter, receiving patch) pair.
const FAR_RAYS: usize = 4;

/// Normal bins per cube face edge: normals of one patch differ by at most
/// the span of one bin (about 30 degrees).
const NORMAL_BINS: f32 = 4.0;

/// The patches of an element mesh: a partition of the elements.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Patches {
    /// Element indices grouped by patch (in element order within a patch).
    pub members: Vec<u32>,
    /// Start of each patch in `members`, plus the end.
    pub start: Vec<u32>,
    /// The patch of each element.
    pub of: Vec<u32>,
    /// Area of each patch.
    pub area: Vec<f32>,
    /// Area-weighted centroid.
    pub centre: Vec<Vec3>,
    /// Area-weighted mean normal (unit).
    pub normal: Vec<Vec3>,
    /// Largest distance from the centre to a member's corner.
    pub radius: Vec<f32>,
    /// Smallest cosine between a member's normal and `normal`.
    pub cos_spread: Vec<f32>,
    /// [`FAR_RAYS`] points (with normals) spread over each patch.
    points: Vec<[(Vec3, Vec3); FAR_RAYS]>,
}

/// Whether a surface with normals within the cone (`n`, `cos_a`) can face a
/// point at `d` plus any offset of length up to `r`: the largest `n' . d`
/// over the cone, plus `r`, is positive (conservative).
fn reaches(n: Vec3, cos_a: f32, d: Vec3, r: f32) -> bool {
    let len = d.length();
    if len <= r {
        return true;
    }
    let cos_t = (n.dot(d) / len).clamp(-1.0, 1.0);
    if cos_t >= cos_a {
        return true;
    }
    let (sin_t, sin_a) = (
        (1.0 - cos_t * cos_t).max(0.0).sqrt(),
        (1.0 - cos_a * cos_a).max(0.0).sqrt(),
    );
    len * (cos_t * cos_a + sin_t * sin_a) + r > 0.0
}

fn normal_bin(n: Vec3) -> u32 {
    let a = n.abs();
    let (axis, major, u, v) = if a.x >= a.y && a.x >= a.z {
        (0, n.x, n.y, n.z)
    } else if a.y >= a.z {
        (1, n.y, n.z, n.x)
    } else {
        (2, n.z, n.x, n.y)
    };
    let face = axis * 2 + u32::from(major < 0.0);
    let m = major.abs().max(f32::MIN_POSITIVE);
    let bin = |x: f32| ((x / m * 0.5 + 0.5) * NORMAL_BINS).clamp(0.0, NORMAL_BINS - 1.0) as u32;
    (face * 16 + bin(u)) * 16 + bin(v)
}

impl Patches {
    /// One patch per element.
    pub fn singletons(mesh: &ElementMesh) -> Self {
        Self::from_assignment(mesh, (0..mesh.elements.len() as u32).collect(), 0)
    }

    /// Groups the elements of `mesh` into patches of about `patch_size`
    /// (see the module docs).
    ///
    /// # Errors
    /// [`CoreError::Cancelled`] when `progress` asks.
    pub fn build(
        mesh: &ElementMesh,
        patch_size: f32,
        progress: &dyn Progress,
    ) -> Result<Self, CoreError> {
        let cell = (patch_size * 0.5).max(f32::MIN_POSITIVE);
        let mut keys: HashMap<(u32, u32, [i32; 3]), u32> = HashMap::new();
        let mut of = Vec::with_capacity(mesh.elements.len());
        let mut next = 0u32;
        for (i, e) in mesh.elements.iter().enumerate() {
            if i % 65_536 == 0 && progress.cancelled() {
                return Err(CoreError::Cancelled);
            }
            let s = &mesh.sources[e.source as usize];
            // The element's longest edge (its source's over k).
            let longest = (0..3)
                .map(|k| (e.p[(k + 1) % 3] - e.p[k]).length())
                .fold(0.0f32, f32::max);
            let fine = longest < 0.5 * patch_size;
            let id = if fine {
                let group = match s.kind {
                    SourceKind::Prepared(_) => s.object,
                    SourceKind::AreaLight { light, .. } => 0x8000_0000 | light,
                };
                let c = (e.c / cell).floor();
                let key = (group, normal_bin(e.n), [c.x as i32, c.y as i32, c.z as i32]);
                *keys.entry(key).or_insert_with(|| {
                    next += 1;
                    next - 1
                })
            } else {
                next += 1;
                next - 1
            };
            of.push(id);
        }
        Ok(Self::from_assignment(mesh, of, next))
    }

    /// The patches of an assignment `of` (element -> patch id, ids numbered
    /// in order of first appearance); `count` 0 means one per element.
    fn from_assignment(mesh: &ElementMesh, of: Vec<u32>, count: u32) -> Self {
        let np = if count == 0 { of.len() } else { count as usize };
        let mut start = vec![0u32; np + 1];
        for &p in &of {
            start[p as usize + 1] += 1;
        }
        for p in 0..np {
            start[p + 1] += start[p];
        }
        let mut fill = start.clone();
        let mut members = vec![0u32; of.len()];
        for (e, &p) in of.iter().enumerate() {
            members[fill[p as usize] as usize] = e as u32;
            fill[p as usize] += 1;
        }
        let (mut area, mut centre, mut normal, mut radius) = (
            vec![0.0f32; np],
            vec![Vec3::ZERO; np],
            vec![Vec3::ZERO; np],
            vec![0.0f32; np],
        );
        for p in 0..np {
            let m = &members[start[p] as usize..start[p + 1] as usize];
            if let [e] = m {
                // A single element is its own patch, exactly.
                let el = &mesh.elements[*e as usize];
                (area[p], centre[p], normal[p]) = (el.area, el.c, el.n);
            } else {
                let (mut a, mut c, mut n) = (0.0f32, Vec3::ZERO, Vec3::ZERO);
                for &e in m {
                    let el = &mesh.elements[e as usize];
                    a += el.area;
                    c += el.c * el.area;
                    n += el.n * el.area;
                }
                area[p] = a;
                centre[p] = if a > 0.0 {
                    c / a
                } else {
                    mesh.elements[m[0] as usize].c
                };
                normal[p] = n.normalize_or(mesh.elements[m[0] as usize].n);
            }
            radius[p] = m
                .iter()
                .flat_map(|&e| mesh.elements[e as usize].p)
                .map(|q| q.distance(centre[p]))
                .fold(0.0f32, f32::max);
        }
        let cos_spread = (0..np)
            .map(|p| {
                let m = &members[start[p] as usize..start[p + 1] as usize];
                m.iter()
                    .map(|&e| mesh.elements[e as usize].n.dot(normal[p]))
                    .fold(1.0f32, f32::min)
                    .clamp(-1.0, 1.0)
            })
            .collect();
        let mut out = Self {
            members,
            start,
            of,
            area,
            centre,
            normal,
            radius,
            cos_spread,
            points: Vec::new(),
        };
        out.points = (0..np).map(|p| out.spread_points(mesh, p)).collect();
        out
    }

    /// Whether some point of patch `q` may lie in front of some element of
    /// `p` and the other way round (a necessary condition for light to pass
    /// between them, from bounding spheres and normal cones).
    pub fn may_face(&self, p: usize, q: usize) -> bool {
        let d = self.centre[q] - self.centre[p];
        let r = (self.radius[p] + self.radius[q]) * 1.001;
        reaches(self.normal[p], self.cos_spread[p], d, r)
            && reaches(self.normal[q], self.cos_spread[q], -d, r)
    }

    /// Number of patches.
    pub fn len(&self) -> usize {
        self.area.len()
    }

    /// The elements of patch `p`.
    pub fn elements(&self, p: usize) -> &[u32] {
        &self.members[self.start[p] as usize..self.start[p + 1] as usize]
    }

    /// True when patches `p` and `q` are far apart (see [`FAR`]).
    pub fn far(&self, p: usize, q: usize) -> bool {
        let d = self.centre[p].distance(self.centre[q]);
        d > FAR * (self.radius[p] + self.radius[q])
    }

    /// Up to [`FAR_RAYS`] points (with normals) spread over patch `p`: the
    /// centroids of evenly spaced elements, or points of its one element.
    fn spread_points(&self, mesh: &ElementMesh, p: usize) -> [(Vec3, Vec3); FAR_RAYS] {
        let m = self.elements(p);
        let mut out = [(Vec3::ZERO, Vec3::ZERO); FAR_RAYS];
        if m.len() >= FAR_RAYS {
            for (k, o) in out.iter_mut().enumerate() {
                let el = &mesh.elements[m[k * m.len() / FAR_RAYS] as usize];
                *o = (el.c, el.n);
            }
        } else {
            for (k, o) in out.iter_mut().enumerate() {
                let el = &mesh.elements[m[k % m.len()] as usize];
                let mut xs = [Vec3::ZERO; 64];
                sub_centroids(&el.p, 2, &mut xs);
                *o = (xs[k], el.n);
            }
        }
        out
    }

    /// The fraction of [`FAR_RAYS`] segments between points of `p` and of
    /// `q` that are unoccluded.
    pub fn visibility(&self, p: usize, q: usize, vis: &Visibility<'_>) -> f32 {
        let (a, b) = (&self.points[p], &self.points[q]);
        let seen = a
            .iter()
            .zip(b)
            .filter(|((x, nx), (y, ny))| vis.visible(*x, *nx, *y, *ny))
            .count();
        seen as f32 / FAR_RAYS as f32
    }
}

/// The fraction of the [`FAR_RAYS`] segments from `x` (normal `n`) to
/// `points` (with their normals) that are unoccluded.
pub(crate) fn free_fraction(
    vis: &Visibility<'_>,
    x: Vec3,
    n: Vec3,
    points: impl Iterator<Item = (Vec3, Vec3)>,
) -> f32 {
    let seen = points
        .take(FAR_RAYS)
        .filter(|&(y, ny)| vis.visible(x, n, y, ny))
        .count();
    seen as f32 / FAR_RAYS as f32
}

/// The point-to-disc form factor from a receiving point `x` (normal `n`) to
/// a source of area `area` at `c` with normal `nc`: `A cos_c cos_x / (pi
/// d^2 + A)`, exact on the axis of a disc (Wallace, Elmquist and Haines
/// 1989).
#[inline]
pub(crate) fn point_to_disc(x: Vec3, n: Vec3, c: Vec3, nc: Vec3, area: f32) -> f32 {
    let d = x - c;
    let d2 = d.length_squared();
    if d2 <= 0.0 {
        return 0.0;
    }
    let inv = d2.sqrt().recip();
    let (cos_c, cos_x) = (nc.dot(d) * inv, -n.dot(d) * inv);
    if cos_c <= 0.0 || cos_x <= 0.0 {
        return 0.0;
    }
    area * cos_c * cos_x / (PI * d2 + area)
}

/// What a shot reads of an element, packed: centroid, normal, area and
/// the largest distance from the centroid to a corner.
#[derive(Debug, Clone, Copy)]
struct Geo {
    c: Vec3,
    n: Vec3,
    area: f32,
    radius: f32,
}

/// Shots of progressive refinement from patches to elements, with
/// ray-cast (or, without visibility, analytic) element form factors.
pub(crate) struct PatchShooter<'a> {
    mesh: &'a ElementMesh,
    patches: &'a Patches,
    rule: PairRule,
    vis: Option<&'a Visibility<'a>>,
    tol: f32,
    geo: Vec<Geo>,
}

impl<'a> PatchShooter<'a> {
    /// A shooter over `mesh` and its `patches`; `vis` None: unoccluded.
    pub fn new(
        mesh: &'a ElementMesh,
        patches: &'a Patches,
        rule: PairRule,
        vis: Option<&'a Visibility<'a>>,
        tol: f32,
    ) -> Self {
        let geo = mesh
            .elements
            .par_iter()
            .map(|e| Geo {
                c: e.c,
                n: e.n,
                area: e.area,
                radius: e.p.iter().map(|q| q.distance(e.c)).fold(0.0f32, f32::max),
            })
            .collect();
        Self {
            mesh,
            patches,
            rule,
            vis,
            tol,
            geo,
        }
    }

    /// Shoots patch `p` with the unshot radiance `du` of every element:
    /// writes `f[j] = F_{j <- p}` (summed over the patch's elements) and
    /// `g[j] = sum_{e in p} F_{j <- e} du_e` for every element `j`.
    pub fn shoot(&self, p: usize, du: &[Vec3], f: &mut [f32], g: &mut [Vec3]) {
        let (mesh, pt) = (self.mesh, self.patches);
        let shooter = pt.elements(p);
        let single = shooter.len() == 1;
        // Area-weighted unshot radiance of the shooter (what a far receiver sees).
        let du_p = if single {
            du[shooter[0] as usize]
        } else {
            shooter
                .iter()
                .map(|&e| du[e as usize] * mesh.elements[e as usize].area)
                .sum::<Vec3>()
                / pt.area[p].max(f32::MIN_POSITIVE)
        };
        let points = &pt.points[p];
        // Per receiving patch: its visibility when it is received in bulk,
        // NEAR when its elements need element form factors, or BEHIND when
        // it cannot face the shooter.
        const NEAR: f32 = -1.0;
        const BEHIND: f32 = -2.0;
        let bulk: Vec<f32> = (0..pt.len())
            .into_par_iter()
            .map(|q| {
                if q == p || (single && pt.elements(q).len() == 1) {
                    NEAR
                } else if !pt.may_face(p, q) {
                    BEHIND
                } else if !pt.far(p, q) {
                    NEAR
                } else {
                    match self.vis {
                        Some(v) => pt.visibility(p, q, v),
                        None => 1.0,
                    }
                }
            })
            .collect();
        f.par_iter_mut()
            .zip(g.par_iter_mut())
            .enumerate()
            .for_each(|(j, (fj, gj))| {
                let v = bulk[pt.of[j] as usize];
                if v == BEHIND {
                    (*fj, *gj) = (0.0, Vec3::ZERO);
                } else if v >= 0.0 {
                    let ff = if v > 0.0 {
                        let r = &self.geo[j];
                        v * point_to_disc(r.c, r.n, pt.centre[p], pt.normal[p], pt.area[p])
                    } else {
                        0.0
                    };
                    (*fj, *gj) = (ff, ff * du_p);
                } else if single {
                    let recv = &mesh.elements[j];
                    let i = shooter[0] as usize;
                    let ff = if j == i {
                        0.0
                    } else {
                        pair(recv, &mesh.elements[i], self.rule, self.vis, self.tol)
                    };
                    (*fj, *gj) = (ff, ff * du[i]);
                } else {
                    // Near a shooting patch of several elements: the
                    // unoccluded element form factors summed over it, times
                    // the fraction of rays from the receiver to it that are
                    // free. Shooting elements far from the receiver by the
                    // patches' criterion send the point-to-disc form factor.
                    let recv = &mesh.elements[j];
                    let rg = &self.geo[j];
                    let (mut sf, mut sg) = (0.0f32, Vec3::ZERO);
                    for &i in shooter {
                        let i = i as usize;
                        if i != j {
                            let s = &self.geo[i];
                            let reach = FAR * (s.radius + rg.radius);
                            let ff = if rg.c.distance_squared(s.c) > reach * reach {
                                point_to_disc(rg.c, rg.n, s.c, s.n, s.area)
                            } else {
                                pair(recv, &mesh.elements[i], self.rule, None, self.tol)
                            };
                            sf += ff;
                            sg += ff * du[i];
                        }
                    }
                    if sf > 0.0
                        && let Some(v) = self.vis
                    {
                        let frac = free_fraction(v, recv.c, recv.n, points.iter().copied());
                        (sf, sg) = (sf * frac, sg * frac);
                    }
                    (*fj, *gj) = (sf, sg);
                }
            });
    }
}
