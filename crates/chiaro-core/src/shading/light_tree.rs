//! The light hierarchy: lights chosen in proportion to an estimate of what
//! each gives a shading point (power, distance and orientation), by a walk
//! down a binary tree of light bounds (Conty Estevez and Kulla 2018,
//! "Importance sampling of many lights with adaptive tree splitting";
//! pbrt-v4's `BVHLightSampler`, `LightBounds` and `DirectionCone`,
//! section 12.6.3). The one hierarchy every technique that chooses lights
//! uses: the path tracer through [`LightSampler`], Whitted and the scan
//! converter through the emitter group ([`super::EmitterGroup`]).
//!
//! The choice is unbiased: a light is given zero probability only where
//! its bounds prove it sends nothing to the point, and [`LightTree::pmf`]
//! is the probability [`LightTree::sample`] picks with, bit for bit.

use super::light_set::{LightPowerTable, light_power};
use crate::geometry::Aabb;
use crate::scene::{AreaShape, Light, LightSelection};
use glam::Vec3;
use std::f32::consts::PI;

/// Lights above which [`LightSelection::Auto`] builds a hierarchy: below,
/// choosing by power alone costs less than the walk saves.
pub const AUTO_TREE_LIGHTS: usize = 64;

/// Depth past which the build splits at the middle whatever the cost
/// (bounds the walk's depth: at most this plus `log2` of the light count).
const SAH_DEPTH: u32 = 64;

/// The deepest tree [`LightTree::pmf`] can walk (`SAH_DEPTH` + 32 + 1).
const MAX_DEPTH: usize = 128;

/// Buckets per axis of the build's cost evaluation (pbrt-v4's 12).
const BUCKETS: usize = 12;

/// What a light or a group of lights can send: where it is, its power, and
/// the cone of its emitting normals (`w`, half-angle `acos(cos_theta_o)`)
/// widened by the spread of each normal's emission (`acos(cos_theta_e)`,
/// a quarter turn for a Lambertian emitter).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LightBounds {
    pub bounds: Aabb,
    /// Power (luminance, [`light_power`]); zero: never chosen.
    pub phi: f32,
    /// Unit axis of the normals' cone.
    pub w: Vec3,
    pub cos_theta_o: f32,
    pub cos_theta_e: f32,
    /// Emits on both sides of its normals.
    pub two_sided: bool,
}

impl LightBounds {
    /// The bounds of `light` (power by [`light_power`] with `scene_radius`);
    /// `None` for lights without a position (ambient, directional).
    /// Spot lights are bounded as point lights (every direction).
    pub fn of_light(light: &Light, scene_radius: f32) -> Option<Self> {
        let phi = light_power(light, scene_radius);
        let all_round = |p: Vec3| Self {
            bounds: Aabb { min: p, max: p },
            phi,
            w: Vec3::Y,
            cos_theta_o: -1.0,
            cos_theta_e: 0.0,
            two_sided: false,
        };
        match light {
            Light::Ambient { .. } | Light::Directional { .. } => None,
            Light::Point { position, .. } => Some(all_round(*position)),
            Light::Spot(s) => Some(all_round(s.position)),
            Light::Area {
                shape, two_sided, ..
            } => {
                let facing = |points: &[Vec3], n: Vec3| Self {
                    bounds: Aabb::from_points(points.iter().copied()),
                    phi,
                    w: n.normalize_or(Vec3::Y),
                    cos_theta_o: 1.0,
                    cos_theta_e: 0.0,
                    two_sided: *two_sided,
                };
                Some(match *shape {
                    AreaShape::Triangle { a, b, c } => facing(&[a, b, c], (b - a).cross(c - a)),
                    AreaShape::Quad {
                        corner,
                        edge_u,
                        edge_v,
                    } => facing(
                        &[
                            corner,
                            corner + edge_u,
                            corner + edge_v,
                            corner + edge_u + edge_v,
                        ],
                        edge_u.cross(edge_v),
                    ),
                    AreaShape::Disk {
                        center,
                        normal,
                        radius,
                    } => facing(
                        &[center - Vec3::splat(radius), center + Vec3::splat(radius)],
                        normal,
                    ),
                    AreaShape::Sphere { center, radius } => Self {
                        bounds: Aabb {
                            min: center - Vec3::splat(radius),
                            max: center + Vec3::splat(radius),
                        },
                        ..all_round(center)
                    },
                })
            }
        }
    }

