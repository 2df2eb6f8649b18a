//! [`RadiositySolution`]: the view-independent result of a radiosity solve
//! (per-element and per-vertex radiance on the display mesh), its look-ups
//! for display and for the hybrid technique, and its serialisation.

use crate::mesh::{barycentric, element_at};
use crate::nearest::NearestIndex;
use chiaro_core::error::CoreError;
use chiaro_core::scene::Scene;
use glam::Vec3;
use serde::{Deserialize, Serialize};
use std::io::{Read, Write};
use std::sync::OnceLock;

/// Format version written by [`RadiositySolution::save`].
pub const FORMAT_VERSION: u32 = 2;

/// How a solution was computed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
pub struct SolveStats {
    /// Solver name (`"progressive"`, ...).
    pub solver: String,
    /// Form-factor method (`"raycast"`, ...).
    pub formfactor: String,
    /// Patch size used for meshing, scene units.
    pub patch_size: f32,
    /// Number of display elements.
    pub elements: usize,
    /// Progressive refinement: shooting patches (groups of elements; equal
    /// to `elements` where no input triangle is finer than the patch size).
    #[serde(default)]
    pub patches: usize,
    /// Iterations (sweeps, shots, or hierarchical gathers).
    pub iterations: u32,
    /// Final unshot-energy (or residual) fraction.
    pub unshot: f32,
    /// Hierarchical radiosity: quadtree nodes (0 for other solvers).
    pub nodes: usize,
    /// Hierarchical radiosity: leaves of the quadtrees.
    pub leaves: usize,
    /// Hierarchical radiosity: links.
    pub links: usize,
    /// Wall-clock seconds of the solve (meshing, form factors, iterations).
    pub seconds: f64,
}

/// A radiosity solution: the display mesh (the elements of every surface
/// and area light) with the outgoing radiance of each element and each
/// vertex.
///
/// Units: *radiance* (W sr^-1 m^-2 in the scene's relative units), the
/// same quantity a path tracer returns for a Lambertian surface; radiosity
/// B (W/m^2) is `pi` times it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RadiositySolution {
    pub(crate) version: u32,
    pub(crate) fingerprint: u64,
    /// How it was computed.
    pub stats: SolveStats,
    pub(crate) vertices: Vec<Vec3>,
    pub(crate) vertex_radiance: Vec<Vec3>,
    pub(crate) vertex_indirect: Vec<Vec3>,
    pub(crate) vertex_irradiance: Vec<Vec3>,
    pub(crate) elements: Vec<[u32; 3]>,
    pub(crate) element_radiance: Vec<Vec3>,
    pub(crate) element_emission: Vec<Vec3>,
    pub(crate) source_corners: Vec<[Vec3; 3]>,
    pub(crate) source_object: Vec<u32>,
    pub(crate) source_k: Vec<u32>,
    pub(crate) source_first: Vec<u32>,
    /// Number of sources that are prepared-scene triangles (the rest are area lights).
    pub(crate) prepared_triangles: u32,
    /// The look-up tree of [`Self::find`], built on first use.
    #[serde(skip)]
    pub(crate) nearest: NearestCache,
}

/// [`NearestIndex`] built once, on the first look-up by position. Not part
/// of a solution's value: equal and cloned as empty.
#[derive(Debug, Default)]
pub(crate) struct NearestCache(OnceLock<NearestIndex>);

impl Clone for NearestCache {
    fn clone(&self) -> Self {
        Self::default()
    }
}

impl PartialEq for NearestCache {
    fn eq(&self, _: &Self) -> bool {
        true
    }
}

/// Smallest albedo an element's irradiance is recovered from; below it the
/// element reflects (almost) nothing and its irradiance is unknown.
pub(crate) const RHO_MIN: f32 = 1e-4;

/// The incident irradiance `pi L_r / rho` (W/m^2) of a Lambertian element
/// that reflects radiance `reflected` with albedo `rho`, per channel; 0 in a
/// channel where `rho <= RHO_MIN` (no division by zero).
pub(crate) fn irradiance_from(reflected: Vec3, rho: Vec3) -> Vec3 {
    let f = |r: f32, rho: f32| {
        if rho > RHO_MIN {
            std::f32::consts::PI * r / rho
        } else {
            0.0
        }
    };
    Vec3::new(
        f(reflected.x, rho.x),
        f(reflected.y, rho.y),
        f(reflected.z, rho.z),
    )
}

