//! Clustering for hierarchical radiosity (Smits, Arvo and Greenberg 1994,
//! "A clustering algorithm for radiosity in complex environments"; Sillion
//! 1995, "A unified hierarchical algorithm for global illumination with
//! scattering volumes and object clusters").
//!
//! Above [`CLUSTER_ABOVE`] source triangles the hierarchical solver does not
//! link every pair of quadtree roots (quadratic in the input). A binary tree
//! of volume *clusters* is built over the roots (median splits of their
//! centroids along the longest axis: a BVH), and linking starts from the
//! root cluster's link to itself, refined top down: a cluster's link to
//! itself becomes the links among its two children (or waits, re-examined
//! after each solve, while `rho * max(B) * A` is below the power
//! threshold); a link whose oracle exceeds the threshold splits its larger
//! end (a cluster into its two children, a surface into its quadtree
//! children, as without clusters).
//!
//! The oracle bounds the radiance a link carries, `rho_p * max(B_q) * F`,
//! with `F = A_q / (pi d^2 + A_q)` (the disc bound of the pairwise solver;
//! `d` is the gap between the bounding spheres when either end is a
//! cluster, and `F = 1` where they overlap). It must exceed both the
//! pairwise solver's radiance threshold (a quarter of it when either end
//! is a cluster) and a threshold on the *power* it
//! moves (times the receiver's area: Smits, Arvo and Greenberg's `B F A`),
//! [`POWER_EPS`] of the emitted power, so small receivers stay linked at
//! cluster level and the number of links follows the light, not the input.
//!
//! A cluster is seen from outside through its projected area
//! `A(w) = (V.w + sqrt(A w^T M w)) / 2` (`V = sum A_i n_i`, `M = sum A_i n_i
//! n_i^T`): half the signed projection plus the Cauchy-Schwarz estimate of
//! `sum A_i |n_i . w|`, exact for a planar cluster and within 16 % of
//! Sillion's isotropic `A / 4` for uniformly oriented ones. Its radiance is
//! the area-weighted mean of its children's (the pull). A surface receives
//! from a cluster `q` the point-to-disc factor `A_q(w) cos / (pi r^2 +
//! A_q)` at its centre (from a surface, the pairwise solver's ray-cast form
//! factor); what a *cluster* receives, `B_q A_q(w) / (pi r^2 + A_q)` seen
//! from its centre, is binned by direction (a cube map of [`BINS`] cells,
//! each keeping its weighted mean direction) and pushed down to the
//! quadtree roots under it, each applying its own normal's cosine (Smits
//! et al.'s per-element receiving, in time linear in the roots). Links
//! from or to a cluster carry one visibility: the free fraction of up to
//! four rays between facing points spread over the two ends, cast through
//! the scene's BVH.

use crate::formfactor::{facing, sub_centroids};
use crate::hierarchical::{HrStats, REFINEMENTS, Tree};
use crate::ray_cast::{PairRule, pair};
use crate::solver::{STALL_WINDOW, Stopper};
use chiaro_core::error::CoreError;
use chiaro_core::progress::Progress;
use glam::Vec3;
use rayon::prelude::*;
use std::f32::consts::PI;

/// Source triangles above which the hierarchical solver clusters (and the
/// `auto` solver picks it).
pub(crate) const CLUSTER_ABOVE: usize = crate::Solver::CLUSTER_ABOVE;

/// The power threshold of the oracle, as a fraction of the emitted power.
pub(crate) const POWER_EPS: f32 = 1e-4;

/// Links past which refinement stops (each link then stays where it is),
/// so memory and time stay bounded however fine the input.
pub(crate) const LINK_BUDGET: usize = 6_000_000;

/// The tag of a cluster's node id (a surface node's id is its index in the
/// quadtree forest).
const CL: u32 = 1 << 31;
/// No parent (the root cluster).
const NONE: u32 = u32::MAX;

/// Cells along each edge of a cube face: what a cluster receives is binned
/// by direction into `6 x BIN_SIDE^2` bins.
const BIN_SIDE: usize = 3;
const BINS: usize = 6 * BIN_SIDE * BIN_SIDE;
/// Roots under a cluster from which the push goes on in parallel.
const PAR_ROOTS: usize = 2048;

