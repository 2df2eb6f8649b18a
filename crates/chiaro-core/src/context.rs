//! The technique interface: every technique renders one [`RenderContext`]
//! (the validated scene and settings, the prepared scenes and their
//! accelerators, built once and on demand, progress and cancellation)
//! through the one method of [`Renderer`], in the manner of pbrt-v4's
//! `Integrator` over its `Scene` and Tungsten's `TraceableScene`.
//!
//! Settings are validated here and nowhere else ([`RenderSettings::validate`]
//! with [`Scene::validate_with`]); a technique takes what the context holds
//! as given.
//!
//! The camera is the context's ([`RenderContext::camera`]: the scene's
//! unless [`RenderContext::with_camera`] moves it), so that an interactive
//! front renders frame after frame of one scene, and a [`FrameCache`] keeps
//! what does not depend on the camera (the prepared scenes, their
//! accelerators, mip-maps and prefiltered environment, the radiosity
//! solution) from one frame's context to the next.

use crate::accel::Accelerator;
use crate::budget::{Estimate, MemoryBudget, bytes_of};
use crate::error::{CoreError, Result};
use crate::film::Film;
use crate::geometry::primitives::MeshSize;
use crate::geometry::tessellation::{FIXED_SEGMENTS, ProjectedView, Tessellation};
use crate::prepared::{PrepareOptions, PreparedScene, sphere_in_world};
use crate::progress::Progress;
use crate::scene::{
    Camera, Geometry, Issue, RadiositySettings, RenderSettings, Scene, Severity, ShadowMethod,
    Technique, Texture,
};
use crate::technique::Description;
use std::any::Any;
use std::sync::{Arc, Mutex, OnceLock};
use std::time::{Duration, Instant};

/// Statistics of one render.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct RenderStats {
    /// Wall-clock time from the context's creation (excluding file I/O).
    pub elapsed: Duration,
    /// Triangles in the scene.
    pub triangles: u64,
    /// Rays traced, where the technique counts them (0 otherwise).
    pub rays: u64,
    /// Of `rays`, those from the camera (Whitted counts them; 0 otherwise).
    pub camera_rays: u64,
}

/// A technique: renders the context's scene with its settings. `aa =
/// "post"` is the facade's filter after the render; a renderer called with
/// it directly supersamples.
pub trait Renderer: Sync {
    /// Renders `ctx`. Returns the film (linear radiance, depth and normal
    /// buffers) and the render's statistics.
    ///
    /// # Errors
    /// [`CoreError::Cancelled`] when the progress asks to stop;
    /// [`CoreError::Unsupported`] for what the technique cannot render.
    fn render(&self, ctx: &RenderContext<'_>) -> Result<(Film, RenderStats)>;

    /// The techniques this renderer draws, each described: what it is,
    /// shows and cannot show.
    fn descriptions(&self) -> &'static [Description];

    /// The technique's own settings checks, beyond those every render has
    /// ([`RenderSettings::validate`]).
    fn check_settings(&self, _settings: &RenderSettings) -> Vec<Issue> {
        Vec::new()
    }

    /// Adds what the technique allocates beyond what every render does
    /// ([`memory_estimate`]) to `estimate`, without allocating it.
    fn memory(&self, _scene: &Scene, _settings: &RenderSettings, _estimate: &mut Estimate) {}
}

/// Builds the accelerator over a prepared scene.
pub type AccelBuilder<'f> = dyn Fn(&PreparedScene<'_>) -> Box<dyn Accelerator> + Sync + 'f;

/// The context's slot for a view-independent solution (radiosity's),
/// shared by the contexts [`RenderContext::with_settings`] derives.
type SolutionSlot = Arc<OnceLock<Arc<dyn Any + Send + Sync>>>;

/// A prepared scene's slot, shared by the contexts of one scene that
/// prepare it alike (a [`FrameCache`], [`RenderContext::with_settings`]).
type PreparedSlot<'a> = Arc<OnceLock<PreparedScene<'a>>>;

/// An accelerator's slot, shared as its prepared scene's.
type AccelSlot = Arc<OnceLock<Box<dyn Accelerator>>>;

