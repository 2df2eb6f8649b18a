//! Hierarchical radiosity (Hanrahan, Salzman and Aupperle 1991).
//!
//! Every source triangle is the root of a quadtree of triangles (4-way
//! midpoint subdivision, down to the depth where it matches the element
//! mesh). Energy flows along *links* between nodes at whatever level is
//! accurate enough: a link from `q` to receiver `p` is refined (the larger
//! of the two is subdivided) while the "BF" oracle
//! `rho_p * max(B_q) * A_q / (pi r^2 + A_q)` (the disc upper bound of the
//! form factor times the largest radiance of a leaf under `q`) exceeds `eps`. The system is
//! then solved by Jacobi-style gathers along links followed by a push-pull
//! over each quadtree; links are refined again with the new radiances
//! (BF refinement) until nothing changes. The number of links grows about
//! linearly with the number of leaves, instead of quadratically. The first
//! links join every pair of source triangles (quadratic in the input);
//! above 2048 source triangles they start instead from a cluster hierarchy
//! over them (`cluster.rs`).

use crate::direct::point_light_direct;
use crate::environment::node_mean;
use crate::formfactor::facing;
use crate::mesh::{Element, ElementMesh, barycentric, material_at};
use crate::ray_cast::{PairRule, Visibility, pair};
use crate::solver::{STALL_WINDOW, Stop, Stopper};
use chiaro_core::budget::{Estimate, bytes_of};
use chiaro_core::error::CoreError;
use chiaro_core::prepared::PreparedScene;
use chiaro_core::progress::Progress;
use chiaro_core::scene::Light;
use glam::Vec3;
use rayon::prelude::*;
use std::f32::consts::PI;

/// Bytes a quadtree node holds: its element; its emitted, current,
/// brightest-leaf, gathered and incident radiance and the iteration's copy
/// of its radiance; its children, depth and link list.
pub(crate) const NODE_BYTES: u64 = (size_of::<Element>()
    + 6 * size_of::<Vec3>()
    + size_of::<Option<[u32; 4]>>()
    + size_of::<u32>()
    + size_of::<Vec<(u32, f32)>>()) as u64;

/// Bytes a link holds: the node it gathers from and the form factor.
pub(crate) const LINK_BYTES: u64 = size_of::<(u32, f32)>() as u64;

/// Links an element receives once refined, on average: the BF oracle
/// links each leaf (or its parent) to the nodes that carry light to it.
/// Measured 36 to 200 on the unit Cornell box (elements of 1/8 and 1/4,
/// pairwise and clustered) and the closed furnace (`tests_memory.rs`).
pub(crate) const LINKS_PER_ELEMENT: u64 = 100;

/// Adds what the hierarchical solver holds over `sources` source triangles
/// meshed into `elements` elements to `estimate`, and with `clustered` the
/// cluster tree over them ([`crate::cluster::memory`]). The basis: every
/// source triangle's quadtree refined down to its elements (4/3 of a node
/// an element); [`LINKS_PER_ELEMENT`] links an element, and without
/// clusters the first linking's one link each ordered pair of sources
/// (quadratic); with clusters at most the link budget.
pub(crate) fn memory(sources: u64, elements: u64, clustered: bool, estimate: &mut Estimate) {
    let elements = elements.max(sources);
    let nodes = elements.saturating_add(elements.saturating_sub(sources) / 3);
    estimate.add(
        format!("radiosity quadtrees ({nodes} nodes)"),
        bytes_of(nodes, NODE_BYTES),
    );
    let refined = elements.saturating_mul(LINKS_PER_ELEMENT);
    let links = if clustered {
        crate::cluster::memory(sources, estimate);
        refined.min(crate::cluster::LINK_BUDGET as u64)
    } else {
        refined.saturating_add(sources.saturating_mul(sources.saturating_sub(1)))
    };
    estimate.add(
        format!("radiosity links ({links})"),
        bytes_of(links, LINK_BYTES),
    );
}

/// Statistics of a hierarchical solution.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub(crate) struct HrStats {
    pub nodes: usize,
    pub leaves: usize,
    pub links: usize,
    pub iterations: u32,
    pub unshot: f32,
    /// Why the last round of gathers stopped.
    pub stop: Stop,
}

