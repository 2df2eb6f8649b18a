//! Radiosity for chiaro: patches, form factors, solvers, view-independent solutions.
//!
//! [`solve`] meshes every surface and area light into triangular elements
//! ([`mesh`]), groups fine elements into shooting patches (`patch.rs`),
//! computes form factors ([`formfactor`]: [`ray_cast`], [`analytic`],
//! [`hemicube`]), solves the radiosity system with the chosen solver
//! ([`solver`]: [`gathering`], [`progressive`], [`hierarchical`]) and
//! returns a [`RadiositySolution`], which the render context keeps
//! ([`solution()`]); `render_solution`
//! draws it from the scene's camera through chiaro-raster's z-buffer (item
//! buffer): the textured colour from the surface layer times the Gouraud
//! interpolation of the vertex irradiance; [`Radiosity`] does both, as the
//! technique interface's [`Renderer`].
//!
//! # Conventions (decided here; see ARCHITECTURE.md)
//! - Every quantity a solver stores is **radiance** `L` (W sr^-1 m^-2), not
//!   radiosity `B = pi L`: the displayed pixel is then exactly what a
//!   converged path tracer returns for the same Lambertian surface. The
//!   equation is `L_j = E_j + rho_j sum_i F_ji L_i`.
//! - `rho` is the material's `diffuse` kd (times vertex colours and texture
//!   at the element centre), clamped to `[0, 1]`; emission is the material's
//!   `emission` (radiance, front side only) or an area light's
//!   `color * intensity`; area lights become elements (`rho = 0`; two-sided
//!   lights get a back-to-back pair) but do not occlude visibility rays.
//! - Point, spot and directional lights are a first "unshot gather": each
//!   element gets `rho * f_att * Ip * spot * cos_theta * V` (the reflected
//!   radiance of irradiance `pi Ip f_att cos / d^2`) added to `E`, with shadow
//!   rays. Ambient lights are ignored.
//! - The environment map is a distant emitter gathered the same way
//!   (`environment.rs`): each element gets `rho / pi` times its irradiance
//!   `int L_env V cos dw` from the map, estimated with stratified,
//!   visibility-tested rays of fixed seeds, added to `E`. The scene's plain
//!   `background` colour lights nothing.
//! - Elements are one-sided: light leaves the front (the side of the
//!   counter-clockwise normal), and only the front gathers. A two-sided
//!   surface (the default, `Sidedness::TwoSided`) is solved as one-sided
//!   (a limitation): its back shows its front's reflected light, so a
//!   surface lit only from behind shows dark from both sides. The display
//!   follows the sidedness rule otherwise: the back of a `OneSided`
//!   material is black, the back of a `Culled` one is not drawn, and
//!   emission shows on a back only when `emission_two_sided`.
//!
//! # Glossary
//! - **source triangle**: a triangle of the prepared scene (or of a meshed
//!   area light) before subdivision.
//! - **element**: one of the `k x k` triangles a source triangle is cut
//!   into; constant albedo, emission and radiance.
//! - **patch** (progressive refinement): a group of neighbouring,
//!   near-coplanar elements finer than the patch size that shoots as one
//!   (`patch.rs`); an element of patch size is its own patch.
//! - **F_ij**: the form factor, the fraction of the energy leaving `i` that
//!   reaches `j`; `A_i F_ij = A_j F_ji` (reciprocity).
//! - **unshot fraction**: power not yet distributed over emitted power, the
//!   stop criterion of every solver (`radiosity.tolerance`).
//! - **link** (hierarchical): an interaction between two quadtree nodes at
//!   the level where its form factor is accurate enough.
//! - **cluster** (hierarchical, above 2048 source triangles): a node of a
//!   bounding-volume tree over the source triangles that exchanges light
//!   as one, with its projected area and mean radiance (`cluster.rs`).

pub mod analytic;
mod cluster;
mod direct;
mod environment;
pub mod formfactor;
pub mod gathering;
pub mod hemicube;
pub mod hierarchical;
pub mod mesh;
mod nearest;
mod patch;
pub mod progressive;
pub mod ray_cast;
pub mod solution;
pub mod solver;

pub use analytic::point_to_polygon;
pub use formfactor::{FormFactor, disc_to_disc, perpendicular_rectangles};
use solution::{RHO_MIN, clamped_weights, irradiance_from};
pub use solution::{RadiositySolution, SolveStats, fingerprint};

use chiaro_core::budget::{Estimate, bytes_of};
use chiaro_core::context::{RenderContext, RenderStats, Renderer};
use chiaro_core::error::CoreError;
use chiaro_core::film::Film;
use chiaro_core::prepared::PreparedScene;
use chiaro_core::progress::Progress;
use chiaro_core::scene::{Facing, RenderSettings, Scene, Technique};
use chiaro_core::shading::texture::background_radiance;
use chiaro_core::technique::{Description, Feature};
use direct::point_light_direct;
use glam::{Vec2, Vec3};
use mesh::{Element, ElementMesh, SourceKind, material_at};
use ray_cast::{PairFormFactor, PairRule, Visibility, pair};
use rayon::prelude::*;
use std::sync::Arc;
use std::time::Instant;