/// What a technique derives from a prepared scene alone (neither the
/// camera nor the settings: the scan converter's shadow-ray BVH, which
/// objects are closed), one value per type, kept and shared with the
/// prepared scene ([`RenderContext::tessellated_derived`]).
#[derive(Default)]
pub struct Derived(Mutex<Vec<Arc<dyn Any + Send + Sync>>>);

impl std::fmt::Debug for Derived {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Derived").finish_non_exhaustive()
    }
}

impl Derived {
    /// The value of type `T` kept, else `build()`'s, kept from now on.
    /// `build` runs outside the lock (it may use rayon; see
    /// `init_outside`); two threads may both build, one value is kept.
    pub fn get_or_build<T: Any + Send + Sync>(&self, build: impl FnOnce() -> T) -> Arc<T> {
        if let Some(v) = self.find::<T>() {
            return v;
        }
        let built = Arc::new(build());
        let mut all = self.0.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(v) = all.iter().find_map(|v| Arc::clone(v).downcast::<T>().ok()) {
            return v;
        }
        all.push(Arc::clone(&built) as Arc<dyn Any + Send + Sync>);
        built
    }

    fn find<T: Any + Send + Sync>(&self) -> Option<Arc<T>> {
        let all = self.0.lock().unwrap_or_else(|e| e.into_inner());
        all.iter().find_map(|v| Arc::clone(v).downcast::<T>().ok())
    }
}

/// The tessellated prepared scene's slots: the scene, its accelerator and
/// what techniques derive from it.
type TessellatedSlots<'a> = (PreparedSlot<'a>, AccelSlot, Arc<Derived>);

/// One render's validated inputs and the state every technique shares,
/// prepared lazily: the flattened scene with analytic spheres (ray tracers)
/// or tessellated spheres (scan conversion, radiosity), each with its ray
/// accelerator.
pub struct RenderContext<'a> {
    scene: &'a Scene,
    settings: RenderSettings,
    camera: Camera,
    progress: &'a dyn Progress,
    start: Instant,
    make_accel: &'a AccelBuilder<'a>,
    /// Whether `make_accel` is the default builder (the accelerators a
    /// [`FrameCache`] keeps are the default's).
    default_accel: bool,
    analytic: PreparedSlot<'a>,
    analytic_accel: AccelSlot,
    tessellated: PreparedSlot<'a>,
    tessellated_accel: AccelSlot,
    tessellated_derived: Arc<Derived>,
    solution: SolutionSlot,
}

/// What the contexts of one scene build that does not depend on the camera,
/// kept from one frame's context to the next ([`RenderContext::with_cache`]),
/// each piece with what it depends on: the flattened scene with analytic
/// spheres and its accelerator (the scene alone), the one with tessellated
/// spheres and its accelerator (the spheres' segment counts, which follow
/// the view for the scan converter), and the radiosity solution (the
/// radiosity settings). The prepared scenes carry their texture mip-maps and
/// prefiltered environment. A context of another scene (not the same
/// object) starts the cache afresh; the scene cannot change while the cache
/// borrows it.
#[derive(Default)]
pub struct FrameCache<'a> {
    scene: Option<&'a Scene>,
    analytic: Option<((), (PreparedSlot<'a>, AccelSlot))>,
    tessellated: Option<(Vec<u32>, TessellatedSlots<'a>)>,
    solution: Option<(RadiositySettings, SolutionSlot)>,
    misses: u64,
}

impl std::fmt::Debug for FrameCache<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FrameCache")
            .field("analytic", &self.analytic.is_some())
            .field("tessellated", &self.tessellated.as_ref().map(|(k, _)| k))
            .field("solution", &self.solution.is_some())
            .field("misses", &self.misses)
            .finish()
    }
}

impl<'a> FrameCache<'a> {
    /// An empty cache (as [`Default`]).
    pub fn new() -> Self {
        Self::default()
    }

    /// How many times a context found a piece missing or built for other
    /// inputs and started it afresh (the first frame's pieces included).
    pub fn misses(&self) -> u64 {
        self.misses
    }