/// The light a cluster receives (with what its ancestors received), by
/// direction: per bin, the sum of the reflected-radiance factors `K` of
/// the sources in it (RGB) and their `|K|`-weighted direction, so one
/// source in a bin is evaluated at its own direction.
#[derive(Clone, Copy)]
struct Bins {
    k: [Vec3; BINS],
    d: [Vec3; BINS],
    any: bool,
}

impl Bins {
    const EMPTY: Self = Self {
        k: [Vec3::ZERO; BINS],
        d: [Vec3::ZERO; BINS],
        any: false,
    };

    /// Adds `k` arriving from unit direction `w`.
    fn add(&mut self, w: Vec3, k: Vec3) {
        let a = w.abs();
        let (face, u, v, m) = if a.x >= a.y && a.x >= a.z {
            (usize::from(w.x < 0.0), w.y, w.z, a.x)
        } else if a.y >= a.z {
            (2 + usize::from(w.y < 0.0), w.z, w.x, a.y)
        } else {
            (4 + usize::from(w.z < 0.0), w.x, w.y, a.z)
        };
        let m = m.max(f32::MIN_POSITIVE);
        let side = BIN_SIDE as f32;
        let cell = |x: f32| ((x / m * 0.5 + 0.5) * side).clamp(0.0, side - 1.0) as usize;
        let i = (face * BIN_SIDE + cell(u)) * BIN_SIDE + cell(v);
        self.k[i] += k;
        self.d[i] += w * k.element_sum();
        self.any = true;
    }

    /// The reflected-radiance gather of a surface of unit normal `n`:
    /// `sum K max(0, n . w)`.
    fn gather(&self, n: Vec3) -> Vec3 {
        if !self.any {
            return Vec3::ZERO;
        }
        let mut sum = Vec3::ZERO;
        for (k, d) in self.k.iter().zip(&self.d) {
            let len = d.length();
            if len > 0.0 {
                let cos = n.dot(*d) / len;
                if cos > 0.0 {
                    sum += *k * cos;
                }
            }
        }
        sum
    }
}

#[inline]
fn is_cluster(n: u32) -> bool {
    n & CL != 0
}

/// A volume cluster of quadtree roots.
#[derive(Debug, Clone, Copy)]
struct Cluster {
    lo: Vec3,
    hi: Vec3,
    area: f32,
    /// `sum A_i n_i`.
    v: Vec3,
    /// `sum A_i n_i n_i^T`: xx, yy, zz, xy, xz, yz.
    m: [f32; 6],
    /// The largest albedo channel under it.
    rho: f32,
    kids: [u32; 2],
    /// The number of quadtree roots under it.
    count: u32,
}

/// Bytes a cluster holds: itself, its radiance and brightest leaf
/// radiance, its parent and its list of received links.
pub(crate) const CLUSTER_BYTES: u64 = (size_of::<Cluster>()
    + 2 * size_of::<Vec3>()
    + size_of::<u32>()
    + size_of::<Vec<(u32, f32)>>()) as u64;

/// Bytes the cluster tree holds a source triangle: its root's parent, its
/// place in the leaf order, its entry while the tree is built (centroid and
/// root) and what the push carries down to it each iteration.
pub(crate) const ROOT_BYTES: u64 =
    (2 * size_of::<u32>() + size_of::<(Vec3, u32)>() + size_of::<Vec3>()) as u64;

/// Adds the cluster tree over `sources` quadtree roots to `estimate`: a
/// binary tree, so one cluster fewer than the roots.
pub(crate) fn memory(sources: u64, estimate: &mut chiaro_core::budget::Estimate) {
    let clusters = sources.saturating_sub(1);
    estimate.add(
        format!("radiosity clusters ({clusters})"),
        chiaro_core::budget::bytes_of(clusters, CLUSTER_BYTES)
            .saturating_add(chiaro_core::budget::bytes_of(sources, ROOT_BYTES)),
    );
}