    /// The bounds of both (pbrt-v4's `Union`): the box around both boxes,
    /// the sum of the powers, the cone around both cones.
    pub fn union(&self, o: &Self) -> Self {
        if self.phi <= 0.0 {
            return *o;
        }
        if o.phi <= 0.0 {
            return *self;
        }
        let (w, cos_theta_o) = cone_union((self.w, self.cos_theta_o), (o.w, o.cos_theta_o));
        Self {
            bounds: self.bounds.union(o.bounds),
            phi: self.phi + o.phi,
            w,
            cos_theta_o,
            cos_theta_e: self.cos_theta_e.min(o.cos_theta_e),
            two_sided: self.two_sided || o.two_sided,
        }
    }

    /// How much these lights may give the point `p` of unit normal `n`
    /// (`Vec3::ZERO`: no surface): power over squared distance times the
    /// largest emission cosine towards `p` and the largest incidence
    /// cosine at `p` that the bounds allow (pbrt-v4's
    /// `LightBounds::Importance`). Zero only where no light inside can
    /// reach `p`; never negative.
    #[inline]
    pub fn importance(&self, p: Vec3, n: Vec3) -> f32 {
        let (min, max) = (self.bounds.min, self.bounds.max);
        let pc = (min + max) * 0.5;
        let r2 = (max - min).length_squared() * 0.25;
        // The squared distance, clamped to the bounding sphere's radius
        // (a point inside the bounds is not infinitely important).
        let d2 = (p - pc).length_squared().max(r2);
        // cos(a - b) and sin(a - b) of angles clamped at zero.
        let cos_sub = |sin_a: f32, cos_a: f32, sin_b: f32, cos_b: f32| {
            if cos_a > cos_b {
                1.0
            } else {
                cos_a * cos_b + sin_a * sin_b
            }
        };
        let sin_sub = |sin_a: f32, cos_a: f32, sin_b: f32, cos_b: f32| {
            if cos_a > cos_b {
                0.0
            } else {
                sin_a * cos_b - cos_a * sin_b
            }
        };
        let wi = (p - pc).normalize_or_zero();
        let mut cos_w = self.w.dot(wi);
        if self.two_sided {
            cos_w = cos_w.abs();
        }
        let sin_w = safe_sqrt(1.0 - cos_w * cos_w);
        // The half-angle of the bounding sphere seen from p (everything
        // when p is inside it).
        let dc2 = (p - pc).length_squared();
        let cos_b = if dc2 < r2 {
            -1.0
        } else {
            safe_sqrt(1.0 - r2 / dc2)
        };
        let sin_b = safe_sqrt(1.0 - cos_b * cos_b);
        // The smallest angle between an emitting normal and p's direction.
        let sin_o = safe_sqrt(1.0 - self.cos_theta_o * self.cos_theta_o);
        let cos_x = cos_sub(sin_w, cos_w, sin_o, self.cos_theta_o);
        let sin_x = sin_sub(sin_w, cos_w, sin_o, self.cos_theta_o);
        let cos_p = cos_sub(sin_x, cos_x, sin_b, cos_b);
        if cos_p <= self.cos_theta_e {
            return 0.0;
        }
        let mut importance = self.phi * cos_p / d2;
        if n != Vec3::ZERO {
            // The largest incidence cosine over the bounds' directions.
            let cos_i = wi.dot(n).abs();
            let sin_i = safe_sqrt(1.0 - cos_i * cos_i);
            importance *= cos_sub(sin_i, cos_i, sin_b, cos_b);
        }
        if importance.is_finite() {
            importance.max(0.0)
        } else {
            0.0
        }
    }

    fn centroid(&self) -> Vec3 {
        (self.bounds.min + self.bounds.max) * 0.5
    }
}

#[inline]
fn safe_sqrt(x: f32) -> f32 {
    x.max(0.0).sqrt()
}