    /// Whether the cache holds a radiosity solution solved with `radiosity`.
    pub fn holds_solution(&self, radiosity: &RadiositySettings) -> bool {
        self.solution
            .as_ref()
            .is_some_and(|(k, slot)| k == radiosity && slot.get().is_some())
    }

    /// The slot kept under `key` in `entry`, or a fresh one kept from now on.
    fn slot<K: PartialEq, T: Default + Clone>(
        entry: &mut Option<(K, T)>,
        key: K,
        misses: &mut u64,
    ) -> T {
        match entry {
            Some((k, slot)) if *k == key => slot.clone(),
            _ => {
                *misses += 1;
                let slot = T::default();
                *entry = Some((key, slot.clone()));
                slot
            }
        }
    }
}

/// A piece a [`FrameCache`] keeps between frames.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CachedPiece {
    /// The prepared scene with analytic spheres and its accelerator
    /// (preview, Whitted, path, hybrid's ray tracing).
    Analytic,
    /// The prepared scene with tessellated spheres, its accelerator and
    /// what techniques derive from it (scan conversion, radiosity).
    Tessellated,
    /// The radiosity solution (radiosity, hybrid).
    Solution,
}

impl CachedPiece {
    /// Every piece, in the order [`FrameCache::evict_unused`] drops them.
    pub const ALL: [Self; 3] = [Self::Solution, Self::Tessellated, Self::Analytic];

    /// Whether a frame of `technique` reads this piece.
    pub fn used_by(self, technique: Technique) -> bool {
        use Technique as T;
        match self {
            Self::Analytic => matches!(technique, T::Preview | T::Whitted | T::Path | T::Hybrid),
            Self::Tessellated => !matches!(technique, T::Preview | T::Whitted | T::Path),
            Self::Solution => technique.solves_radiosity(),
        }
    }

    /// The piece's name in messages.
    pub fn name(self) -> &'static str {
        match self {
            Self::Analytic => "prepared scene and BVH (analytic spheres)",
            Self::Tessellated => "prepared scene and BVH (tessellated spheres)",
            Self::Solution => "radiosity solution",
        }
    }
}

/// The bytes a prepared scene and its accelerator hold, by the budget's
/// per-triangle and per-vertex sizes (which include the BVH), with its
/// texture mip levels as [`memory_estimate`] counts them.
pub fn prepared_bytes(ps: &PreparedScene<'_>) -> u64 {
    let texels: u64 = ps
        .scene
        .textures
        .iter()
        .map(|t| match t {
            Texture::Image(i) => u64::from(i.width) * u64::from(i.height),
            Texture::Procedural(_) => 0,
        })
        .sum();
    bytes_of(
        ps.triangles.len() as u64,
        crate::budget::PREPARED_TRIANGLE_BYTES,
    )
    .saturating_add(bytes_of(
        ps.positions.len() as u64,
        crate::budget::PREPARED_VERTEX_BYTES,
    ))
    .saturating_add(bytes_of(texels, 16) / 3)
}