/// The clustered solver's state over the quadtree forest `t`.
struct Clustered<'t, 'a, 's> {
    t: &'t mut Tree<'a, 's>,
    cl: Vec<Cluster>,
    /// Radiance and brightest leaf radiance of each cluster.
    cb: Vec<Vec3>,
    cbmax: Vec<Vec3>,
    /// The parent cluster of each cluster, and of each source's root.
    parent: Vec<u32>,
    root_parent: Vec<u32>,
    /// Links received by each cluster: (source node, visibility).
    clinks: Vec<Vec<(u32, f32)>>,
    /// Clusters whose exchange within themselves is below the threshold
    /// (left out until the light grows: [`Self::refine_existing`]).
    deferred: Vec<u32>,
    /// The source triangles in the order of the tree's leaves: every
    /// cluster covers a contiguous range.
    order: Vec<u32>,
    /// The root cluster.
    root: u32,
    eps_pow: f32,
    links: usize,
    calls: u64,
    progress: &'t dyn Progress,
}

impl<'t, 'a, 's> Clustered<'t, 'a, 's> {
    /// The clustered solver over the forest `t` (not yet built), with the
    /// oracle's power threshold `eps_pow`.
    fn new(t: &'t mut Tree<'a, 's>, eps_pow: f32, progress: &'t dyn Progress) -> Self {
        Self {
            t,
            cl: Vec::new(),
            cb: Vec::new(),
            cbmax: Vec::new(),
            parent: Vec::new(),
            root_parent: Vec::new(),
            clinks: Vec::new(),
            deferred: Vec::new(),
            order: Vec::new(),
            root: NONE,
            eps_pow: eps_pow.max(f32::MIN_POSITIVE),
            links: 0,
            calls: 0,
            progress,
        }
    }

    /// Builds the cluster tree over the roots of `t` (at least two) and
    /// pulls the first radiances up it.
    fn build(&mut self) -> u32 {
        let mut items: Vec<(Vec3, u32)> = self
            .t
            .roots
            .iter()
            .map(|&r| (self.t.el[r as usize].c, r))
            .collect();
        self.root_parent = vec![NONE; self.t.roots.len()];
        let root = self.split(&mut items);
        self.order = items
            .iter()
            .map(|&(_, r)| self.t.el[r as usize].source)
            .collect();
        self.cb = vec![Vec3::ZERO; self.cl.len()];
        self.cbmax = vec![Vec3::ZERO; self.cl.len()];
        self.clinks = vec![Vec::new(); self.cl.len()];
        self.pull();
        root
    }