/// The smallest cone around cones `a` and `b`, each `(axis, cos half-angle)`
/// (pbrt-v4's `Union(DirectionCone, DirectionCone)`).
fn cone_union(a: (Vec3, f32), b: (Vec3, f32)) -> (Vec3, f32) {
    let theta_a = a.1.clamp(-1.0, 1.0).acos();
    let theta_b = b.1.clamp(-1.0, 1.0).acos();
    let theta_d = a.0.dot(b.0).clamp(-1.0, 1.0).acos();
    if (theta_d + theta_b).min(PI) <= theta_a {
        return a;
    }
    if (theta_d + theta_a).min(PI) <= theta_b {
        return b;
    }
    let theta_o = (theta_a + theta_d + theta_b) * 0.5;
    if theta_o >= PI {
        return (a.0, -1.0);
    }
    // Turn a's axis towards b's by theta_o - theta_a (Rodrigues' formula).
    let theta_r = theta_o - theta_a;
    let Some(k) = a.0.cross(b.0).try_normalize() else {
        return (a.0, -1.0);
    };
    let (s, c) = theta_r.sin_cos();
    let v = a.0;
    let w = v * c + k.cross(v) * s + k * k.dot(v) * (1.0 - c);
    (w.normalize_or(a.0), theta_o.cos())
}

/// The cost of a node of bounds `b` inside `parent` split along `axis`
/// (pbrt-v4's surface area orientation heuristic, `EvaluateCost`).
fn split_cost(b: &LightBounds, parent: &Aabb, axis: usize) -> f32 {
    let theta_o = b.cos_theta_o.clamp(-1.0, 1.0).acos();
    let theta_e = b.cos_theta_e.clamp(-1.0, 1.0).acos();
    let theta_w = (theta_o + theta_e).min(PI);
    let sin_o = safe_sqrt(1.0 - b.cos_theta_o * b.cos_theta_o);
    let m_omega = 2.0 * PI * (1.0 - b.cos_theta_o)
        + PI / 2.0
            * (2.0 * theta_w * sin_o - (theta_o - 2.0 * theta_w).cos() - 2.0 * theta_o * sin_o
                + b.cos_theta_o);
    let ext = parent.extent();
    let kr = if ext[axis] > 0.0 {
        ext.max_element() / ext[axis]
    } else {
        1.0
    };
    b.phi * m_omega * kr * b.bounds.surface_area()
}

/// Marks a node without children.
const LEAF: u32 = u32::MAX;

#[derive(Debug, Clone, Copy, PartialEq)]
struct Node {
    bounds: LightBounds,
    /// The first child, or the light (an index of the builder's list) of
    /// a leaf.
    first: u32,
    /// The second child; `LEAF` for a leaf.
    second: u32,
    /// The parent (`LEAF` at the root).
    parent: u32,
}

/// A binary tree over lights' bounds, one light per leaf; see the module.
#[derive(Debug, Clone, PartialEq)]
pub struct LightTree {
    nodes: Vec<Node>,
    /// The leaf of each light (`LEAF`: not in the tree, never chosen).
    leaf: Vec<u32>,
}

impl LightTree {
    /// The tree over `bounds` (light `i` of the caller has `bounds[i]`;
    /// `None` and zero power: never chosen); `None` when no light has power.
    pub fn new(bounds: &[Option<LightBounds>]) -> Option<Self> {
        let mut items: Vec<(u32, LightBounds)> = bounds
            .iter()
            .enumerate()
            .filter_map(|(i, b)| {
                b.filter(|b| b.phi > 0.0 && b.phi.is_finite())
                    .map(|b| (i as u32, b))
            })
            .collect();
        if items.is_empty() {
            return None;
        }
        let mut tree = Self {
            nodes: Vec::with_capacity(2 * items.len()),
            leaf: vec![LEAF; bounds.len()],
        };
        tree.build(&mut items, 0, LEAF);
        Some(tree)
    }