impl FrameCache<'_> {
    /// The pieces built and held, each with an estimate of its bytes:
    /// prepared scenes by [`prepared_bytes`], the solution by
    /// `solution_bytes` (the core does not know its type; the facade
    /// measures a radiosity solution).
    pub fn held(
        &self,
        solution_bytes: impl Fn(&(dyn Any + Send + Sync)) -> u64,
    ) -> Vec<(CachedPiece, u64)> {
        let mut held = Vec::new();
        let prepared = |slot: &PreparedSlot<'_>| slot.get().map(prepared_bytes);
        if let Some(b) = self.analytic.as_ref().and_then(|(_, (p, _))| prepared(p)) {
            held.push((CachedPiece::Analytic, b));
        }
        if let Some(b) = self
            .tessellated
            .as_ref()
            .and_then(|(_, (p, _, _))| prepared(p))
        {
            held.push((CachedPiece::Tessellated, b));
        }
        if let Some(b) = self
            .solution
            .as_ref()
            .and_then(|(_, slot)| slot.get())
            .map(|s| solution_bytes(s.as_ref()))
        {
            held.push((CachedPiece::Solution, b));
        }
        held
    }

    /// Drops `piece` (the next frame that reads it builds it again).
    pub fn evict(&mut self, piece: CachedPiece) {
        match piece {
            CachedPiece::Analytic => self.analytic = None,
            CachedPiece::Tessellated => self.tessellated = None,
            CachedPiece::Solution => self.solution = None,
        }
    }

    /// Makes room for a frame of `technique` that needs `frame_bytes` of
    /// its own within `budget`: while what the cache holds and the frame
    /// does not read, added to `frame_bytes`, exceeds the budget, drops
    /// those pieces (in [`CachedPiece::ALL`]'s order). Returns each piece
    /// dropped with its bytes, for the front to say so.
    pub fn evict_unused(
        &mut self,
        technique: Technique,
        frame_bytes: u64,
        budget: MemoryBudget,
        solution_bytes: impl Fn(&(dyn Any + Send + Sync)) -> u64,
    ) -> Vec<(CachedPiece, u64)> {
        let idle: Vec<(CachedPiece, u64)> = self
            .held(solution_bytes)
            .into_iter()
            .filter(|(piece, _)| !piece.used_by(technique))
            .collect();
        let mut total = idle
            .iter()
            .fold(frame_bytes, |t, (_, b)| t.saturating_add(*b));
        let mut dropped = Vec::new();
        for piece in CachedPiece::ALL {
            if total <= budget.limit.0 {
                break;
            }
            if let Some(&(_, b)) = idle.iter().find(|(p, _)| *p == piece) {
                self.evict(piece);
                total = total.saturating_sub(b);
                dropped.push((piece, b));
            }
        }
        dropped
    }
}

/// `cell`'s value, computed by `build` outside the lock when the cell is
/// empty: the builds use rayon, and a rayon worker blocked in
/// `OnceLock::get_or_init` while another thread's build waits on the jobs
/// queued behind it deadlocks. Two threads may both build; one value is kept.
fn init_outside<T>(cell: &OnceLock<T>, build: impl FnOnce() -> T) -> &T {
    if let Some(v) = cell.get() {
        return v;
    }
    let v = build();
    cell.get_or_init(|| v)
}

impl std::fmt::Debug for RenderContext<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RenderContext")
            .field("technique", &self.settings.technique)
            .field("width", &self.settings.width)
            .field("height", &self.settings.height)
            .finish_non_exhaustive()
    }
}

impl<'a> RenderContext<'a> {
    /// Validates `scene` rendered with `settings` (which replace
    /// `scene.render`). Every error found is reported at once; warnings
    /// about the settings go to `progress`. The memory budget depends on
    /// the technique too ([`Renderer::memory`]): the facade checks it
    /// before a renderer runs, as it checks the technique's own settings.
    ///
    /// # Errors
    /// [`CoreError::InvalidScene`] listing every error, each naming its
    /// setting or scene item.
    pub fn new(
        scene: &'a Scene,
        settings: &RenderSettings,
        progress: &'a dyn Progress,
    ) -> Result<Self> {
        let mut errors = Vec::new();
        for issue in scene.validate_with(settings) {
            match issue.severity {
                Severity::Error => errors.push(issue.to_string()),
                Severity::Warning if issue.path.starts_with("render") => {
                    progress.warning(&format!("{}: {}", issue.path, issue.message));
                }
                Severity::Warning => {}
            }
        }
        if !errors.is_empty() {
            return Err(CoreError::InvalidScene { issues: errors });
        }
        Ok(Self {
            scene,
            settings: settings.clone(),
            camera: scene.camera,
            progress,
            start: Instant::now(),
            make_accel: &crate::accel::instanced::build_accelerator,
            default_accel: true,
            analytic: PreparedSlot::default(),
            analytic_accel: AccelSlot::default(),
            tessellated: PreparedSlot::default(),
            tessellated_accel: AccelSlot::default(),
            tessellated_derived: Arc::default(),
            solution: SolutionSlot::default(),
        })
    }