pub use chiaro_core::scene::{FormFactorMethod as Method, RadiositySolver as Solver};

/// The radiosity technique: the context's [`solution()`], displayed by
/// `render_solution`.
#[derive(Debug, Clone, Copy, Default)]
pub struct Radiosity;

impl Renderer for Radiosity {
    fn render(&self, ctx: &RenderContext<'_>) -> Result<(Film, RenderStats), CoreError> {
        let solution = solution(ctx)?;
        let film = render_solution(ctx, &solution)?;
        Ok((film, ctx.stats(0)))
    }

    fn descriptions(&self) -> &'static [Description] {
        std::slice::from_ref(&DESCRIPTION)
    }

    fn memory(&self, scene: &Scene, settings: &RenderSettings, estimate: &mut Estimate) {
        solver_memory(scene, settings, estimate);
        // The display's item buffer: a depth key and an element id a
        // supersample.
        let ss = u64::from(display_supersampling(settings));
        let pixels = u64::from(settings.width) * u64::from(settings.height);
        estimate.add(
            "radiosity display supersamples",
            bytes_of(pixels.saturating_mul(ss * ss), 8),
        );
    }
}

/// The display's supersamples along each axis: the square root of the
/// samples per pixel, rounded, 1 to 8.
fn display_supersampling(settings: &RenderSettings) -> u32 {
    (settings.samples.max(1) as f32)
        .sqrt()
        .round()
        .clamp(1.0, 8.0) as u32
}

/// The radiosity technique, described.
pub const DESCRIPTION: Description = Description {
    technique: Technique::Radiosity,
    title: "radiosity",
    method: "elements, with patches grouped from fine input triangles to shoot from; hemicube / ray-cast / analytic form factors, Jacobi, Gauss-Seidel, progressive and hierarchical (clustered above 2048 triangles) solvers, `auto` picking progressive or clustered by size; the view-independent solution drawn with Gouraud interpolation",
    shows: "diffuse interreflection and colour bleeding, soft shadows, textures (the texture times the patches' light), the environment map's light with its occlusion",
    cannot_show: &[
        (
            Feature::Mirrors,
            "mirror reflections: mirrors are drawn matte",
        ),
        (
            Feature::Transparency,
            "transparency and refraction: drawn opaque",
        ),
        (
            Feature::Highlights,
            "specular highlights: surfaces are drawn diffuse",
        ),
        (
            Feature::NormalMaps,
            "normal and bump maps: patches are lit with their face normal",
        ),
        (
            Feature::AmbientLight,
            "ambient lights: interreflection is computed instead",
        ),
        (Feature::DepthCue, "depth cueing"),
        (
            Feature::AlphaMask,
            "cut-outs of alpha-masked (glTF MASK) surfaces: patches are drawn whole",
        ),
    ],
};

/// Adds what the radiosity solver allocates to `estimate`, over at least
/// one element a triangle of the tessellated scene: with the matrix
/// solvers, two dense f32 matrices; with the hierarchical solver (and
/// `auto` where it picks it), its quadtrees, links and clusters
/// ([`hierarchical`]'s estimate; the solve checks it again with the real
/// element count once the scene is meshed, before building them).
pub fn solver_memory(scene: &Scene, settings: &RenderSettings, estimate: &mut Estimate) {
    let cfg = &settings.radiosity;
    let n = chiaro_core::context::tessellated_triangles(scene, settings);
    if cfg.solver.is_matrix() {
        estimate.add("radiosity matrix", bytes_of(n.saturating_mul(n), 8));
    } else if cfg
        .solver
        .resolve(usize::try_from(n).unwrap_or(usize::MAX), cfg.formfactor)
        == Solver::Hierarchical
    {
        hierarchical::memory(n, n, n > cluster::CLUSTER_ABOVE as u64, estimate);
    }
}

/// The hierarchical solver's memory over `sources` source triangles meshed
/// into `elements` elements, checked against the budget before they are
/// made: the render's estimate ([`chiaro_core::context::memory_estimate`])
/// with [`hierarchical::memory`] at that element count.
fn check_hierarchy_memory(
    ctx: &RenderContext<'_>,
    sources: usize,
    elements: u64,
    clustered: bool,
) -> Result<(), CoreError> {
    let (scene, settings) = (ctx.scene(), ctx.settings());
    let mut estimate = chiaro_core::context::memory_estimate(scene, settings);
    hierarchical::memory(sources as u64, elements, clustered, &mut estimate);
    estimate
        .check(settings.memory_budget())
        .map_err(|e| CoreError::Unsupported(format!("radiosity ({elements} elements): {e}")))
}