    /// The subtree over `items` (centroid, root node): a root alone, else a
    /// cluster of the two halves split at the median of the longest axis.
    fn split(&mut self, items: &mut [(Vec3, u32)]) -> u32 {
        if let [(_, r)] = items {
            return *r;
        }
        let (lo, hi) = items.iter().fold(
            (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
            |(lo, hi), (c, _)| (lo.min(*c), hi.max(*c)),
        );
        let ext = hi - lo;
        let axis = if ext.x >= ext.y && ext.x >= ext.z {
            0
        } else if ext.y >= ext.z {
            1
        } else {
            2
        };
        let mid = items.len() / 2;
        items.select_nth_unstable_by(mid, |a, b| a.0[axis].total_cmp(&b.0[axis]));
        let (l, r) = items.split_at_mut(mid);
        let kids = [self.split(l), self.split(r)];
        let (a, b) = (self.summary(kids[0]), self.summary(kids[1]));
        let id = self.cl.len() as u32;
        let mut m = [0.0; 6];
        for (k, x) in m.iter_mut().enumerate() {
            *x = a.m[k] + b.m[k];
        }
        self.cl.push(Cluster {
            lo: a.lo.min(b.lo),
            hi: a.hi.max(b.hi),
            area: a.area + b.area,
            v: a.v + b.v,
            m,
            rho: a.rho.max(b.rho),
            kids,
            count: items.len() as u32,
        });
        self.parent.push(NONE);
        for k in kids {
            if is_cluster(k) {
                self.parent[(k & !CL) as usize] = id;
            } else {
                let s = self.t.el[k as usize].source as usize;
                self.root_parent[s] = id;
            }
        }
        id | CL
    }

    /// Node `n` as a cluster summary (a surface node as a cluster of one).
    fn summary(&self, n: u32) -> Cluster {
        if is_cluster(n) {
            return self.cl[(n & !CL) as usize];
        }
        let e = &self.t.el[n as usize];
        let (a, nn) = (e.area, e.n);
        Cluster {
            lo: e.p[0].min(e.p[1]).min(e.p[2]),
            hi: e.p[0].max(e.p[1]).max(e.p[2]),
            area: a,
            v: nn * a,
            m: [
                a * nn.x * nn.x,
                a * nn.y * nn.y,
                a * nn.z * nn.z,
                a * nn.x * nn.y,
                a * nn.x * nn.z,
                a * nn.y * nn.z,
            ],
            rho: e.rho.max_element(),
            kids: [NONE; 2],
            count: 1,
        }
    }

    /// Cluster radiances from their children's, children first (clusters
    /// are stored after their children).
    fn pull(&mut self) {
        for c in 0..self.cl.len() {
            let (mut sum, mut mx) = (Vec3::ZERO, Vec3::ZERO);
            for k in self.cl[c].kids {
                sum += self.b(k) * self.area(k);
                mx = mx.max(self.bmax(k));
            }
            self.cb[c] = sum / self.cl[c].area.max(f32::MIN_POSITIVE);
            self.cbmax[c] = mx;
        }
    }

    fn b(&self, n: u32) -> Vec3 {
        if is_cluster(n) {
            self.cb[(n & !CL) as usize]
        } else {
            self.t.b[n as usize]
        }
    }

    fn bmax(&self, n: u32) -> Vec3 {
        if is_cluster(n) {
            self.cbmax[(n & !CL) as usize]
        } else {
            self.t.bmax[n as usize]
        }
    }

    fn area(&self, n: u32) -> f32 {
        if is_cluster(n) {
            self.cl[(n & !CL) as usize].area
        } else {
            self.t.el[n as usize].area
        }
    }

    fn rho(&self, n: u32) -> f32 {
        if is_cluster(n) {
            self.cl[(n & !CL) as usize].rho
        } else {
            self.t.el[n as usize].rho.max_element()
        }
    }

    /// Centre and bounding radius.
    fn sphere(&self, n: u32) -> (Vec3, f32) {
        if is_cluster(n) {
            let c = &self.cl[(n & !CL) as usize];
            ((c.lo + c.hi) * 0.5, (c.hi - c.lo).length() * 0.5)
        } else {
            let e = &self.t.el[n as usize];
            let r = e.p.iter().map(|q| q.distance(e.c)).fold(0.0f32, f32::max);
            (e.c, r)
        }
    }

    /// The area of node `n` projected towards unit direction `w`, front
    /// faces only (see the module docs).
    fn projected_area(&self, n: u32, w: Vec3) -> f32 {
        if !is_cluster(n) {
            let e = &self.t.el[n as usize];
            return e.area * e.n.dot(w).max(0.0);
        }
        let c = &self.cl[(n & !CL) as usize];
        let m = c.m;
        let q = m[0] * w.x * w.x
            + m[1] * w.y * w.y
            + m[2] * w.z * w.z
            + 2.0 * (m[3] * w.x * w.y + m[4] * w.x * w.z + m[5] * w.y * w.z);
        (0.5 * (c.v.dot(w) + (c.area * q.max(0.0)).sqrt())).clamp(0.0, c.area)
    }

    /// The factor from a point `x` with normal `nx` to node `q`, without
    /// visibility: `A_q(w) cos / (pi r^2 + A_q)` (a point-to-disc form
    /// factor with the node's projected area).
    fn point_factor(&self, x: Vec3, nx: Vec3, q: u32) -> f32 {
        let (c, _) = self.sphere(q);
        let d = c - x;
        let r2 = d.length_squared();
        if r2 <= 0.0 {
            return 0.0;
        }
        let w = d / r2.sqrt();
        let cos = nx.dot(w);
        if cos <= 0.0 {
            return 0.0;
        }
        let aq = self.area(q);
        self.projected_area(q, -w) * cos / (PI * r2 + aq)
    }

    /// Four points (with normals) spread over node `n`: a surface's
    /// sub-centroids, or the centres of four surfaces of a cluster reached
    /// by the four left/right choices of its top two levels.
    fn points(&self, n: u32) -> [(Vec3, Vec3); 4] {
        if !is_cluster(n) {
            let e = &self.t.el[n as usize];
            let mut xs = [Vec3::ZERO; 64];
            sub_centroids(&e.p, 2, &mut xs);
            return [0, 1, 2, 3].map(|i| (xs[i], e.n));
        }
        [0usize, 1, 2, 3].map(|i| {
            let mut m = n;
            let mut level = 0;
            while is_cluster(m) {
                let bit = if level < 2 { (i >> level) & 1 } else { 0 };
                m = self.cl[(m & !CL) as usize].kids[bit];
                level += 1;
            }
            let e = &self.t.el[m as usize];
            (e.c, e.n)
        })
    }

    /// The free fraction of up to four rays between points of `p` and
    /// `q` that face each other (a point facing away takes no part in the
    /// exchange, and lifting it to its back would start the ray inside a
    /// closed object); 1 when no sampled pair faces (the projected areas
    /// carry the orientation).
    fn visibility(&self, p: u32, q: u32) -> f32 {
        let Some(vis) = self.t.vis else {
            return 1.0;
        };
        let (a, b) = (self.points(p), self.points(q));
        let (mut seen, mut tried) = (0u32, 0u32);
        'pairs: for k in 0..4 {
            for (i, &(x, nx)) in a.iter().enumerate() {
                let (y, ny) = b[(i + k) % 4];
                let d = y - x;
                if nx.dot(d) <= 0.0 || ny.dot(d) >= 0.0 {
                    continue;
                }
                tried += 1;
                if vis.visible(x, nx, y, ny) {
                    seen += 1;
                }
                if tried == 4 {
                    break 'pairs;
                }
            }
        }
        if tried == 0 {
            1.0
        } else {
            seen as f32 / tried as f32
        }
    }