    /// Builds the subtree of `items` under `parent`; returns its node.
    fn build(&mut self, items: &mut [(u32, LightBounds)], depth: u32, parent: u32) -> u32 {
        let at = self.nodes.len() as u32;
        if let [(light, b)] = items {
            self.nodes.push(Node {
                bounds: *b,
                first: *light,
                second: LEAF,
                parent,
            });
            self.leaf[*light as usize] = at;
            return at;
        }
        let all = items[1..]
            .iter()
            .fold(items[0].1, |acc, (_, b)| acc.union(b));
        self.nodes.push(Node {
            bounds: all,
            first: LEAF,
            second: LEAF,
            parent,
        });
        let mid = if depth < SAH_DEPTH {
            Self::cheapest_split(items, &all.bounds)
        } else {
            None
        }
        .unwrap_or(items.len() / 2);
        let (left, right) = items.split_at_mut(mid);
        let a = self.build(left, depth + 1, at);
        let b = self.build(right, depth + 1, at);
        let node = &mut self.nodes[at as usize];
        node.first = a;
        node.second = b;
        at
    }

    /// Partitions `items` at the bucket boundary of least cost over the
    /// three axes (centroids in [`BUCKETS`] buckets); returns the split
    /// index, `None` when no axis separates them.
    fn cheapest_split(items: &mut [(u32, LightBounds)], bounds: &Aabb) -> Option<usize> {
        let cb = Aabb::from_points(items.iter().map(|(_, b)| b.centroid()));
        let bucket = |c: Vec3, axis: usize| {
            let (lo, hi) = (cb.min[axis], cb.max[axis]);
            let t = (c[axis] - lo) / (hi - lo);
            ((t * BUCKETS as f32) as usize).min(BUCKETS - 1)
        };
        let mut best: Option<(f32, usize, usize)> = None;
        for axis in 0..3 {
            if cb.max[axis] <= cb.min[axis] {
                continue;
            }
            let mut buckets: [Option<LightBounds>; BUCKETS] = [None; BUCKETS];
            for (_, b) in items.iter() {
                let k = bucket(b.centroid(), axis);
                buckets[k] = Some(buckets[k].map_or(*b, |x| x.union(b)));
            }
            let join = |bs: &[Option<LightBounds>]| {
                bs.iter()
                    .flatten()
                    .fold(None, |acc: Option<LightBounds>, b| {
                        Some(acc.map_or(*b, |a| a.union(b)))
                    })
            };
            for split in 0..BUCKETS - 1 {
                let (Some(b0), Some(b1)) = (join(&buckets[..=split]), join(&buckets[split + 1..]))
                else {
                    continue;
                };
                let cost = split_cost(&b0, bounds, axis) + split_cost(&b1, bounds, axis);
                if cost.is_finite() && best.is_none_or(|(c, _, _)| cost < c) {
                    best = Some((cost, axis, split));
                }
            }
        }
        let (_, axis, split) = best?;
        // Stable partition: the lights of buckets up to `split` first.
        let (mut low, high): (Vec<_>, Vec<_>) = items
            .iter()
            .partition(|(_, b)| bucket(b.centroid(), axis) <= split);
        let mid = low.len();
        low.extend(high);
        items.copy_from_slice(&low);
        (mid > 0 && mid < items.len()).then_some(mid)
    }

    /// The probability of taking the first child of interior node `node`
    /// at `(p, n)`: in proportion to the children's importance, or to
    /// their power where neither can light the point (the walk then still
    /// ends at a light, so the probabilities always sum to one; such a
    /// light contributes nothing and costs no shadow ray).
    #[inline]
    fn first_probability(&self, node: &Node, p: Vec3, n: Vec3) -> f32 {
        let (a, b) = (
            &self.nodes[node.first as usize].bounds,
            &self.nodes[node.second as usize].bounds,
        );
        let (i0, i1) = (a.importance(p, n), b.importance(p, n));
        if i0 + i1 > 0.0 {
            i0 / (i0 + i1)
        } else {
            a.phi / (a.phi + b.phi)
        }
    }