/// The context's radiosity solution: the one it was given (a saved
/// solution, or the viewer's from the last frame), checked to belong to the
/// scene, else [`solve`]d on first use and kept for the context's later
/// renders.
///
/// # Errors
/// As [`solve`]; [`CoreError::Unsupported`] for a given solution of
/// another scene.
pub fn solution(ctx: &RenderContext<'_>) -> Result<Arc<RadiositySolution>, CoreError> {
    let solution = ctx.solution(solve)?;
    solution.check_scene(ctx.scene())?;
    Ok(solution)
}

/// Elements per cancellation check of the per-element passes.
const CHUNK: usize = 16_384;

/// `f(i)` for `i` in `0..n`, in parallel, polling `progress` for
/// cancellation between chunks.
fn par_map<T: Send>(
    n: usize,
    progress: &dyn Progress,
    f: impl Fn(usize) -> T + Sync + Send,
) -> Result<Vec<T>, CoreError> {
    let mut out = Vec::with_capacity(n);
    for lo in (0..n).step_by(CHUNK) {
        if progress.cancelled() {
            return Err(CoreError::Cancelled);
        }
        out.par_extend((lo..(lo + CHUNK).min(n)).into_par_iter().map(&f));
    }
    Ok(out)
}

/// Emissive source triangles grouped by the patch of their first element:
/// a group of one is gathered triangle by triangle, a larger group as one
/// disc from receivers far from it (see [`patch::FAR`]).
struct EmitterGroup {
    sources: Vec<Element>,
    area: f32,
    le: Vec3,
    centre: Vec3,
    normal: Vec3,
    radius: f32,
}

impl EmitterGroup {
    /// The free fraction of four rays from element `e` to sources spread
    /// over the group.
    fn free_fraction(&self, e: &Element, vis: &Visibility<'_>) -> f32 {
        let n = self.sources.len();
        let points = (0..4).map(|k| {
            let s = &self.sources[k * n / 4];
            (s.c, s.n)
        });
        patch::free_fraction(vis, e.c, e.n, points)
    }
}

/// Receiver elements times emissive triangles above which [`direct_light`]
/// gathers each pair with one point and one ray.
const DIRECT_PAIR_BUDGET: usize = 20_000_000;

/// Reflected radiance at each element due to *direct* light: point-like
/// lights and the environment map (`point_direct`) plus every emissive source triangle, gathered
/// with ray-cast form factors (16 visibility rays per receiver point), or,
/// for a group of several emitters, their unoccluded form factors (the
/// group's point-to-disc form factor when it is far from the receiver)
/// times the free fraction of four rays to the group.
fn direct_light(
    ps: &PreparedScene<'_>,
    mesh: &ElementMesh,
    patches: &patch::Patches,
    point_direct: &[Vec3],
    vis: &Visibility<'_>,
    tol: f32,
    progress: &dyn Progress,
) -> Result<Vec<Vec3>, CoreError> {
    let mut groups: Vec<EmitterGroup> = Vec::new();
    let mut group_of: std::collections::HashMap<u32, usize> = Default::default();
    for (si, s) in mesh.sources.iter().enumerate() {
        let (_, le) = material_at(ps, s, 1.0 / 3.0, 1.0 / 3.0);
        if le.max_element() <= 0.0 {
            continue;
        }
        let el = Element::new(s.p, s.n, Vec3::ZERO, le, [0; 3], si as u32);
        let key = patches.of[mesh.first[si] as usize];
        let g = *group_of.entry(key).or_insert_with(|| {
            groups.push(EmitterGroup {
                sources: Vec::new(),
                area: 0.0,
                le: Vec3::ZERO,
                centre: Vec3::ZERO,
                normal: Vec3::ZERO,
                radius: 0.0,
            });
            groups.len() - 1
        });
        groups[g].sources.push(el);
    }
    for g in &mut groups {
        for s in &g.sources {
            g.area += s.area;
            g.le += s.le * s.area;
            g.centre += s.c * s.area;
            g.normal += s.n * s.area;
        }
        let a = g.area.max(f32::MIN_POSITIVE);
        (g.le, g.centre) = (g.le / a, g.centre / a);
        g.normal = g.normal.normalize_or(g.sources[0].n);
        g.radius = g
            .sources
            .iter()
            .flat_map(|s| s.p)
            .map(|q| q.distance(g.centre))
            .fold(0.0f32, f32::max);
    }
    // Every element gathers from every emitter: past a budget of pairs
    // (a whole model made emissive), one quadrature point and one
    // visibility ray a pair instead of up to 16 and 16, so the work stays
    // bounded (counted in pairs, so the result does not depend on timing).
    let emitters: usize = groups.iter().map(|g| g.sources.len()).sum();
    let rule = if mesh.elements.len().saturating_mul(emitters) > DIRECT_PAIR_BUDGET {
        PairRule {
            far_m: 1,
            mid_m: 1,
            near_m: 1,
            vis_m: 1,
        }
    } else {
        PairRule {
            far_m: 2,
            mid_m: 2,
            near_m: 4,
            vis_m: 4,
        }
    };
    par_map(mesh.elements.len(), progress, |i| {
        let (e, pd) = (&mesh.elements[i], &point_direct[i]);
        if e.rho == Vec3::ZERO {
            return Vec3::ZERO;
        }
        let radius = e.p.iter().map(|q| q.distance(e.c)).fold(0.0f32, f32::max);
        let mut sum = Vec3::ZERO;
        for g in &groups {
            if g.sources.len() > 1 && e.c.distance(g.centre) > patch::FAR * (g.radius + radius) {
                let f = patch::point_to_disc(e.c, e.n, g.centre, g.normal, g.area);
                if f > 0.0 {
                    sum += g.le * (f * g.free_fraction(e, vis));
                }
                continue;
            }
            if let [s] = g.sources.as_slice() {
                if s.source != e.source {
                    sum += s.le * pair(e, s, rule, Some(vis), tol);
                }
                continue;
            }
            // Near a group of several emitters: their unoccluded form
            // factors, times the free fraction of four rays to the group.
            let mut near = Vec3::ZERO;
            for s in &g.sources {
                if s.source != e.source {
                    near += s.le * pair(e, s, rule, None, tol);
                }
            }
            if near != Vec3::ZERO {
                sum += near * g.free_fraction(e, vis);
            }
        }
        *pd + e.rho * sum
    })
}