    /// The same context with `settings` changed by `f` (validated again),
    /// for a render that derives its settings from another's (one sample
    /// per pixel before a post filter). Both share the camera and the
    /// analytic prepared scene; the tessellated one while the spheres'
    /// segments stay, the solution while `f` leaves `settings.radiosity` as
    /// it is.
    ///
    /// # Errors
    /// As [`Self::new`].
    pub fn with_settings(&self, f: impl FnOnce(&mut RenderSettings)) -> Result<Self> {
        let mut settings = self.settings.clone();
        f(&mut settings);
        let mut ctx = Self::new(self.scene, &settings, self.progress)?;
        ctx.camera = self.camera;
        ctx.make_accel = self.make_accel;
        ctx.default_accel = self.default_accel;
        ctx.analytic = Arc::clone(&self.analytic);
        ctx.analytic_accel = Arc::clone(&self.analytic_accel);
        if ctx.sphere_segments() == self.sphere_segments() {
            ctx.tessellated = Arc::clone(&self.tessellated);
            ctx.tessellated_accel = Arc::clone(&self.tessellated_accel);
            ctx.tessellated_derived = Arc::clone(&self.tessellated_derived);
        }
        if settings.radiosity == self.settings.radiosity {
            ctx.solution = Arc::clone(&self.solution);
        }
        Ok(ctx)
    }

    /// The context seen through `camera` instead of the scene's (a frame of
    /// an interactive session: only the view moves). Call it before
    /// [`Self::with_cache`], whose tessellated scene follows the camera.
    pub fn with_camera(mut self, camera: Camera) -> Self {
        if camera != self.camera {
            self.camera = camera;
            self.tessellated = PreparedSlot::default();
            self.tessellated_accel = AccelSlot::default();
            self.tessellated_derived = Arc::default();
        }
        self
    }

    /// The context taking from `cache` what an earlier context of the same
    /// scene built that this one would build alike, and leaving in it what
    /// this one builds ([`FrameCache`]). Pictures are those of a context
    /// without a cache, bit for bit.
    pub fn with_cache(mut self, cache: &mut FrameCache<'a>) -> Self {
        if !cache.scene.is_some_and(|s| std::ptr::eq(s, self.scene)) {
            let misses = cache.misses;
            *cache = FrameCache {
                scene: Some(self.scene),
                misses,
                ..FrameCache::default()
            };
        }
        let misses = &mut cache.misses;
        if self.default_accel {
            (self.analytic, self.analytic_accel) =
                FrameCache::slot(&mut cache.analytic, (), misses);
            (
                self.tessellated,
                self.tessellated_accel,
                self.tessellated_derived,
            ) = FrameCache::slot(&mut cache.tessellated, self.sphere_segments(), misses);
        }
        if self.settings.technique.solves_radiosity() && self.solution.get().is_none() {
            self.solution =
                FrameCache::slot(&mut cache.solution, self.settings.radiosity.clone(), misses);
        }
        self
    }

    /// The segments of each sphere of the scene as [`Self::tessellated`]
    /// cuts it: what that prepared scene depends on besides the scene.
    fn sphere_segments(&self) -> Vec<u32> {
        let t = tessellation_from(&self.camera, &self.settings);
        self.scene
            .objects
            .iter()
            .filter_map(|obj| match obj.geometry {
                Geometry::Sphere { radius } => {
                    let (center, r) = sphere_in_world(obj.transform.world_from_object(), radius);
                    Some(t.sphere_segments(center, r))
                }
                Geometry::Mesh(_) => None,
            })
            .collect()
    }

    /// The context with a view-independent solution given rather than
    /// solved (one loaded from a file, or kept by the viewer between
    /// frames). The technique that reads it checks it belongs to the scene.
    pub fn with_solution<T: Any + Send + Sync>(mut self, solution: Arc<T>) -> Self {
        let slot = OnceLock::new();
        let _ = slot.set(solution as Arc<dyn Any + Send + Sync>);
        self.solution = Arc::new(slot);
        self
    }