    /// The BF oracle of a link `q -> p` (see the module docs).
    fn oracle(&self, p: u32, q: u32) -> bool {
        let bq = self.bmax(q).max_element();
        let rho = self.rho(p);
        if bq <= 0.0 || rho <= 0.0 {
            return false;
        }
        let ((cp, rp), (cq, rq)) = (self.sphere(p), self.sphere(q));
        let aq = self.area(q);
        let d = cp.distance(cq);
        let f = if !is_cluster(p) && !is_cluster(q) {
            aq / (PI * d * d + aq)
        } else {
            let gap = d - rp - rq;
            if gap <= 0.0 {
                1.0
            } else {
                aq / (PI * gap * gap + aq)
            }
        };
        let e = rho * bq * f;
        // A cluster's transport is cruder than a pair's form factor (its
        // projected area, one visibility for the whole link): a quarter of
        // the pairwise radiance threshold.
        let eps = if is_cluster(p) || is_cluster(q) {
            0.25 * self.t.eps
        } else {
            self.t.eps
        };
        e > eps && e * self.area(p) > self.eps_pow
    }

    /// Whether the light cluster `c` exchanges within itself may exceed
    /// the power threshold: `rho * max(B) * A` bounds it (F <= 1).
    fn self_oracle(&self, c: u32) -> bool {
        let e = self.rho(c) * self.bmax(c).max_element() * self.area(c);
        e > self.eps_pow && self.links < LINK_BUDGET
    }

    fn can_split(&self, n: u32) -> bool {
        is_cluster(n) || self.t.can_subdivide(n)
    }

    /// The children of node `n` (making a surface's quadtree children).
    fn kids(&mut self, n: u32) -> ([u32; 4], usize) {
        if is_cluster(n) {
            let [a, b] = self.cl[(n & !CL) as usize].kids;
            ([a, b, 0, 0], 2)
        } else {
            (self.t.subdivide(n), 4)
        }
    }

    fn add_link(&mut self, p: u32, q: u32) {
        if is_cluster(p) {
            self.clinks[(p & !CL) as usize].push((q, f32::NAN));
        } else {
            self.t.links[p as usize].push((q, f32::NAN));
        }
        self.links += 1;
    }