/// Solves the radiosity of the context's scene with `settings.radiosity`
/// and returns the view-independent solution (radiance per element and per
/// vertex).
///
/// # Errors
/// [`CoreError::Unsupported`] when the mesh is too large for the solver;
/// [`CoreError::Cancelled`] when the progress asks.
pub fn solve(ctx: &RenderContext<'_>) -> Result<RadiositySolution, CoreError> {
    solve_with(ctx, true)
}

/// [`solve`], with progressive refinement shooting from patches of
/// several elements when `clustered` (else from every element).
pub(crate) fn solve_with(
    ctx: &RenderContext<'_>,
    clustered: bool,
) -> Result<RadiositySolution, CoreError> {
    solve_clustering(ctx, clustered, cluster::CLUSTER_ABOVE)
}

/// [`solve_with`], with the hierarchical solver building a cluster
/// hierarchy above `cluster_above` source triangles (`cluster.rs`).
pub(crate) fn solve_clustering(
    ctx: &RenderContext<'_>,
    clustered: bool,
    cluster_above: usize,
) -> Result<RadiositySolution, CoreError> {
    let cfg = &ctx.settings().radiosity;
    let (scene, progress) = (ctx.scene(), ctx.progress());
    let start = Instant::now();
    let ps = ctx.tessellated();
    let patch = if cfg.patch_size > 0.0 {
        cfg.patch_size
    } else {
        mesh::default_patch_size(ps)
    };
    let size = ps.bounds.diagonal().max(1e-6);
    let tol = size * 1e-6;
    let vis = Visibility {
        accel: ctx.tessellated_accel(),
        eps: size * 1e-4,
    };
    // `auto`: progressive refinement on small scenes, clusters above.
    let solver = cfg.solver.resolve(ps.triangles.len(), cfg.formfactor);
    progress.begin("radiosity meshing", 1);
    // The hierarchical solver's quadtrees, links and clusters are checked
    // against the budget at the element count, before the elements are made.
    let hierarchy = |sources: usize, elements: u64| {
        if solver == Solver::Hierarchical {
            check_hierarchy_memory(ctx, sources, elements, sources > cluster_above.max(1))
        } else {
            Ok(())
        }
    };
    let mesh = mesh::build_checked(
        ps,
        patch,
        solver == Solver::Hierarchical,
        progress,
        &hierarchy,
    )?;
    // Patches above elements shoot in progressive refinement with element
    // form factors (hemicubes are cast from one element's centre, so their
    // shots stay per element); the other solvers work on elements.
    let patches =
        if clustered && solver == Solver::Progressive && cfg.formfactor != Method::Hemicube {
            patch::Patches::build(&mesh, patch, progress)?
        } else {
            patch::Patches::singletons(&mesh)
        };
    progress.advance(1);
    let n = mesh.elements.len();
    progress.message(&format!(
        "radiosity: {n} elements in {} patches (patch size {patch}), solver {}, form factors {}",
        patches.len(),
        solver.name(),
        cfg.formfactor.name()
    ));
    let mut point_direct: Vec<Vec3> = par_map(n, progress, |i| {
        point_light_direct(&mesh.elements[i], &scene.lights, &vis)
    })?;
    // The environment map's light, gathered with visibility, joins the
    // point lights' as the elements' first gather (none without a map).
    let env_direct = match environment::EnvironmentSource::new(scene, n) {
        Some(env) => {
            progress.begin("radiosity environment", 1);
            progress.message(&format!(
                "radiosity: gathering the environment, {} + {} directions an element",
                env.directions(),
                env.directions()
            ));
            let d = par_map(n, progress, |i| {
                env.reflected(&mesh.elements[i], i as u64, &vis)
            })?;
            progress.advance(1);
            for (p, d) in point_direct.iter_mut().zip(&d) {
                *p += *d;
            }
            d
        }
        None => Vec::new(),
    };
    let e: Vec<Vec3> = mesh
        .elements
        .iter()
        .zip(&point_direct)
        .map(|(el, d)| el.le + *d)
        .collect();
    let mut stats = SolveStats {
        solver: solver.name().into(),
        formfactor: cfg.formfactor.name().into(),
        patch_size: patch,
        elements: n,
        patches: patches.len(),
        ..SolveStats::default()
    };
    let hemi;
    let pairs;
    let mut pair_rule = None;
    let ff: &dyn FormFactor = match cfg.formfactor {
        Method::Hemicube => {
            hemi = hemicube::HemicubeFormFactor::new(
                &mesh.elements,
                &mesh.vertices,
                cfg.hemicube_resolution,
                size,
            );
            &hemi
        }
        Method::Raycast => {
            pairs = PairFormFactor::raycast(
                &mesh.elements,
                Visibility {
                    accel: vis.accel,
                    eps: vis.eps,
                },
                tol,
            );
            pair_rule = Some(pairs.rule);
            &pairs
        }
        Method::Analytic => {
            pairs = PairFormFactor::analytic(&mesh.elements, tol);
            pair_rule = Some(pairs.rule);
            &pairs
        }
    };
    // Each solver's radiance per element, iterations, final unshot fraction,
    // why it stopped and where most unshot light was left.
    let (stop, max_iter) = (cfg.tolerance, cfg.max_iterations);
    let (l, iterations, unshot, ended, worst) = match solver {
        Solver::Jacobi | Solver::GaussSeidel => {
            let m = gathering::build_matrix(&mesh.elements, ff, progress)?;
            let sweep = if solver == Solver::Jacobi {
                gathering::Sweep::Jacobi
            } else {
                gathering::Sweep::GaussSeidel
            };
            let out = gathering::iterate(&mesh.elements, &e, &m, stop, max_iter, progress, sweep)?;
            (out.l, out.iterations, out.unshot, out.stop, Some(out.worst))
        }
        // `resolve` turned `auto` into progressive or hierarchical.
        Solver::Progressive | Solver::Auto => {
            let columns = |i: usize, du: &[Vec3], f: &mut [f32], g: &mut [Vec3]| {
                ff.column(i, f);
                g.par_iter_mut()
                    .zip(f.par_iter())
                    .for_each(|(g, f)| *g = *f * du[i]);
            };
            let shooter = pair_rule.map(|rule| {
                patch::PatchShooter::new(
                    &mesh,
                    &patches,
                    rule,
                    (cfg.formfactor == Method::Raycast).then_some(&vis),
                    tol,
                )
            });
            let by_patch = |p: usize, du: &[Vec3], f: &mut [f32], g: &mut [Vec3]| {
                if let Some(s) = &shooter {
                    s.shoot(p, du, f, g);
                }
            };
            let shoot: &progressive::Shoot<'_> = if shooter.is_some() {
                &by_patch
            } else {
                &columns
            };
            let out = progressive::progressive(
                &mesh.elements,
                &patches,
                &e,
                shoot,
                stop,
                max_iter,
                progress,
            )?;
            (out.l, out.iterations, out.unshot, out.stop, Some(out.worst))
        }
        Solver::Hierarchical => {
            let (rule, v) = match cfg.formfactor {
                Method::Analytic => (PairFormFactor::analytic(&[], tol).rule, None),
                _ => (
                    PairFormFactor::raycast(
                        &[],
                        Visibility {
                            accel: vis.accel,
                            eps: vis.eps,
                        },
                        tol,
                    )
                    .rule,
                    Some(&vis),
                ),
            };
            let (l, hs) = hierarchical::solve(
                ps,
                &mesh,
                &e,
                &env_direct,
                v,
                rule,
                tol,
                stop,
                max_iter,
                cluster_above,
                progress,
            )?;
            (stats.nodes, stats.leaves, stats.links) = (hs.nodes, hs.leaves, hs.links);
            (l, hs.iterations, hs.unshot, hs.stop, None)
        }
    };
    (stats.iterations, stats.unshot) = (iterations, unshot);
    warn_unconverged(ctx, &mesh, ended, &stats, worst);
    let l: Vec<Vec3> = l.into_iter().map(chiaro_core::shading::sanitize).collect();
    // Irradiance for the display, pi (L - Le) / rho, and its indirect part
    // for the hybrid, pi (L - Le - direct) / rho.
    let direct = direct_light(ps, &mesh, &patches, &point_direct, &vis, tol, progress)?;
    let (irradiance, indirect): (Vec<Vec3>, Vec<Vec3>) = mesh
        .elements
        .iter()
        .zip(&l)
        .zip(&direct)
        .map(|((el, l), d)| {
            let reflected = (*l - el.le).max(Vec3::ZERO);
            (
                irradiance_from(reflected, el.rho),
                irradiance_from((reflected - *d).max(Vec3::ZERO), el.rho),
            )
        })
        .unzip();
    stats.seconds = start.elapsed().as_secs_f64();
    progress.message(&format!(
        "radiosity: solved in {:.2} s ({} iterations, unshot {:.3e})",
        stats.seconds, stats.iterations, stats.unshot
    ));
    Ok(build_solution(
        scene, ps, &mesh, l, irradiance, indirect, stats,
    ))
}