    /// Chooses a light for the point `p` of unit normal `n` (`Vec3::ZERO`
    /// without a surface) with the uniform number `u` in `[0, 1)`: its
    /// index in the builder's list, the probability it was chosen with
    /// (the same as [`Self::pmf`]'s), and a uniform number in `[0, 1)` left
    /// of `u` (coarser the deeper the leaf).
    #[inline]
    pub fn sample(&self, p: Vec3, n: Vec3, u: f32) -> (usize, f32, f32) {
        let below_one = 1.0 - f32::EPSILON / 2.0;
        let mut u = u.clamp(0.0, below_one);
        let mut pmf = 1.0f32;
        let mut node = &self.nodes[0];
        loop {
            if node.second == LEAF {
                return (node.first as usize, pmf, u);
            }
            let p0 = self.first_probability(node, p, n);
            if u < p0 {
                u = (u / p0).min(below_one);
                pmf *= p0;
                node = &self.nodes[node.first as usize];
            } else {
                let p1 = 1.0 - p0;
                u = ((u - p0) / p1).clamp(0.0, below_one);
                pmf *= p1;
                node = &self.nodes[node.second as usize];
            }
        }
    }

    /// The probability that [`Self::sample`] chooses light `light` at
    /// `(p, n)` (zero for a light not in the tree), computed with the same
    /// operations in the same order.
    pub fn pmf(&self, p: Vec3, n: Vec3, light: usize) -> f32 {
        let Some(&leaf) = self.leaf.get(light) else {
            return 0.0;
        };
        if leaf == LEAF {
            return 0.0;
        }
        // The path from the root, gathered leaf-up.
        let mut path = [0u32; MAX_DEPTH];
        let mut len = 0;
        let mut at = leaf;
        while at != LEAF && len < MAX_DEPTH {
            path[len] = at;
            len += 1;
            at = self.nodes[at as usize].parent;
        }
        let mut pmf = 1.0f32;
        for k in (1..len).rev() {
            let node = &self.nodes[path[k] as usize];
            let p0 = self.first_probability(node, p, n);
            pmf *= if node.first == path[k - 1] {
                p0
            } else {
                1.0 - p0
            };
        }
        pmf
    }

    /// The bounds of all the lights.
    pub fn root(&self) -> &LightBounds {
        &self.nodes[0].bounds
    }
}

/// How the path tracer chooses the light of a next-event estimate: by
/// power alone (one table), or by the hierarchy with the lights that have
/// no position (directional lights, the environment) chosen by power
/// beside it (the tree counts as one entry of its total power).
#[derive(Debug, Clone, PartialEq)]
pub enum LightSampler {
    Power(LightPowerTable),
    Tree {
        /// Each light without a position, then the tree, by power.
        top: LightPowerTable,
        /// The light of each top entry but the last (the tree's).
        top_light: Vec<u32>,
        /// The top entry of each light (`u32::MAX`: in the tree).
        entry: Vec<u32>,
        tree: LightTree,
    },
}

impl LightSampler {
    /// The sampler of `lights` (none ambient) followed (as light
    /// `lights.len()`) by an environment map of mean luminance `env` when
    /// there is one; powers by [`light_power`] and
    /// [`super::environment_power`] with `scene_radius`. `selection` picks
    /// power or the hierarchy (`Auto`: the hierarchy over more than
    /// [`AUTO_TREE_LIGHTS`] lights with a position). One call: the result
    /// depends on nothing else, so a caller may keep it between frames.
    pub fn new(
        lights: &[&Light],
        scene_radius: f32,
        env: Option<f32>,
        selection: LightSelection,
    ) -> Self {
        let power = || LightPowerTable::of_lights(lights, scene_radius, env);
        let bounds: Vec<Option<LightBounds>> = lights
            .iter()
            .map(|l| LightBounds::of_light(l, scene_radius))
            .collect();
        let placed = bounds.iter().filter(|b| b.is_some()).count();
        let use_tree = match selection {
            LightSelection::Power => false,
            LightSelection::Tree => true,
            LightSelection::Auto => placed > AUTO_TREE_LIGHTS,
        };
        let tree = use_tree.then(|| LightTree::new(&bounds)).flatten();
        let Some(tree) = tree else {
            return Self::Power(power());
        };
        let mut top_light = Vec::new();
        let mut powers = Vec::new();
        let n = lights.len() + usize::from(env.is_some());
        let mut entry = vec![u32::MAX; n];
        for (i, l) in lights.iter().enumerate() {
            if bounds[i].is_none() {
                entry[i] = top_light.len() as u32;
                top_light.push(i as u32);
                powers.push(light_power(l, scene_radius));
            }
        }
        if let Some(mean) = env {
            entry[lights.len()] = top_light.len() as u32;
            top_light.push(lights.len() as u32);
            powers.push(super::environment_power(scene_radius, mean));
        }
        powers.push(tree.root().phi);
        Self::Tree {
            top: LightPowerTable::new(&powers),
            top_light,
            entry,
            tree,
        }
    }