pub(crate) struct Tree<'a, 's> {
    pub(crate) ps: &'a PreparedScene<'s>,
    pub(crate) mesh: &'a ElementMesh,
    pub(crate) lights: &'a [Light],
    /// Each element's reflected environment light (empty without a map),
    /// averaged over a node's elements for the node's emission.
    pub(crate) env: &'a [Vec3],
    pub(crate) vis: Option<&'a Visibility<'a>>,
    pub(crate) rule: PairRule,
    pub(crate) tol: f32,
    pub(crate) el: Vec<Element>,
    pub(crate) e: Vec<Vec3>,
    pub(crate) b: Vec<Vec3>,
    pub(crate) bmax: Vec<Vec3>,
    pub(crate) g: Vec<Vec3>,
    pub(crate) incident: Vec<Vec3>,
    pub(crate) children: Vec<Option<[u32; 4]>>,
    pub(crate) depth: Vec<u32>,
    pub(crate) links: Vec<Vec<(u32, f32)>>,
    pub(crate) roots: Vec<u32>,
    pub(crate) eps: f32,
}

impl<'a, 's> Tree<'a, 's> {
    /// The quadtree roots of every source triangle of `mesh`, with no
    /// links (`eps` still 0).
    pub(crate) fn forest(
        ps: &'a PreparedScene<'s>,
        mesh: &'a ElementMesh,
        env: &'a [Vec3],
        vis: Option<&'a Visibility<'a>>,
        rule: PairRule,
        tol: f32,
    ) -> Self {
        let mut t = Tree {
            ps,
            mesh,
            lights: &ps.scene.lights,
            env,
            vis,
            rule,
            tol,
            el: Vec::new(),
            e: Vec::new(),
            b: Vec::new(),
            bmax: Vec::new(),
            g: Vec::new(),
            incident: Vec::new(),
            children: Vec::new(),
            depth: Vec::new(),
            links: Vec::new(),
            roots: Vec::new(),
            eps: 0.0,
        };
        for (si, s) in mesh.sources.iter().enumerate() {
            let r = t.make_node(si as u32, s.p, 0);
            t.roots.push(r);
        }
        t
    }

    pub(crate) fn make_node(&mut self, source: u32, p: [Vec3; 3], depth: u32) -> u32 {
        let s = &self.mesh.sources[source as usize];
        let c = (p[0] + p[1] + p[2]) / 3.0;
        let (u, v) = barycentric(&s.p, c);
        let (rho, le) = material_at(self.ps, s, u, v);
        let el = Element::new(p, s.n, rho, le, [0; 3], source);
        let mut direct = match self.vis {
            Some(vis) => point_light_direct(&el, self.lights, vis),
            None => Vec3::ZERO,
        };
        if !self.env.is_empty() {
            direct += node_mean(self.mesh, self.env, source, &p, depth);
        }
        self.el.push(el);
        self.e.push(le + direct);
        self.b.push(le + direct);
        self.bmax.push(le + direct);
        self.g.push(Vec3::ZERO);
        self.incident.push(Vec3::ZERO);
        self.children.push(None);
        self.depth.push(depth);
        self.links.push(Vec::new());
        self.el.len() as u32 - 1
    }

    fn max_depth(&self, node: u32) -> u32 {
        let k = self.mesh.k[self.el[node as usize].source as usize];
        k.trailing_zeros()
    }

    pub(crate) fn can_subdivide(&self, node: u32) -> bool {
        self.depth[node as usize] < self.max_depth(node)
    }

    pub(crate) fn subdivide(&mut self, node: u32) -> [u32; 4] {
        if let Some(c) = self.children[node as usize] {
            return c;
        }
        let [a, b, c] = self.el[node as usize].p;
        let (ab, bc, ca) = ((a + b) * 0.5, (b + c) * 0.5, (c + a) * 0.5);
        let (s, d) = (self.el[node as usize].source, self.depth[node as usize] + 1);
        let kids = [
            self.make_node(s, [a, ab, ca], d),
            self.make_node(s, [ab, b, bc], d),
            self.make_node(s, [ca, bc, c], d),
            self.make_node(s, [ab, bc, ca], d),
        ];
        // Children start from their parent's radiance so the oracle sees light.
        let (pb, pm) = (self.b[node as usize], self.bmax[node as usize]);
        for &k in &kids {
            self.b[k as usize] = self.b[k as usize].max(pb);
            self.bmax[k as usize] = self.bmax[k as usize].max(pm);
        }
        self.children[node as usize] = Some(kids);
        kids
    }

    fn oracle(&self, p: u32, q: u32) -> bool {
        let (ep, eq) = (&self.el[p as usize], &self.el[q as usize]);
        let r2 = ep.c.distance_squared(eq.c);
        let f = eq.area / (PI * r2 + eq.area);
        // The brightest leaf under q, not its mean: a coarse link transports
        // the mean radiance and loses the correlation between where q is
        // bright and where the form factor is large (e.g. near a shared edge).
        ep.rho.max_element() * self.bmax[q as usize].max_element() * f > self.eps
    }