/// Warns through the context's progress when a solve stopped before
/// converging ([`solver::stop_warning`]), naming the object of element
/// `worst` (the one holding the most unshot power) when known.
fn warn_unconverged(
    ctx: &RenderContext<'_>,
    mesh: &ElementMesh,
    stop: solver::Stop,
    stats: &SolveStats,
    worst: Option<usize>,
) {
    let culprit = worst
        .and_then(|e| mesh.elements.get(e))
        .and_then(|e| mesh.sources.get(e.source as usize))
        .and_then(|s| ctx.scene().objects.get(s.object as usize))
        .map(|o| format!("object \"{}\"", o.name));
    if let Some(w) = solver::stop_warning(
        stop,
        &stats.solver,
        stats.iterations,
        stats.unshot,
        ctx.settings().radiosity.tolerance,
        culprit.as_deref(),
    ) {
        ctx.progress().warning(&w);
    }
}

fn build_solution(
    scene: &Scene,
    ps: &PreparedScene<'_>,
    mesh: &ElementMesh,
    l: Vec<Vec3>,
    irradiance: Vec<Vec3>,
    indirect: Vec<Vec3>,
    stats: SolveStats,
) -> RadiositySolution {
    let nv = mesh.vertices.len();
    let mut vr = vec![Vec3::ZERO; nv];
    let mut w = vec![0.0f32; nv];
    // Irradiance is known only on elements that reflect: each channel is
    // averaged over those (`wi`), so a black neighbour does not darken it.
    let (mut ve, mut vi, mut wi) = (
        vec![Vec3::ZERO; nv],
        vec![Vec3::ZERO; nv],
        vec![Vec3::ZERO; nv],
    );
    for (((el, l), e), ind) in mesh.elements.iter().zip(&l).zip(&irradiance).zip(&indirect) {
        let reflects = Vec3::select(el.rho.cmpgt(Vec3::splat(RHO_MIN)), Vec3::ONE, Vec3::ZERO);
        for &v in &el.verts {
            let v = v as usize;
            vr[v] += *l * el.area;
            w[v] += el.area;
            ve[v] += *e * el.area;
            vi[v] += *ind * el.area;
            wi[v] += reflects * el.area;
        }
    }
    for (r, w) in vr.iter_mut().zip(&w) {
        if *w > 0.0 {
            *r /= *w;
        }
    }
    for ((e, i), w) in ve.iter_mut().zip(vi.iter_mut()).zip(&wi) {
        let inv = Vec3::select(w.cmpgt(Vec3::ZERO), Vec3::ONE / *w, Vec3::ZERO);
        *e *= inv;
        *i *= inv;
    }
    RadiositySolution {
        version: solution::FORMAT_VERSION,
        fingerprint: fingerprint(scene, stats.patch_size),
        stats,
        vertices: mesh.vertices.clone(),
        vertex_radiance: vr,
        vertex_indirect: vi,
        vertex_irradiance: ve,
        elements: mesh.elements.iter().map(|e| e.verts).collect(),
        element_radiance: l,
        element_emission: mesh.elements.iter().map(|e| e.le).collect(),
        source_corners: mesh.sources.iter().map(|s| s.p).collect(),
        source_object: mesh.sources.iter().map(|s| s.object).collect(),
        source_k: mesh.k.clone(),
        source_first: mesh.first.clone(),
        prepared_triangles: (mesh
            .sources
            .iter()
            .filter(|s| matches!(s.kind, SourceKind::Prepared(_)))
            .count() as u32)
            .min(ps.triangles.len() as u32),
        nearest: Default::default(),
    }
}

