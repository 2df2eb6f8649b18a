//! The source triangle of an object nearest to a point, for the look-ups by
//! position ([`crate::RadiositySolution::radiance_at`] and the hybrid's
//! indirect irradiance at every ray hit): one bounding-volume tree per
//! object, searched with a lower bound of the distance measure, so a
//! look-up costs about log(triangles) instead of a scan of every triangle.

use crate::mesh::barycentric;
use glam::Vec3;

/// How far `p` is from triangle `c` in the look-up's measure: the
/// barycentric distance outside the triangle times its longest edge from
/// corner 0, plus the distance off its plane; with the clamped
/// barycentrics of `p`, and `None` when the triangle faces away from `n`
/// (`n` nonzero).
///
/// It is at least half the Euclidean distance from `p` to the triangle
/// (moving the barycentrics into the triangle changes them by at most
/// twice the outside part in the L1 norm), which is what lets the tree
/// prune by bounding boxes.
pub(crate) fn measure(c: &[Vec3; 3], p: Vec3, n: Vec3) -> Option<(f32, f32, f32)> {
    let nt = (c[1] - c[0]).cross(c[2] - c[0]).normalize_or_zero();
    if n != Vec3::ZERO && nt.dot(n) < 0.0 {
        return None;
    }
    let (u, v) = barycentric(c, p);
    let out = (-u).max(0.0) + (-v).max(0.0) + (u + v - 1.0).max(0.0);
    let scale = (c[1] - c[0]).length().max((c[2] - c[0]).length());
    let d = out * scale + nt.dot(p - c[0]).abs();
    Some((d, u.clamp(0.0, 1.0), v.clamp(0.0, 1.0)))
}

/// A lower bound of [`measure`] for every triangle inside a box at
/// Euclidean distance `dist` from the point: half of it, less a margin
/// for rounding.
fn lower_bound(dist: f32) -> f32 {
    0.45 * dist
}

const LEAF: usize = 4;

#[derive(Debug, Clone, Copy)]
struct Node {
    lo: Vec3,
    hi: Vec3,
    /// Leaf: `first..first + count` of `order`; inner: children `first`
    /// and `first + 1` of `nodes` (`count == 0`).
    first: u32,
    count: u32,
}

/// One tree per object over the solution's source triangles.
#[derive(Debug, Default)]
pub(crate) struct NearestIndex {
    /// Root node of each object's tree (`u32::MAX`: no triangle).
    roots: Vec<u32>,
    nodes: Vec<Node>,
    /// Triangle ids, leaf by leaf.
    order: Vec<u32>,
}