    /// The context's view-independent solution (radiosity's): the one
    /// given to [`Self::with_solution`] or solved before, else `solve`d
    /// now and kept, as the prepared scenes are.
    ///
    /// # Errors
    /// What `solve` returns; [`CoreError::Unsupported`] when the context
    /// holds a solution of another type.
    pub fn solution<T: Any + Send + Sync>(
        &self,
        solve: impl FnOnce(&Self) -> Result<T>,
    ) -> Result<Arc<T>> {
        if self.solution.get().is_none() {
            let solved = Arc::new(solve(self)?);
            let _ = self.solution.set(solved);
        }
        self.solved().ok_or_else(|| {
            CoreError::Unsupported("the context holds another kind of solution".into())
        })
    }

    /// The solution held, if one was given or solved, without solving.
    pub fn solved<T: Any + Send + Sync>(&self) -> Option<Arc<T>> {
        self.solution
            .get()
            .and_then(|s| Arc::clone(s).downcast::<T>().ok())
    }

    /// Uses `make` instead of the BVH to build the ray accelerators (the
    /// brute-force list in tests).
    pub fn with_accelerator(mut self, make: &'a AccelBuilder<'a>) -> Self {
        self.make_accel = make;
        self.default_accel = false;
        self.analytic_accel = AccelSlot::default();
        self.tessellated_accel = AccelSlot::default();
        self
    }

    /// The scene.
    pub fn scene(&self) -> &'a Scene {
        self.scene
    }

    /// The validated settings.
    pub fn settings(&self) -> &RenderSettings {
        &self.settings
    }

    /// The camera: the scene's, or the one given to [`Self::with_camera`].
    /// Techniques read the view from here, never from the scene.
    pub fn camera(&self) -> &Camera {
        &self.camera
    }

    /// Progress, warnings and cancellation.
    pub fn progress(&self) -> &'a dyn Progress {
        self.progress
    }

    /// The scene flattened for the ray tracers: spheres stay analytic.
    pub fn analytic(&self) -> &PreparedScene<'a> {
        init_outside(&self.analytic, || {
            PreparedScene::new(
                self.scene,
                PrepareOptions {
                    analytic_spheres: true,
                    ..PrepareOptions::default()
                },
            )
        })
    }

    /// The ray accelerator over [`Self::analytic`].
    pub fn analytic_accel(&self) -> &dyn Accelerator {
        init_outside(&self.analytic_accel, || (self.make_accel)(self.analytic())).as_ref()
    }

    /// The scene flattened for scan conversion and radiosity: spheres
    /// tessellated as the technique asks ([`tessellation`]).
    pub fn tessellated(&self) -> &PreparedScene<'a> {
        init_outside(&self.tessellated, || {
            PreparedScene::new(
                self.scene,
                PrepareOptions {
                    analytic_spheres: false,
                    tessellation: tessellation_from(&self.camera, &self.settings),
                },
            )
        })
    }

    /// The ray accelerator over [`Self::tessellated`].
    pub fn tessellated_accel(&self) -> &dyn Accelerator {
        init_outside(&self.tessellated_accel, || {
            (self.make_accel)(self.tessellated())
        })
        .as_ref()
    }

    /// What techniques derive from [`Self::tessellated`] alone, kept with
    /// it (in a [`FrameCache`] too).
    pub fn tessellated_derived(&self) -> &Derived {
        &self.tessellated_derived
    }

    /// Whether the progress asks to stop.
    pub fn cancelled(&self) -> bool {
        self.progress.cancelled()
    }

    /// The statistics of a render that traced `rays` rays.
    pub fn stats(&self, rays: u64) -> RenderStats {
        RenderStats {
            elapsed: self.start.elapsed(),
            triangles: self.scene.triangle_count() as u64,
            rays,
            camera_rays: 0,
        }
    }
}

/// How `settings`' technique tessellates analytic primitives: radiosity and
/// the hybrid with [`FIXED_SEGMENTS`] (their solutions, saved and reused,
/// must not depend on the view), the scan converter by each primitive's
/// projected size in the camera's image.
pub fn tessellation(scene: &Scene, settings: &RenderSettings) -> Tessellation {
    tessellation_from(&scene.camera, settings)
}

/// [`tessellation`] seen from `camera` rather than the scene's.
fn tessellation_from(camera: &Camera, settings: &RenderSettings) -> Tessellation {
    if settings.technique.solves_radiosity() {
        Tessellation::Fixed(FIXED_SEGMENTS)
    } else {
        Tessellation::Projected(ProjectedView::new(camera, settings.height))
    }
}