/// Draws `solution` from the context's camera: the display mesh is scan
/// converted into chiaro-raster's item buffer (z-buffer) at
/// `round(sqrt(samples))^2` samples per pixel, and each visible sample gets
/// its surface's emission plus its textured `kd / pi` times the Gouraud
/// interpolation of its element's vertex irradiance (exact barycentrics on
/// the element's plane along the pixel ray): display-time texture
/// modulation, so textures keep their detail. Background:
/// what every technique's camera sees (`texture::background_radiance`).
/// Fills the film's depth and normal buffers. Only the pixels of
/// `settings.crop_rect()` are shaded (the rest stay black with infinite
/// depth), each equal to the full render's.
///
/// # Errors
/// [`CoreError::Unsupported`] if the solution belongs to another scene;
/// [`CoreError::Cancelled`] when `progress` asks.
pub(crate) fn render_solution(
    ctx: &RenderContext<'_>,
    solution: &RadiositySolution,
) -> Result<Film, CoreError> {
    let (scene, settings, progress) = (ctx.scene(), ctx.settings(), ctx.progress());
    solution.check_scene(scene)?;
    let (w, h) = (settings.width.max(1), settings.height.max(1));
    let ss = display_supersampling(settings);
    let (sw, sh) = (w * ss, h * ss);
    progress.begin("radiosity display", 1);
    if progress.cancelled() {
        return Err(CoreError::Cancelled);
    }
    let cam = ctx.camera();
    let clip_from_world = cam.projection_matrix(w as f32 / h as f32) * cam.view_matrix();
    let normals: Vec<Vec3> = solution
        .elements
        .iter()
        .map(|t| {
            let c = t.map(|i| solution.vertices[i as usize]);
            (c[1] - c[0]).cross(c[2] - c[0]).normalize_or_zero()
        })
        .collect();
    let surfaces = DisplaySurfaces::new(ctx.tessellated(), solution);
    // The eye does not see the backs of `Sidedness::Culled` materials, as in
    // the other techniques: such elements are left out.
    let culling = scene.materials.iter().any(|m| !m.sidedness.eye_sees_back());
    let (kept, ids): (Vec<[u32; 3]>, Vec<u32>) = if culling {
        let ps = &surfaces.ps;
        let nt = (solution.prepared_triangles as usize).min(ps.triangles.len());
        (0..solution.elements.len())
            .filter(|&e| {
                let s = surfaces.sources[e] as usize;
                let back = || {
                    let c0 = solution.vertices[solution.elements[e][0] as usize];
                    normals[e].dot(cam.toward_viewer(c0)) < 0.0
                };
                !(s < nt && !ps.material(ps.tri_material[s]).sidedness.eye_sees_back() && back())
            })
            .map(|e| (solution.elements[e], e as u32))
            .unzip()
    } else {
        (Vec::new(), Vec::new())
    };
    let depth_key = chiaro_raster::raster::DepthKey::of_camera(cam);
    let buf = chiaro_raster::zbuffer::item_buffer_with(
        clip_from_world,
        sw,
        sh,
        &solution.vertices,
        if culling { &kept } else { &solution.elements },
        &ids,
        &chiaro_raster::zbuffer::ItemBufferOptions {
            cull_back_faces: false,
            depth_key,
        },
    );
    let mut film = Film::new(w, h);
    // Only the crop window's pixels are shaded (the others stay black with
    // infinite depth); each pixel depends only on its own samples, so the
    // window equals the same pixels of a full render.
    let [cx0, cy0, cx1, cy1] = settings.crop_rect();
    let pixel_rays = cam.pixel_rays(sw, sh);
    let rows: Vec<Vec<(Vec3, f32, Vec3)>> = (cy0..cy1.min(h))
        .into_par_iter()
        .map(|y| {
            (cx0..cx1.min(w))
                .map(|x| {
                    let (mut col, mut depth, mut normal) = (Vec3::ZERO, f32::INFINITY, Vec3::ZERO);
                    for sy in 0..ss {
                        for sx in 0..ss {
                            let (px, py) = (x * ss + sx, y * ss + sy);
                            let id = buf.id[(py * sw + px) as usize];
                            let ray = pixel_rays.ray(px as f32 + 0.5, py as f32 + 0.5);
                            let (o, d) = (ray.origin, ray.dir);
                            if id == chiaro_raster::zbuffer::NO_ITEM {
                                col += background_radiance(scene, d);
                                continue;
                            }
                            let e = id as usize;
                            let n = normals[e];
                            let c = solution.elements[e].map(|i| solution.vertices[i as usize]);
                            let denom = n.dot(d);
                            let t = if denom.abs() > 1e-12 {
                                n.dot(c[0] - o) / denom
                            } else {
                                0.0
                            };
                            let p = o + d * t;
                            let back = n.dot(d) > 0.0;
                            col += surfaces.radiance(solution, e, &c, p, back);
                            if t.is_finite() && t < depth {
                                depth = t;
                                normal = n;
                            }
                        }
                    }
                    (col / (ss * ss) as f32, depth, normal)
                })
                .collect()
        })
        .collect();
    for (y, row) in (cy0..).zip(rows) {
        for (x, (c, d, n)) in (cx0..).zip(row) {
            film.set(x, y, c);
            let i = film.index(x, y);
            film.depth[i] = d;
            film.normal[i] = n;
        }
    }
    progress.advance(1);
    Ok(film)
}