    /// Chooses a light for the point `p` of normal `n` with the uniform
    /// number `u`: its index and the probability it was chosen with (the
    /// same as [`Self::pmf`]'s). `None` without lights.
    #[inline]
    pub fn sample(&self, p: Vec3, n: Vec3, u: f32) -> Option<(usize, f32)> {
        match self {
            Self::Power(t) => t.pick(u).map(|i| (i, t.pmf(i))),
            Self::Tree {
                top,
                top_light,
                tree,
                ..
            } => {
                let k = top.pick(u)?;
                let pk = top.pmf(k);
                if let Some(&li) = top_light.get(k) {
                    return Some((li as usize, pk));
                }
                // The tree: u rescaled into its entry.
                let start = if k == 0 { 0.0 } else { top.cdf()[k - 1] };
                let v = if pk > 0.0 { (u - start) / pk } else { 0.0 };
                let (li, pl, _) = tree.sample(p, n, v);
                Some((li, pk * pl))
            }
        }
    }

    /// The probability that [`Self::sample`] chooses light `i` at `(p, n)`.
    #[inline]
    pub fn pmf(&self, p: Vec3, n: Vec3, i: usize) -> f32 {
        match self {
            Self::Power(t) => t.pmf(i),
            Self::Tree {
                top, entry, tree, ..
            } => match entry.get(i) {
                None => 0.0,
                Some(&k) if k != u32::MAX => top.pmf(k as usize),
                Some(_) => top.pmf(top.len() - 1) * tree.pmf(p, n, i),
            },
        }
    }

    /// The number of lights chosen from (the environment included).
    pub fn len(&self) -> usize {
        match self {
            Self::Power(t) => t.len(),
            Self::Tree { entry, .. } => entry.len(),
        }
    }