/// The triangles of `scene`'s meshes, and of its spheres once tessellated
/// by `tessellation`, without tessellating them.
fn triangle_counts(scene: &Scene, tessellation: Tessellation) -> (MeshSize, MeshSize) {
    let mut meshes = MeshSize {
        vertices: 0,
        triangles: 0,
    };
    let mut spheres = MeshSize {
        vertices: 0,
        triangles: 0,
    };
    for obj in &scene.objects {
        let s = match obj.geometry {
            Geometry::Mesh(id) => match scene.meshes.get(id.index()) {
                Some(m) => MeshSize::of(m),
                None => continue,
            },
            Geometry::Sphere { radius } => {
                let (center, r) = sphere_in_world(obj.transform.world_from_object(), radius);
                let slices = tessellation.sphere_segments(center, r);
                let s = MeshSize::uv_sphere(slices, slices / 2);
                spheres.vertices = spheres.vertices.saturating_add(s.vertices);
                spheres.triangles = spheres.triangles.saturating_add(s.triangles);
                continue;
            }
        };
        meshes.vertices = meshes.vertices.saturating_add(s.vertices);
        meshes.triangles = meshes.triangles.saturating_add(s.triangles);
    }
    (meshes, spheres)
}

/// Triangles of the scene as `settings`' technique tessellates it (meshes
/// and tessellated spheres, [`tessellation`]).
pub fn tessellated_triangles(scene: &Scene, settings: &RenderSettings) -> u64 {
    let (meshes, spheres) = triangle_counts(scene, tessellation(scene, settings));
    meshes.triangles.saturating_add(spheres.triangles)
}

/// What every render of `scene` with `settings` allocates, by consumer, in
/// bytes: the prepared triangles and vertices (with the spheres the scan
/// converter and radiosity tessellate), texture mip levels, the film, and
/// shadow maps (up to their share of the budget,
/// [`crate::budget::MemoryBudget::shadow_map_bytes`]). A technique adds
/// its own ([`Renderer::memory`]: the scan converter's supersamples, a
/// dense radiosity matrix). The per-item sizes are the constants of
/// [`crate::budget`]; the sum is an estimate of the peak, made without
/// allocating anything.
pub fn memory_estimate(scene: &Scene, settings: &RenderSettings) -> Estimate {
    let analytic = matches!(
        settings.technique,
        Technique::Preview | Technique::Whitted | Technique::Path
    );
    let (meshes, sphere) = triangle_counts(scene, tessellation(scene, settings));
    let spheres = scene
        .objects
        .iter()
        .filter(|o| matches!(o.geometry, Geometry::Sphere { .. }))
        .count();
    let mut e = Estimate::default();
    e.add(
        format!("{} mesh triangles", meshes.triangles),
        meshes.prepared_bytes(),
    );
    if !analytic {
        e.add(
            format!(
                "{spheres} tessellated spheres ({} triangles)",
                sphere.triangles
            ),
            sphere.prepared_bytes(),
        );
    }
    let texels: u64 = scene
        .textures
        .iter()
        .map(|t| match t {
            Texture::Image(i) => u64::from(i.width) * u64::from(i.height),
            Texture::Procedural(_) => 0,
        })
        .sum();
    // Mip levels: a third of the texels again, RGBA f32.
    e.add("texture mip levels", bytes_of(texels, 16) / 3);
    let pixels = u64::from(settings.width) * u64::from(settings.height);
    // Colour, depth and normal a pixel.
    e.add("film", bytes_of(pixels, 28));
    if settings.shadows == ShadowMethod::Map {
        // Up to six depth faces of f32 per light; lights past the shadow-map
        // share of the budget use shadow rays instead, so no more than it.
        let r = u64::from(settings.shadow_map.resolution);
        let lights = scene.lights.len() as u64;
        e.add(
            "shadow maps",
            bytes_of(r * r * 6, 4)
                .saturating_mul(lights)
                .min(settings.memory_budget().shadow_map_bytes()),
        );
    }
    e
}