/// What the display reads from the scene: the surface layer (tessellated
/// spheres, as solved), each element's source triangle, and the `(kd,
/// emission)` of the source triangles whose surface is uniform (untextured,
/// one vertex colour), evaluated once.
struct DisplaySurfaces<'a> {
    ps: &'a PreparedScene<'a>,
    sources: Vec<u32>,
    uniform: Vec<Option<(Vec3, Vec3)>>,
}

impl<'a> DisplaySurfaces<'a> {
    fn new(ps: &'a PreparedScene<'a>, solution: &RadiositySolution) -> Self {
        let n = (solution.prepared_triangles as usize).min(ps.triangles.len());
        let uniform = (0..n as u32)
            .into_par_iter()
            .map(|t| {
                let m = ps.material(ps.tri_material[t as usize]);
                let [a, b, c] = ps.triangles[t as usize].map(|i| ps.colors[i as usize]);
                (!m.is_textured() && a == b && b == c).then(|| surface(ps, t, 1.0 / 3.0, 1.0 / 3.0))
            })
            .collect();
        Self {
            ps,
            sources: solution.element_sources(),
            uniform,
        }
    }

    /// The displayed radiance at point `p` of element `e` (corners `c`):
    /// display-time texture modulation. On a surface of the scene it is the
    /// surface layer's emission plus its textured `kd / pi` times the
    /// Gouraud-interpolated irradiance of the solution (solved with each
    /// patch's albedo), so a texture keeps its detail within a patch; an
    /// area light's element shows its emission. Seen from the `back`, the
    /// sidedness rule: a one-sided surface reflects nothing, and emission
    /// shows only when two-sided (elements are one-sided: a two-sided
    /// surface's back shows its front's irradiance, a listed limitation).
    fn radiance(
        &self,
        solution: &RadiositySolution,
        e: usize,
        c: &[Vec3; 3],
        p: Vec3,
        back: bool,
    ) -> Vec3 {
        let s = self.sources[e];
        let Some(uniform) = self.uniform.get(s as usize) else {
            return solution.element_emission[e];
        };
        let m = self.ps.material(self.ps.tri_material[s as usize]);
        let transmissive = m.transmit.max_element() > 0.0;
        let black = back && m.sidedness.seen_from(-1.0, transmissive) == Facing::BackBlack;
        let emits = !back || m.emission_two_sided;
        let irradiance = solution.interpolate(
            &solution.vertex_irradiance,
            e,
            clamped_weights(mesh::barycentric(c, p)),
        );
        let (kd, emission) = uniform.unwrap_or_else(|| {
            let [_, u, v] =
                clamped_weights(mesh::barycentric(&solution.source_corners[s as usize], p));
            surface(self.ps, s, u, v)
        });
        let emission = if emits { emission } else { Vec3::ZERO };
        if black {
            return emission;
        }
        emission + kd * irradiance * std::f32::consts::FRAC_1_PI
    }
}

/// `(kd, emission)` of prepared triangle `t` at barycentrics `(u, v)`, as
/// the solve and the display read it: the surface layer at the base level
/// of textures, `kd` clamped to `[0, 1]`, emission to `>= 0`.
pub(crate) fn surface(ps: &PreparedScene<'_>, t: u32, u: f32, v: f32) -> (Vec3, Vec3) {
    let (dpdu, dpdv) = ps.triangle_dpduv(t);
    let m = ps
        .shading_surface_at(
            ps.triangle_surface(t, u, v),
            dpdu,
            dpdv,
            Vec2::ZERO,
            Vec2::ZERO,
        )
        .material;
    (
        m.kd.clamp(Vec3::ZERO, Vec3::ONE),
        m.emission.max(Vec3::ZERO),
    )
}

#[cfg(test)]
mod tests;
#[cfg(test)]
mod tests_cluster;
#[cfg(test)]
mod tests_environment;
#[cfg(test)]
mod tests_hostile;
#[cfg(test)]
mod tests_memory;