    /// True without lights.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The power table when lights are chosen by power alone.
    pub fn power_table(&self) -> Option<&LightPowerTable> {
        match self {
            Self::Power(t) => Some(t),
            Self::Tree { .. } => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Attenuation;

    /// xorshift64* numbers in `[0, 1)`.
    fn rng(state: &mut u64) -> f32 {
        *state ^= *state >> 12;
        *state ^= *state << 25;
        *state ^= *state >> 27;
        ((state.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 40) as f32) / (1u64 << 24) as f32
    }

    fn in_box(state: &mut u64, half: f32) -> Vec3 {
        Vec3::new(
            (2.0 * rng(state) - 1.0) * half,
            (2.0 * rng(state) - 1.0) * half,
            (2.0 * rng(state) - 1.0) * half,
        )
    }

    fn unit(state: &mut u64) -> Vec3 {
        loop {
            let v = in_box(state, 1.0);
            if let Some(u) = v.try_normalize() {
                return u;
            }
        }
    }

    /// Small triangles of random orientation, size and power (some
    /// two-sided, some dark), point lights, a spot and a sphere: `n` in all.
    fn many_lights(n: usize, seed: u64) -> Vec<Light> {
        let mut s = seed;
        (0..n)
            .map(|k| {
                let c = in_box(&mut s, 2.0);
                let color = Vec3::new(rng(&mut s), rng(&mut s), rng(&mut s)) * 3.0;
                match k % 23 {
                    5 => Light::Point {
                        position: c,
                        color,
                        intensity: 1.0,
                        attenuation: Attenuation::InverseSquare,
                    },
                    11 => Light::Area {
                        shape: AreaShape::Sphere {
                            center: c,
                            radius: 0.05,
                        },
                        color,
                        intensity: 1.0,
                        two_sided: false,
                    },
                    17 => Light::Area {
                        shape: AreaShape::Triangle {
                            a: c,
                            b: c + Vec3::X * 0.1,
                            c: c + Vec3::Z * 0.1,
                        },
                        color: Vec3::ZERO,
                        intensity: 1.0,
                        two_sided: false,
                    },
                    _ => {
                        let size = 0.02 + 0.2 * rng(&mut s);
                        Light::Area {
                            shape: AreaShape::Triangle {
                                a: c,
                                b: c + unit(&mut s) * size,
                                c: c + unit(&mut s) * size,
                            },
                            color,
                            intensity: 1.0,
                            two_sided: k % 3 == 0,
                        }
                    }
                }
            })
            .collect()
    }

    fn tree_of(lights: &[Light]) -> LightTree {
        let bounds: Vec<Option<LightBounds>> = lights
            .iter()
            .map(|l| LightBounds::of_light(l, 4.0))
            .collect();
        LightTree::new(&bounds).expect("lights with power")
    }

    /// True when some point of the one-sided triangle's front can face `p`
    /// (what a zero probability must rule out).
    fn may_light(light: &Light, p: Vec3) -> bool {
        match light {
            Light::Area { color, .. } if *color == Vec3::ZERO => false,
            Light::Area {
                shape: AreaShape::Triangle { a, b, c },
                two_sided: false,
                ..
            } => {
                let n = (*b - *a).cross(*c - *a).normalize();
                n.dot(p - *a) > 1e-4
            }
            _ => true,
        }
    }

    #[test]
    fn probabilities_sum_to_one_and_match_the_walk() {
        let lights = many_lights(300, 7);
        let tree = tree_of(&lights);
        let mut s = 99u64;
        let mut full = 0;
        for _ in 0..200 {
            let p = in_box(&mut s, 3.0);
            let n = unit(&mut s);
            let pmf: Vec<f32> = (0..lights.len()).map(|i| tree.pmf(p, n, i)).collect();
            let sum: f64 = pmf.iter().map(|&x| f64::from(x)).sum();
            assert!(sum <= 1.0 + 1e-5, "{p} {n}: {sum}");
            // A zero probability only where the light cannot reach p.
            for (i, l) in lights.iter().enumerate() {
                if pmf[i] == 0.0 && sum > 0.0 {
                    assert!(!may_light(l, p), "{p}: light {i} ({l:?}) skipped");
                }
            }
            full += usize::from((sum - 1.0).abs() < 1e-5);
            // The walk's probability is pmf's, bit for bit.
            for k in 0..64 {
                let u = (k as f32 + rng(&mut s)) / 64.0;
                let (i, pk, rest) = tree.sample(p, n, u);
                assert_eq!(pk.to_bits(), pmf[i].to_bits(), "light {i}");
                assert!((0.0..1.0).contains(&rest));
            }
        }
        assert_eq!(full, 200);
        // A light not in the tree (no power, or out of range): never.
        assert_eq!(tree.pmf(Vec3::ZERO, Vec3::Y, 17), 0.0);
        assert_eq!(tree.pmf(Vec3::ZERO, Vec3::Y, 300), 0.0);
    }

    #[test]
    fn choices_follow_the_probabilities() {
        // Chi-square of 200,000 choices at a few points against pmf, over
        // the lights expected at least 20 times (the rest pooled).
        let lights = many_lights(120, 3);
        let tree = tree_of(&lights);
        let mut s = 5u64;
        for _ in 0..4 {
            let p = in_box(&mut s, 2.5);
            let n = unit(&mut s);
            let draws = 200_000u32;
            let mut counts = vec![0u32; lights.len()];
            for _ in 0..draws {
                counts[tree.sample(p, n, rng(&mut s)).0] += 1;
            }
            let (mut chi2, mut dof) = (0.0f64, 0usize);
            let (mut pooled_e, mut pooled_o) = (0.0f64, 0.0f64);
            for (i, &c) in counts.iter().enumerate() {
                let e = f64::from(tree.pmf(p, n, i)) * f64::from(draws);
                if e == 0.0 {
                    assert_eq!(c, 0, "light {i} chosen with probability 0");
                } else if e >= 20.0 {
                    chi2 += (f64::from(c) - e).powi(2) / e;
                    dof += 1;
                } else {
                    pooled_e += e;
                    pooled_o += f64::from(c);
                }
            }
            if pooled_e > 0.0 {
                chi2 += (pooled_o - pooled_e).powi(2) / pooled_e;
                dof += 1;
            }
            // The 1e-4 upper tail of chi-square (Wilson-Hilferty).
            let k = (dof.max(2) - 1) as f64;
            let z = 3.72;
            let limit = k * (1.0 - 2.0 / (9.0 * k) + z * (2.0 / (9.0 * k)).sqrt()).powi(3);
            assert!(
                dof > 10 && chi2 < limit,
                "{p}: chi2 {chi2} over {dof} cells"
            );
        }
    }

    #[test]
    fn closer_and_facing_lights_are_more_likely() {
        // Two equal downward triangles: the one above the point and facing
        // it is chosen far more often than the distant one, and one facing
        // away never.
        let tri = |x: f32, facing_down: bool| {
            let (b, c) = (Vec3::new(x + 0.1, 1.0, 0.0), Vec3::new(x, 1.0, 0.1));
            let a = Vec3::new(x, 1.0, 0.0);
            let shape = if facing_down {
                AreaShape::Triangle { a, b, c }
            } else {
                AreaShape::Triangle { a, b: c, c: b }
            };
            Light::Area {
                shape,
                color: Vec3::ONE,
                intensity: 1.0,
                two_sided: false,
            }
        };
        let lights = [tri(0.0, true), tri(5.0, true), tri(0.2, false)];
        let tree = tree_of(&lights);
        let (p, n) = (Vec3::ZERO, Vec3::Y);
        assert!(tree.pmf(p, n, 0) > 10.0 * tree.pmf(p, n, 1));
        assert_eq!(tree.pmf(p, n, 2), 0.0);
        let sum: f32 = (0..3).map(|i| tree.pmf(p, n, i)).sum();
        assert!((sum - 1.0).abs() < 1e-6);
    }

    #[test]
    fn the_sampler_keeps_power_sampling_and_adds_the_tree() {
        let lights = many_lights(100, 11);
        let sun = Light::Directional {
            direction: Vec3::NEG_Y,
            color: Vec3::ONE,
            intensity: 1.0,
        };
        let mut refs: Vec<&Light> = lights.iter().collect();
        refs.push(&sun);
        let power = LightSampler::new(&refs, 4.0, Some(0.5), LightSelection::Power);
        let table = LightPowerTable::of_lights(&refs, 4.0, Some(0.5));
        assert_eq!(power.power_table(), Some(&table));
        let tree = LightSampler::new(&refs, 4.0, Some(0.5), LightSelection::Auto);
        assert!(tree.power_table().is_none(), "100 lights: the hierarchy");
        assert_eq!(tree.len(), 102);
        let mut s = 1u64;
        for _ in 0..50 {
            let (p, n) = (in_box(&mut s, 3.0), unit(&mut s));
            let sum: f64 = (0..tree.len()).map(|i| f64::from(tree.pmf(p, n, i))).sum();
            assert!((sum - 1.0).abs() < 1e-5, "{sum}");
            // The sun and the environment keep their power share (up to
            // the order the powers are summed in).
            for i in [100, 101] {
                assert!((tree.pmf(p, n, i) - table.pmf(i)).abs() < 1e-6 * table.pmf(i));
            }
            for k in 0..32 {
                let u = (k as f32 + 0.5) / 32.0;
                let (i, pk) = tree.sample(p, n, u).expect("lights");
                assert_eq!(pk.to_bits(), tree.pmf(p, n, i).to_bits());
            }
        }
        let few = LightSampler::new(&refs[..10], 4.0, None, LightSelection::Auto);
        assert!(few.power_table().is_some(), "10 lights: power");
    }
}