    /// Links `q -> p` at the right level (p receives).
    fn refine(&mut self, p: u32, q: u32) {
        if !facing(&self.el[p as usize], &self.el[q as usize], self.tol) {
            return;
        }
        let (sp, sq) = (self.can_subdivide(p), self.can_subdivide(q));
        if (sp || sq) && self.oracle(p, q) {
            let split_q = sq && (!sp || self.el[q as usize].area > self.el[p as usize].area);
            if split_q {
                for c in self.subdivide(q) {
                    self.refine(p, c);
                }
            } else {
                for c in self.subdivide(p) {
                    self.refine(c, q);
                }
            }
        } else {
            self.links[p as usize].push((q, f32::NAN));
        }
    }

    /// Computes the form factors of new links (marked NaN), in parallel.
    fn evaluate_links(&mut self) {
        let (el, rule, vis, tol) = (&self.el, self.rule, self.vis, self.tol);
        self.links.par_iter_mut().enumerate().for_each(|(p, ls)| {
            for (q, f) in ls.iter_mut() {
                if f.is_nan() {
                    *f = pair(&el[p], &el[*q as usize], rule, vis, tol);
                }
            }
            ls.retain(|(_, f)| *f > 0.0);
        });
    }

    /// Re-examines every link with the current radiances; returns whether any changed.
    fn refine_existing(&mut self) -> bool {
        let mut changed = false;
        for p in 0..self.el.len() as u32 {
            let old = std::mem::take(&mut self.links[p as usize]);
            let mut keep = Vec::with_capacity(old.len());
            for (q, f) in old {
                let subdividable = self.can_subdivide(p) || self.can_subdivide(q);
                if subdividable && self.oracle(p, q) {
                    changed = true;
                    self.refine(p, q);
                } else {
                    keep.push((q, f));
                }
            }
            self.links[p as usize].extend(keep);
        }
        changed
    }

    pub(crate) fn push_pull(&mut self, node: u32, down: Vec3) -> Vec3 {
        let i = node as usize;
        let d = down + self.g[i];
        let b = match self.children[i] {
            None => {
                self.incident[i] = d;
                let b = self.e[i] + self.el[i].rho * d;
                self.bmax[i] = b;
                b
            }
            Some(kids) => {
                let (mut sum, mut mx) = (Vec3::ZERO, Vec3::ZERO);
                for k in kids {
                    sum += self.push_pull(k, d) * self.el[k as usize].area;
                    mx = mx.max(self.bmax[k as usize]);
                }
                self.bmax[i] = mx;
                sum / self.el[i].area.max(f32::MIN_POSITIVE)
            }
        };
        self.b[i] = b;
        b
    }

    pub(crate) fn leaf_power_change(&self, old: &[Vec3]) -> f32 {
        (0..self.el.len())
            .filter(|&i| self.children[i].is_none())
            .map(|i| self.el[i].area * (self.b[i] - old[i]).abs().element_sum())
            .sum()
    }

    fn iterate(
        &mut self,
        tol: f32,
        max_iter: u32,
        p0: f32,
        stats: &mut HrStats,
        progress: &dyn Progress,
    ) -> Result<(), CoreError> {
        let mut stopper = Stopper::new(tol, max_iter, STALL_WINDOW);
        for done in 1.. {
            if progress.cancelled() {
                return Err(CoreError::Cancelled);
            }
            let old = self.b.clone();
            let b = &self.b;
            self.g = self
                .links
                .par_iter()
                .map(|ls| ls.iter().map(|&(q, f)| b[q as usize] * f).sum())
                .collect();
            for r in 0..self.roots.len() {
                let root = self.roots[r];
                self.push_pull(root, Vec3::ZERO);
            }
            stats.iterations += 1;
            stats.unshot = self.leaf_power_change(&old) / p0;
            progress.message(&format!(
                "hierarchical: iteration {}, residual {:.3e}, {} links",
                stats.iterations,
                stats.unshot,
                self.links.iter().map(Vec::len).sum::<usize>()
            ));
            if let Some(stop) = stopper.check(stats.unshot, done) {
                stats.stop = stop;
                break;
            }
        }
        Ok(())
    }

    /// The deepest node of the tree of `source` containing point `x`.
    pub(crate) fn locate(&self, source: u32, x: Vec3) -> u32 {
        let mut node = self.roots[source as usize];
        while let Some(kids) = self.children[node as usize] {
            let (u, v) = barycentric(&self.el[node as usize].p, x);
            let w = 1.0 - u - v;
            node = if w >= 0.5 {
                kids[0]
            } else if u >= 0.5 {
                kids[1]
            } else if v >= 0.5 {
                kids[2]
            } else {
                kids[3]
            };
        }
        node
    }
}