/// Gouraud weights of corners 0, 1, 2 from barycentrics `(a, b)` (weights of
/// corners 1 and 2), clamped into the triangle.
pub(crate) fn clamped_weights((a, b): (f32, f32)) -> [f32; 3] {
    let (a, b) = (a.clamp(0.0, 1.0), b.clamp(0.0, 1.0));
    let s = (a + b).max(1.0);
    let (a, b) = (a / s, b / s);
    [1.0 - a - b, a, b]
}

/// FNV-1a over bytes.
fn fnv1a(bytes: &[u8], mut h: u64) -> u64 {
    for &b in bytes {
        h ^= b as u64;
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

/// The fingerprint of what a solution depends on: meshes, objects,
/// materials, lights, the environment when there is one (their serde form)
/// and the patch size. Textures are not hashed (only their ids, through the
/// materials and the environment).
pub fn fingerprint(scene: &Scene, patch_size: f32) -> u64 {
    let mut h = 0xcbf2_9ce4_8422_2325u64;
    let parts = [
        serde_json::to_vec(&scene.meshes),
        serde_json::to_vec(&scene.objects),
        serde_json::to_vec(&scene.materials),
        serde_json::to_vec(&scene.lights),
    ];
    for p in parts {
        h = fnv1a(&p.unwrap_or_default(), h);
    }
    // Only with a map, so a scene without one keeps its fingerprint.
    if let Some(env) = &scene.environment {
        h = fnv1a(&serde_json::to_vec(env).unwrap_or_default(), h);
    }
    fnv1a(&patch_size.to_le_bytes(), h)
}

impl RadiositySolution {
    /// Number of display elements.
    pub fn element_count(&self) -> usize {
        self.elements.len()
    }

    /// Number of display vertices.
    pub fn vertex_count(&self) -> usize {
        self.vertices.len()
    }

    /// Display mesh: vertex positions (world space).
    pub fn vertices(&self) -> &[Vec3] {
        &self.vertices
    }

    /// Display mesh: triangles over [`Self::vertices`], counter-clockwise from the front.
    pub fn triangles(&self) -> &[[u32; 3]] {
        &self.elements
    }

    /// Outgoing radiance of each vertex (area-weighted mean of the elements
    /// around it), linear RGB: the colours Gouraud shading interpolates.
    pub fn vertex_radiance(&self) -> &[Vec3] {
        &self.vertex_radiance
    }

    /// Outgoing radiance of each element (constant over it).
    pub fn element_radiance(&self) -> &[Vec3] {
        &self.element_radiance
    }

    /// Emitted radiance of each element.
    pub fn element_emission(&self) -> &[Vec3] {
        &self.element_emission
    }

    /// Display element `e` at barycentrics `(u, v)` (weights of its corners
    /// 1 and 2) of source triangle `t`, and the Gouraud weights of its
    /// vertices at the point of the source triangle.
    fn locate(&self, t: usize, u: f32, v: f32) -> Option<(usize, [f32; 3])> {
        let k = *self.source_k.get(t)?;
        let e = *self.source_first.get(t)? as usize + element_at(k, u, v) as usize;
        let tri = self.elements.get(e)?;
        let c = self.source_corners[t];
        let p = c[0] + u * (c[1] - c[0]) + v * (c[2] - c[0]);
        let corners = tri.map(|i| self.vertices[i as usize]);
        Some((e, clamped_weights(barycentric(&corners, p))))
    }

    /// Incident irradiance (W/m^2, all of it: direct and reflected light)
    /// of each vertex, the area-weighted mean over the elements around it
    /// that reflect (see `irradiance_from`): the display multiplies it by
    /// the textured `kd / pi` at each pixel.
    pub fn vertex_irradiance(&self) -> &[Vec3] {
        &self.vertex_irradiance
    }

    /// The source triangle of each element.
    pub(crate) fn element_sources(&self) -> Vec<u32> {
        let mut out = vec![0; self.elements.len()];
        for (s, (&first, &k)) in self.source_first.iter().zip(&self.source_k).enumerate() {
            let first = first as usize;
            for o in out.iter_mut().skip(first).take((k * k) as usize) {
                *o = s as u32;
            }
        }
        out
    }

    pub(crate) fn interpolate(&self, values: &[Vec3], e: usize, w: [f32; 3]) -> Vec3 {
        let tri = self.elements[e];
        values[tri[0] as usize] * w[0]
            + values[tri[1] as usize] * w[1]
            + values[tri[2] as usize] * w[2]
    }

    /// Outgoing radiance (W sr^-1 m^-2, emission included) at barycentrics
    /// `(u, v)` (weights of corners 1 and 2, as in
    /// [`chiaro_core::accel::Hit`]) of triangle `triangle` of the
    /// [`chiaro_core::prepared::PreparedScene`] built with
    /// `PrepareOptions::default()` (tessellated spheres), Gouraud-interpolated
    /// from the vertices. `None` if the triangle is out of range. O(1).
    pub fn radiance_at_triangle(&self, triangle: u32, u: f32, v: f32) -> Option<Vec3> {
        if triangle >= self.prepared_triangles {
            return None;
        }
        let (e, w) = self.locate(triangle as usize, u, v)?;
        Some(self.interpolate(&self.vertex_radiance, e, w))
    }

    /// Incident *indirect* irradiance (W/m^2: light that has been reflected
    /// at least once, i.e. neither emitted light nor the direct light of
    /// lights and emitters) at the same place as [`Self::radiance_at_triangle`].
    /// A technique that computes direct light itself (the hybrid) adds
    /// `kd / pi` times this to its Lambertian term in place of the ambient term.
    pub fn indirect_irradiance_at_triangle(&self, triangle: u32, u: f32, v: f32) -> Option<Vec3> {
        if triangle >= self.prepared_triangles {
            return None;
        }
        let (e, w) = self.locate(triangle as usize, u, v)?;
        Some(self.interpolate(&self.vertex_indirect, e, w))
    }

    /// The source triangle of `object` nearest to `p` (on the side `n` faces
    /// if `n` is nonzero), with the barycentrics of `p` in it.
    fn find(&self, object: u32, p: Vec3, n: Vec3) -> Option<(usize, f32, f32)> {
        let count = self.prepared_triangles as usize;
        self.nearest
            .0
            .get_or_init(|| NearestIndex::new(&self.source_corners, &self.source_object, count))
            .nearest(&self.source_corners, object, p, n)
    }

    /// Outgoing radiance (W sr^-1 m^-2, emission included) at point `p` on
    /// object `object` (the index in `Scene::objects`, as in
    /// [`chiaro_core::prepared::SurfaceHit::object`]), on the side facing
    /// `n` (pass the geometric normal; `Vec3::ZERO` for either side).
    /// Works for analytic spheres too (the nearest facet of the tessellated
    /// sphere). `None` when the object has no surface in the solution.
    /// Cost: about log(triangles of the object), after a tree over the
    /// solution's triangles is built on the first call (linear in the
    /// triangle count, once); [`Self::radiance_at_triangle`] is O(1).
    pub fn radiance_at(&self, object: u32, p: Vec3, n: Vec3) -> Option<Vec3> {
        let (t, u, v) = self.find(object, p, n)?;
        self.radiance_at_triangle(t as u32, u, v)
    }

    /// Incident indirect irradiance (W/m^2, see
    /// [`Self::indirect_irradiance_at_triangle`]) at point `p` on object
    /// `object`, found as in [`Self::radiance_at`].
    pub fn indirect_irradiance_at(&self, object: u32, p: Vec3, n: Vec3) -> Option<Vec3> {
        let (t, u, v) = self.find(object, p, n)?;
        self.indirect_irradiance_at_triangle(t as u32, u, v)
    }

    /// Area-weighted mean outgoing radiance of `object`'s elements, or
    /// `None` if it has none (for tests and per-wall comparisons).
    pub fn object_mean_radiance(&self, object: u32) -> Option<Vec3> {
        let (mut sum, mut area) = (Vec3::ZERO, 0.0f32);
        for t in 0..self.prepared_triangles as usize {
            if self.source_object[t] != object {
                continue;
            }
            let k = self.source_k[t] as usize;
            let first = self.source_first[t] as usize;
            for e in first..first + k * k {
                let c = self.elements[e].map(|i| self.vertices[i as usize]);
                let a = 0.5 * (c[1] - c[0]).cross(c[2] - c[0]).length();
                sum += self.element_radiance[e] * a;
                area += a;
            }
        }
        (area > 0.0).then(|| sum / area)
    }

    /// Writes the solution as JSON.
    ///
    /// # Errors
    /// [`CoreError::Unsupported`] with the I/O or encoding error.
    pub fn save(&self, w: impl Write) -> Result<(), CoreError> {
        serde_json::to_writer(std::io::BufWriter::new(w), self)
            .map_err(|e| CoreError::Unsupported(format!("cannot save radiosity solution: {e}")))
    }

    /// Reads a solution written by [`Self::save`] and checks that it belongs
    /// to `scene` (same geometry, materials, lights and patch size).
    ///
    /// # Errors
    /// [`CoreError::Unsupported`] for unreadable data, another format
    /// version, or a solution of a different scene.
    pub fn load(r: impl Read, scene: &Scene) -> Result<Self, CoreError> {
        let s: RadiositySolution = serde_json::from_reader(std::io::BufReader::new(r))
            .map_err(|e| CoreError::Unsupported(format!("cannot read radiosity solution: {e}")))?;
        if s.version != FORMAT_VERSION {
            return Err(CoreError::Unsupported(format!(
                "radiosity solution has format version {} (this build reads {FORMAT_VERSION})",
                s.version
            )));
        }
        s.check_scene(scene)?;
        Ok(s)
    }

    /// Checks that the solution was computed for `scene`.
    ///
    /// # Errors
    /// [`CoreError::Unsupported`] when the scene's geometry, materials or
    /// lights differ from those the solution was computed for, or the data
    /// is inconsistent.
    pub fn check_scene(&self, scene: &Scene) -> Result<(), CoreError> {
        let f = fingerprint(scene, self.stats.patch_size);
        if f != self.fingerprint {
            return Err(CoreError::Unsupported(format!(
                "radiosity solution does not match this scene (fingerprint {:016x}, scene {f:016x}): \
                 geometry, materials, lights or patch size differ; solve again",
                self.fingerprint
            )));
        }
        let nv = self.vertices.len();
        let ne = self.elements.len();
        let ok = self.vertex_radiance.len() == nv
            && self.vertex_indirect.len() == nv
            && self.vertex_irradiance.len() == nv
            && self.element_radiance.len() == ne
            && self.element_emission.len() == ne
            && self
                .elements
                .iter()
                .all(|t| t.iter().all(|&i| (i as usize) < nv))
            && self.source_k.len() == self.source_corners.len()
            && self.source_first.len() == self.source_corners.len()
            && self.source_object.len() == self.source_corners.len()
            && (self.prepared_triangles as usize) <= self.source_corners.len()
            && self
                .source_k
                .iter()
                .zip(&self.source_first)
                .all(|(&k, &f)| k >= 1 && f as u64 + k as u64 * k as u64 <= ne as u64);
        if !ok {
            return Err(CoreError::Unsupported(
                "radiosity solution is inconsistent (corrupt file?)".into(),
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod round_trip_tests {
    use super::SolveStats;

    /// Solutions are compared byte for byte after a save/load round trip
    /// (the Python module's `to_bytes`/`from_bytes`, Ray's object store):
    /// every float must read back exactly. `seconds` is a measured time,
    /// any f64; serde_json parses floats exactly only with its
    /// `float_roundtrip` feature (its default parser may be one ulp off).
    #[test]
    fn stats_floats_read_back_exactly() {
        let mut x = 0x9E37_79B9_7F4A_7C15u64;
        for _ in 0..20_000 {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            let stats = SolveStats {
                seconds: (x >> 11) as f64 / (1u64 << 53) as f64 * 10.0,
                unshot: f32::from_bits(0x3000_0000 | (x as u32 & 0x0fff_ffff)),
                ..SolveStats::default()
            };
            let text = serde_json::to_string(&stats).expect("serialises");
            let back: SolveStats = serde_json::from_str(&text).expect("parses");
            assert_eq!(back, stats, "{text}");
        }
    }
}