    /// Links `q -> p` (p receives) at the level the oracle accepts; a
    /// cluster's link to itself becomes the links among its children,
    /// unless the power it could move is below the threshold.
    fn refine(&mut self, p: u32, q: u32) -> Result<(), CoreError> {
        self.calls += 1;
        if self.calls.is_multiple_of(65_536) && self.progress.cancelled() {
            return Err(CoreError::Cancelled);
        }
        if p == q {
            if is_cluster(p) {
                if self.self_oracle(p) {
                    let [a, b] = self.cl[(p & !CL) as usize].kids;
                    for (x, y) in [(a, a), (a, b), (b, a), (b, b)] {
                        self.refine(x, y)?;
                    }
                } else {
                    self.deferred.push(p);
                }
            }
            return Ok(());
        }
        if !is_cluster(p)
            && !is_cluster(q)
            && !facing(&self.t.el[p as usize], &self.t.el[q as usize], self.t.tol)
        {
            return Ok(());
        }
        let (sp, sq) = (self.can_split(p), self.can_split(q));
        if (sp || sq) && self.links < LINK_BUDGET && self.oracle(p, q) {
            let split_q = sq && (!sp || self.area(q) > self.area(p));
            if split_q {
                let (k, n) = self.kids(q);
                for &c in &k[..n] {
                    self.refine(p, c)?;
                }
            } else {
                let (k, n) = self.kids(p);
                for &c in &k[..n] {
                    self.refine(c, q)?;
                }
            }
        } else {
            self.add_link(p, q);
        }
        Ok(())
    }

    /// Evaluates the new links (marked NaN) in parallel and drops those
    /// between surfaces that carry nothing.
    fn evaluate(&mut self) {
        let mut surface = std::mem::take(&mut self.t.links);
        let mut clusters = std::mem::take(&mut self.clinks);
        {
            let me = &*self;
            let t = &*me.t;
            // Fewer receiver points than the pairwise solver's near rule:
            // near pairs of fine input are many here.
            let rule = PairRule {
                near_m: t.rule.near_m.min(3),
                vis_m: t.rule.vis_m.min(1),
                ..t.rule
            };
            surface.par_iter_mut().enumerate().for_each(|(p, ls)| {
                let ep = &t.el[p];
                for (q, f) in ls.iter_mut() {
                    if f.is_nan() {
                        *f = if is_cluster(*q) {
                            me.visibility(p as u32, *q) * me.point_factor(ep.c, ep.n, *q)
                        } else {
                            pair(ep, &t.el[*q as usize], rule, t.vis, t.tol)
                        };
                    }
                }
                // A link from a cluster carrying nothing now (its sampled
                // rays blocked, its centre behind) is kept: refined later,
                // parts of it may carry light.
                ls.retain(|(q, f)| *f > 0.0 || is_cluster(*q));
            });
            clusters.par_iter_mut().enumerate().for_each(|(c, ls)| {
                for (q, f) in ls.iter_mut() {
                    if f.is_nan() {
                        *f = me.visibility(c as u32 | CL, *q);
                    }
                }
            });
        }
        self.t.links = surface;
        self.clinks = clusters;
        self.links = self.link_count();
    }

    fn link_count(&self) -> usize {
        self.t.links.iter().map(Vec::len).sum::<usize>()
            + self.clinks.iter().map(Vec::len).sum::<usize>()
    }

    /// Re-examines every link with the current radiances; returns whether
    /// any was refined.
    fn refine_existing(&mut self) -> Result<bool, CoreError> {
        let mut changed = false;
        let n = self.t.links.len();
        for p in 0..n {
            let old = std::mem::take(&mut self.t.links[p]);
            let mut keep = Vec::with_capacity(old.len());
            for (q, f) in old {
                let p = p as u32;
                if (self.can_split(p) || self.can_split(q))
                    && self.links < LINK_BUDGET
                    && self.oracle(p, q)
                {
                    changed = true;
                    self.links -= 1;
                    self.refine(p, q)?;
                } else {
                    keep.push((q, f));
                }
            }
            self.t.links[p].extend(keep);
        }
        for c in 0..self.cl.len() {
            let old = std::mem::take(&mut self.clinks[c]);
            let mut keep = Vec::with_capacity(old.len());
            let p = c as u32 | CL;
            for (q, f) in old {
                if self.links < LINK_BUDGET && self.oracle(p, q) {
                    changed = true;
                    self.links -= 1;
                    self.refine(p, q)?;
                } else {
                    keep.push((q, f));
                }
            }
            self.clinks[c].extend(keep);
        }
        for c in std::mem::take(&mut self.deferred) {
            if self.self_oracle(c) {
                changed = true;
                self.refine(c, c)?;
            } else {
                self.deferred.push(c);
            }
        }
        Ok(changed)
    }

