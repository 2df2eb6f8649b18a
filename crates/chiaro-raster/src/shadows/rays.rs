//! Shadow rays from the scan converter (Appel 1968, Whitted 1980): a segment
//! from the point to the light sample against a BVH of the scene.

use chiaro_core::accel::Accelerator;
use chiaro_core::accel::alpha::AlphaTested;
use chiaro_core::accel::bvh::SceneBvh;
use chiaro_core::context::Derived;
use chiaro_core::prepared::PreparedScene;
use chiaro_core::shading::LightSample;
use chiaro_core::shadow::ShadowCasters;
use glam::Vec3;
use std::sync::Arc;

/// Shadow rays against a BVH of the scene's triangles.
pub(crate) struct RayShadows {
    /// The BVH, alpha-tested when the scene has masked materials.
    bvh: Arc<ShadowBvh>,
    casters: ShadowCasters,
}

/// The BVH of [`shadow_bvh`], as a render context keeps it
/// ([`chiaro_core::context::Derived`]).
pub(crate) struct ShadowBvh(Box<dyn Accelerator>);

/// The scene's BVH; shadow rays pass through cut-out texels of masked materials.
pub(crate) fn shadow_bvh(ps: &PreparedScene<'_>) -> Box<dyn Accelerator> {
    AlphaTested::wrap(ps, Box::new(SceneBvh::new(ps)))
}

impl RayShadows {
    pub(crate) fn new(ps: &PreparedScene<'_>) -> Self {
        Self {
            bvh: Arc::new(ShadowBvh(shadow_bvh(ps))),
            casters: ShadowCasters::new(ps),
        }
    }

    /// [`Self::new`] with the BVH kept in `derived` (built there once).
    pub(crate) fn kept(ps: &PreparedScene<'_>, derived: &Derived) -> Self {
        Self {
            bvh: derived.get_or_build(|| ShadowBvh(shadow_bvh(ps))),
            casters: ShadowCasters::new(ps),
        }
    }

    /// Shadow rays that see only the transparent casters (`None` when
    /// there are none): the tint that shadow volumes cannot count. The BVH
    /// is kept in `derived`.
    pub(crate) fn transparent_only(ps: &PreparedScene<'_>, derived: &Derived) -> Option<Self> {
        let casters = ShadowCasters::new(ps).transparent_only()?;
        Some(Self {
            bvh: derived.get_or_build(|| ShadowBvh(shadow_bvh(ps))),
            casters,
        })
    }

    /// RGB transmittance from `p` (unit geometric normal `ng`) to the
    /// sample, by the shared query of [`chiaro_core::shadow`] (the Whitted
    /// tracer's): 0 behind an opaque caster, the product of the transmit
    /// colours of the transparent surfaces crossed otherwise.
    pub(crate) fn visibility(&self, p: Vec3, ng: Vec3, s: &LightSample) -> Vec3 {
        self.casters
            .light_transmittance(&*self.bvh.0, p, ng, s, &mut 0)
    }
}