/// Link refinements after the first linking: the progress counts the solve
/// after the first linking and after each of them.
pub(crate) const REFINEMENTS: u64 = 6;

/// Solves by hierarchical radiosity and returns the radiance of every
/// element of `mesh` (whose subdivisions must be powers of two) and the
/// statistics. `e_elem` is each element's emitted plus direct radiance
/// (point lights and `env`, the environment's part, empty without a map):
/// an element smaller than its leaf gets `E_elem + rho * incident(leaf)`.
/// Above `cluster_above` source triangles the links start from a cluster
/// hierarchy (`cluster.rs`), else from every pair of source triangles.
pub(crate) fn solve(
    ps: &PreparedScene<'_>,
    mesh: &ElementMesh,
    e_elem: &[Vec3],
    env: &[Vec3],
    vis: Option<&Visibility<'_>>,
    rule: PairRule,
    tol_geom: f32,
    tolerance: f32,
    max_iter: u32,
    cluster_above: usize,
    progress: &dyn Progress,
) -> Result<(Vec<Vec3>, HrStats), CoreError> {
    progress.begin("radiosity hierarchical", REFINEMENTS + 1);
    let mut t = Tree::forest(ps, mesh, env, vis, rule, tol_geom);
    let p0: f32 = e_elem
        .iter()
        .zip(&mesh.elements)
        .map(|(e, el)| el.area * e.abs().element_sum())
        .sum();
    let mut stats = HrStats::default();
    if p0 <= 0.0 {
        return Ok((e_elem.to_vec(), stats));
    }
    let max_e = t.e.iter().map(|e| e.max_element()).fold(0.0f32, f32::max);
    // BF threshold: 0.01 * tolerance * the brightest emitted radiance.
    // Coarse links between large elements underestimate the transport (the
    // receiver's sub-point average of a form factor that is convex towards
    // a shared edge falls short of its integral), so too loose a threshold
    // darkens the walls lit only indirectly; 0.01 keeps the Cornell box's
    // walls as close to the path tracer as the full-matrix solution
    // (BENCHMARKS.md, "Radiosity").
    t.eps = (0.01 * tolerance * max_e).max(f32::MIN_POSITIVE);
    // Above `cluster_above` source triangles, links start from a cluster
    // hierarchy over them instead of from every pair (quadratic).
    let clusters = if t.roots.len() > cluster_above.max(1) {
        let (links, clusters) =
            crate::cluster::solve(&mut t, tolerance, max_iter, p0, &mut stats, progress)?;
        stats.links = links;
        clusters
    } else {
        link_pairwise(&mut t, tolerance, max_iter, p0, &mut stats, progress)?;
        stats.links = t.links.iter().map(Vec::len).sum();
        0
    };
    // Clusters count as nodes; leaves are the quadtrees'.
    stats.nodes = t.el.len() + clusters;
    stats.leaves = t.children.iter().filter(|c| c.is_none()).count();
    let l = mesh
        .elements
        .iter()
        .zip(e_elem)
        .map(|(el, e)| {
            let leaf = t.locate(el.source, el.c) as usize;
            *e + el.rho * t.incident[leaf]
        })
        .collect();
    Ok((l, stats))
}

/// The first links of every pair of quadtree roots, refined with the BF
/// oracle, then solved and re-refined up to [`REFINEMENTS`] times.
fn link_pairwise(
    t: &mut Tree<'_, '_>,
    tolerance: f32,
    max_iter: u32,
    p0: f32,
    stats: &mut HrStats,
    progress: &dyn Progress,
) -> Result<(), CoreError> {
    let roots = t.roots.clone();
    // Every pair of roots is linked first (quadratic in the source
    // triangles): say so, and poll for cancellation between receivers.
    progress.message(&format!(
        "hierarchical: linking {} source triangles pairwise",
        roots.len()
    ));
    for &p in &roots {
        if progress.cancelled() {
            return Err(CoreError::Cancelled);
        }
        for &q in &roots {
            if p != q {
                t.refine(p, q);
            }
        }
    }
    t.evaluate_links();
    t.iterate(tolerance, max_iter, p0, stats, progress)?;
    progress.advance(1);
    let mut rounds = 1;
    for _ in 0..REFINEMENTS {
        if !t.refine_existing() {
            break;
        }
        t.evaluate_links();
        t.iterate(tolerance, max_iter, p0, stats, progress)?;
        progress.advance(1);
        rounds += 1;
    }
    progress.advance(REFINEMENTS + 1 - rounds);
    Ok(())
}