    /// Adds what cluster `c` receives along its links to `bins`: per link
    /// from `q`, `B_q V A_q(w) / (pi r^2 + A_q)` from the direction `w` of
    /// `q`'s centre seen from `c`'s (the cosine is each surface's own).
    fn add_received(&self, c: usize, bins: &mut Bins) {
        let (cc, _) = self.sphere(c as u32 | CL);
        for &(q, v) in &self.clinks[c] {
            let b = self.b(q);
            if b == Vec3::ZERO {
                continue;
            }
            let d = self.sphere(q).0 - cc;
            let r2 = d.length_squared();
            if r2 <= 0.0 {
                continue;
            }
            let w = d / r2.sqrt();
            let f = v * self.projected_area(q, -w) / (PI * r2 + self.area(q));
            if f > 0.0 {
                bins.add(w, b * f);
            }
        }
    }

    /// Pushes what the clusters receive down to the quadtree roots under
    /// node `n` (`acc`: what its ancestors received), writing each root's
    /// gather to `out` (one entry per root under `n`, in leaf order).
    fn push_down(&self, n: u32, acc: &Bins, out: &mut [Vec3]) {
        if !is_cluster(n) {
            out[0] = acc.gather(self.t.el[n as usize].n);
            return;
        }
        let c = (n & !CL) as usize;
        let mut own;
        let acc = if self.clinks[c].is_empty() {
            acc
        } else {
            own = *acc;
            self.add_received(c, &mut own);
            &own
        };
        let [a, b] = self.cl[c].kids;
        let na = if is_cluster(a) {
            self.cl[(a & !CL) as usize].count as usize
        } else {
            1
        };
        let (lo, hi) = out.split_at_mut(na);
        if lo.len() + hi.len() >= PAR_ROOTS {
            rayon::join(|| self.push_down(a, acc, lo), || self.push_down(b, acc, hi));
        } else {
            self.push_down(a, acc, lo);
            self.push_down(b, acc, hi);
        }
    }

    /// Gathers along every link, pushes what clusters received down to the
    /// quadtree roots under them (each with its own centre and normal),
    /// pushes and pulls every quadtree, then pulls the clusters; until the
    /// change in power falls below `tol` (the shared stop criterion).
    fn iterate(
        &mut self,
        tol: f32,
        max_iter: u32,
        p0: f32,
        stats: &mut HrStats,
    ) -> Result<(), CoreError> {
        let mut stopper = Stopper::new(tol, max_iter, STALL_WINDOW);
        for done in 1.. {
            if self.progress.cancelled() {
                return Err(CoreError::Cancelled);
            }
            let old = self.t.b.clone();
            let (g, down): (Vec<Vec3>, Vec<Vec3>) = {
                let me = &*self;
                let g =
                    me.t.links
                        .par_iter()
                        .map(|ls| ls.iter().map(|&(q, f)| me.b(q) * f).sum())
                        .collect();
                let mut down = vec![Vec3::ZERO; me.order.len()];
                me.push_down(me.root, &Bins::EMPTY, &mut down);
                (g, down)
            };
            self.t.g = g;
            for (i, d) in down.into_iter().enumerate() {
                let root = self.t.roots[self.order[i] as usize];
                self.t.push_pull(root, d);
            }
            self.pull();
            stats.iterations += 1;
            stats.unshot = self.t.leaf_power_change(&old) / p0;
            self.progress.message(&format!(
                "hierarchical (clustered): iteration {}, residual {:.3e}, {} links",
                stats.iterations, stats.unshot, self.links
            ));
            if let Some(stop) = stopper.check(stats.unshot, done) {
                stats.stop = stop;
                break;
            }
        }
        Ok(())
    }
}