impl NearestIndex {
    /// Builds the trees of `corners` (the first `count` source triangles),
    /// grouped by `object`.
    pub(crate) fn new(corners: &[[Vec3; 3]], object: &[u32], count: usize) -> Self {
        let count = count.min(corners.len()).min(object.len());
        let objects = object[..count]
            .iter()
            .map(|&o| o as usize + 1)
            .max()
            .unwrap_or(0);
        let mut per_object: Vec<Vec<u32>> = vec![Vec::new(); objects];
        for t in 0..count {
            per_object[object[t] as usize].push(t as u32);
        }
        let mut index = Self {
            roots: vec![u32::MAX; objects],
            nodes: Vec::new(),
            order: Vec::with_capacity(count),
        };
        let centroid = |t: u32| {
            let c = corners[t as usize];
            (c[0] + c[1] + c[2]) / 3.0
        };
        for (o, mut tris) in per_object.into_iter().enumerate() {
            if tris.is_empty() {
                continue;
            }
            index.roots[o] = index.nodes.len() as u32;
            index.nodes.push(Node {
                lo: Vec3::ZERO,
                hi: Vec3::ZERO,
                first: 0,
                count: 0,
            });
            // (node, triangles) still to split, depth first.
            let root = index.roots[o] as usize;
            let mut todo = vec![(root, std::mem::take(&mut tris))];
            while let Some((ni, mut tris)) = todo.pop() {
                let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
                for &t in &tris {
                    for p in corners[t as usize] {
                        lo = lo.min(p);
                        hi = hi.max(p);
                    }
                }
                if tris.len() <= LEAF {
                    index.nodes[ni] = Node {
                        lo,
                        hi,
                        first: index.order.len() as u32,
                        count: tris.len() as u32,
                    };
                    index.order.extend_from_slice(&tris);
                    continue;
                }
                // Median split along the centroids' widest axis.
                let (mut clo, mut chi) =
                    (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
                for &t in &tris {
                    clo = clo.min(centroid(t));
                    chi = chi.max(centroid(t));
                }
                let ext = chi - clo;
                let axis = if ext.x >= ext.y && ext.x >= ext.z {
                    0
                } else if ext.y >= ext.z {
                    1
                } else {
                    2
                };
                let mid = tris.len() / 2;
                tris.select_nth_unstable_by(mid, |&a, &b| {
                    centroid(a)[axis]
                        .total_cmp(&centroid(b)[axis])
                        .then(a.cmp(&b))
                });
                let right = tris.split_off(mid);
                let first = index.nodes.len();
                let blank = index.nodes[ni];
                index.nodes.push(blank);
                index.nodes.push(blank);
                index.nodes[ni] = Node {
                    lo,
                    hi,
                    first: first as u32,
                    count: 0,
                };
                todo.push((first, tris));
                todo.push((first + 1, right));
            }
        }
        index
    }

    /// The triangle of `object` with the smallest [`measure`] to `p` (the
    /// lowest id among equals, as a scan in id order finds), with its
    /// clamped barycentrics.
    pub(crate) fn nearest(
        &self,
        corners: &[[Vec3; 3]],
        object: u32,
        p: Vec3,
        n: Vec3,
    ) -> Option<(usize, f32, f32)> {
        let root = *self.roots.get(object as usize)?;
        if root == u32::MAX {
            return None;
        }
        let mut best: Option<(f32, u32, f32, f32)> = None;
        let mut stack = vec![root];
        while let Some(ni) = stack.pop() {
            let node = self.nodes[ni as usize];
            let dist = (node.lo - p).max(p - node.hi).max(Vec3::ZERO).length();
            if best.is_some_and(|b| lower_bound(dist) > b.0) {
                continue;
            }
            if node.count == 0 {
                // Nearer child last, so it is searched first.
                let (a, b) = (node.first, node.first + 1);
                let da = self.box_distance(a, p);
                let db = self.box_distance(b, p);
                if da <= db {
                    stack.extend([b, a]);
                } else {
                    stack.extend([a, b]);
                }
                continue;
            }
            let leaf = &self.order[node.first as usize..(node.first + node.count) as usize];
            for &t in leaf {
                let Some((d, u, v)) = measure(&corners[t as usize], p, n) else {
                    continue;
                };
                let better = match best {
                    None => true,
                    Some(b) => d < b.0 || (d == b.0 && t < b.1),
                };
                if better {
                    best = Some((d, t, u, v));
                }
            }
        }
        best.map(|(_, t, u, v)| (t as usize, u, v))
    }

    fn box_distance(&self, ni: u32, p: Vec3) -> f32 {
        let n = self.nodes[ni as usize];
        (n.lo - p).max(p - n.hi).max(Vec3::ZERO).length()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The scan the index replaces: every triangle of the object in id order.
    fn scan(
        c: &[[Vec3; 3]],
        obj: &[u32],
        object: u32,
        p: Vec3,
        n: Vec3,
    ) -> Option<(usize, f32, f32)> {
        let mut best: Option<(f32, usize, f32, f32)> = None;
        for t in 0..c.len() {
            if obj[t] != object {
                continue;
            }
            if let Some((d, u, v)) = measure(&c[t], p, n)
                && best.is_none_or(|b| d < b.0)
            {
                best = Some((d, t, u, v));
            }
        }
        best.map(|(_, t, u, v)| (t, u, v))
    }

    #[test]
    fn index_finds_what_the_scan_finds() {
        // A small LCG: uniform in [-s/2, s/2).
        let mut state = 7u64;
        let mut r = |s: f32| {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            ((state >> 40) as f32 / (1u64 << 24) as f32 - 0.5) * s
        };
        // A grid of floor triangles (object 0, with shared edges and ties),
        // a random soup (object 1), an empty object 2, and object 3.
        let mut c = Vec::new();
        let mut obj = Vec::new();
        for i in 0..20 {
            for j in 0..20 {
                let (x, z) = (i as f32, j as f32);
                let a = Vec3::new(x, 0.0, z);
                c.push([a, a + Vec3::Z, a + Vec3::X]);
                c.push([a + Vec3::X, a + Vec3::Z, a + Vec3::new(1.0, 0.0, 1.0)]);
                obj.extend([0, 0]);
            }
        }
        for _ in 0..300 {
            let o = Vec3::new(r(20.0), r(20.0), r(20.0));
            c.push([
                o,
                o + Vec3::new(r(3.0), r(3.0), r(3.0)),
                o + Vec3::new(r(3.0), r(3.0), r(3.0)),
            ]);
            obj.push(1);
        }
        c.push([Vec3::ZERO, Vec3::X, Vec3::Y]);
        obj.push(3);
        let index = NearestIndex::new(&c, &obj, c.len());
        for k in 0..2000 {
            let object = [0, 1, 2, 3][k % 4];
            let p = if k % 8 == 0 {
                // Exactly on grid vertices and edges: ties.
                Vec3::new((k % 21) as f32, 0.0, ((k / 21) % 21) as f32 * 0.5)
            } else {
                Vec3::new(r(50.0) + 10.0, r(4.0), r(50.0) + 10.0)
            };
            let n = match k % 3 {
                0 => Vec3::ZERO,
                1 => Vec3::Y,
                _ => Vec3::new(r(2.0), r(2.0), r(2.0)).normalize_or_zero(),
            };
            assert_eq!(
                index.nearest(&c, object, p, n),
                scan(&c, &obj, object, p, n),
                "object {object}, p {p}, n {n}"
            );
        }
    }
}