/// Solves the quadtree forest `t` (roots made, `t.eps` set) by clustered
/// hierarchical radiosity: the cluster tree, the root's self-link refined,
/// gathers and push-pull to `tolerance`, then up to [`REFINEMENTS`] rounds
/// of BF refinement. `p0` is the emitted power. Returns the number of
/// links and of clusters.
///
/// # Errors
/// [`CoreError::Cancelled`] when `progress` asks.
pub(crate) fn solve(
    t: &mut Tree<'_, '_>,
    tolerance: f32,
    max_iter: u32,
    p0: f32,
    stats: &mut HrStats,
    progress: &dyn Progress,
) -> Result<(usize, usize), CoreError> {
    let mut c = Clustered::new(t, POWER_EPS * p0 / 3.0, progress);
    let root = c.build();
    c.root = root;
    progress.message(&format!(
        "hierarchical: {} clusters over {} source triangles; linking from the root cluster",
        c.cl.len(),
        c.t.roots.len()
    ));
    c.refine(root, root)?;
    c.evaluate();
    c.iterate(tolerance, max_iter, p0, stats)?;
    progress.advance(1);
    let mut rounds = 1;
    for _ in 0..REFINEMENTS {
        if !c.refine_existing()? {
            break;
        }
        c.evaluate();
        c.iterate(tolerance, max_iter, p0, stats)?;
        progress.advance(1);
        rounds += 1;
    }
    progress.advance(REFINEMENTS + 1 - rounds);
    Ok((c.links, c.cl.len()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh;
    use crate::ray_cast::Visibility;
    use chiaro_core::context::RenderContext;
    use chiaro_core::progress::NoProgress;
    use chiaro_core::scene::RenderSettings;

    #[test]
    fn the_cluster_tree_covers_every_source_once() {
        let s = chiaro_testkit::scenes::unit_cornell_box();
        let settings = RenderSettings::default();
        let ctx = RenderContext::new(&s, &settings, &NoProgress).expect("context");
        let ps = ctx.tessellated();
        let m = mesh::build(ps, 0.25, true, &NoProgress).expect("mesh");
        let vis = Visibility {
            accel: ctx.tessellated_accel(),
            eps: 1e-4,
        };
        let rule = PairRule {
            far_m: 1,
            mid_m: 1,
            near_m: 1,
            vis_m: 1,
        };
        let mut t = Tree::forest(ps, &m, &[], Some(&vis), rule, 1e-6);
        let n = t.roots.len();
        let area: f32 = t.roots.iter().map(|&r| t.el[r as usize].area).sum();
        let mut c = Clustered::new(&mut t, 1.0, &NoProgress);
        c.root = c.build();
        // n leaves make n - 1 clusters; the leaf order is a permutation.
        assert_eq!(c.cl.len(), n - 1);
        let mut order = c.order.clone();
        order.sort_unstable();
        assert_eq!(order, (0..n as u32).collect::<Vec<_>>());
        assert_eq!(c.root, (c.cl.len() as u32 - 1) | CL);
        let root = c.cl[c.cl.len() - 1];
        assert_eq!(root.count as usize, n);
        assert!(
            (root.area - area).abs() <= 1e-4 * area,
            "{} {area}",
            root.area
        );
        // Each cluster holds its children's roots and boxes, and each
        // source's chain of parents ends at the root.
        for (i, cl) in c.cl.iter().enumerate() {
            let kids = cl.kids.map(|k| c.summary(k));
            assert_eq!(cl.count, kids[0].count + kids[1].count);
            for (j, k) in cl.kids.into_iter().enumerate() {
                assert!(kids[j].lo.cmpge(cl.lo).all() && kids[j].hi.cmple(cl.hi).all());
                if is_cluster(k) {
                    assert_eq!(c.parent[(k & !CL) as usize], i as u32);
                }
            }
        }
        for s in 0..n {
            let (mut p, mut steps) = (c.root_parent[s], 0);
            while c.parent[p as usize] != NONE {
                p = c.parent[p as usize];
                steps += 1;
                assert!(steps <= n);
            }
            assert_eq!(p | CL, c.root);
        }
        // The projected area of a planar cluster is exact.
        let floor = c.summary(c.t.roots[0]);
        let w = Vec3::new(0.3, 0.8, 0.1).normalize();
        let exact = floor.area * floor.v.normalize().dot(w).max(0.0);
        assert!((c.projected_area(c.t.roots[0], w) - exact).abs() < 1e-6);
    }
}
