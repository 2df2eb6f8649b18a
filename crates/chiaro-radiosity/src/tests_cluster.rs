//! The clustered hierarchical solver (`cluster.rs`) on small scenes, with
//! clustering forced: the furnace, agreement with the pairwise hierarchical
//! solution on the Cornell box, and cancellation.

use super::*;
use chiaro_core::progress::NoProgress;
use chiaro_testkit::scenes::unit_cornell_box;
use std::sync::atomic::{AtomicU32, Ordering};

/// Hierarchical radiosity with ray-cast form factors and elements of
/// `patch` size; `cluster_above` source triangles switch clustering on.
fn solve_hierarchical(
    s: &Scene,
    patch: f32,
    cluster_above: usize,
    progress: &dyn Progress,
) -> Result<RadiositySolution, CoreError> {
    let r = hierarchical_settings(patch);
    solve_clustering(&RenderContext::new(s, &r, progress)?, true, cluster_above)
}

/// Hierarchical ray-cast settings at 32x32 with elements of `patch` size.
pub(crate) fn hierarchical_settings(patch: f32) -> RenderSettings {
    let mut r = RenderSettings {
        width: 32,
        height: 32,
        ..Default::default()
    };
    r.radiosity.solver = Solver::Hierarchical;
    r.radiosity.patch_size = patch;
    r
}

#[test]
fn clustered_furnace_gives_e_over_one_minus_rho() {
    let rho = 0.6f32;
    let e = Vec3::new(1.0, 0.5, 0.25);
    let s = crate::tests::furnace(rho, e);
    let expect = e / (1.0 - rho);
    let sol = solve_hierarchical(&s, 0.34, 0, &NoProgress).expect("solve");
    assert!(sol.stats.nodes > sol.stats.leaves, "no clusters");
    // Power in equals power out: the area-weighted mean within 2 %, every
    // element within 5 %.
    let l = sol.element_radiance();
    let mean = l.iter().fold(Vec3::ZERO, |a, b| a + *b) / l.len() as f32;
    let err = ((mean - expect) / expect).abs().max_element();
    assert!(err < 0.02, "mean {mean} vs {expect}");
    for (i, x) in l.iter().enumerate() {
        let err = ((*x - expect) / expect).abs().max_element();
        assert!(err < 0.05, "element {i}: {x} vs {expect}");
    }
}

#[test]
fn clustered_cornell_box_agrees_with_the_pairwise_solution() {
    let s = unit_cornell_box();
    let pairwise = solve_hierarchical(&s, 0.125, usize::MAX, &NoProgress).expect("pairwise");
    let clustered = solve_hierarchical(&s, 0.125, 0, &NoProgress).expect("clustered");
    assert!(clustered.stats.links > 0);
    // Each object's mean radiance within 3 % (under 2 % measured; 7 %
    // darker on the blocks when links from clusters whose sampled rays
    // were all blocked were dropped), and no element off by more than 15 %
    // of the brightest reflecting one.
    for o in 0..7 {
        let (a, b) = (
            pairwise.object_mean_radiance(o).expect("object"),
            clustered.object_mean_radiance(o).expect("object"),
        );
        let err = ((b - a) / a.max(Vec3::splat(1e-6))).abs().max_element();
        assert!(err < 0.03, "object {o}: clustered {b} vs pairwise {a}");
    }
    let (la, lb) = (pairwise.element_radiance(), clustered.element_radiance());
    let bright = la
        .iter()
        .zip(pairwise.element_emission())
        .filter(|(_, e)| **e == Vec3::ZERO)
        .map(|(l, _)| l.max_element())
        .fold(0.0f32, f32::max);
    for (i, (a, b)) in la.iter().zip(lb).enumerate() {
        assert!(
            (*a - *b).abs().max_element() < 0.15 * bright,
            "element {i}: clustered {b} vs pairwise {a}"
        );
    }
}

/// Cancels at its `n`th poll.
struct CancelAt(AtomicU32, u32);

impl Progress for CancelAt {
    fn begin(&self, _stage: &str, _total: u64) {}
    fn advance(&self, _n: u64) {}
    fn cancelled(&self) -> bool {
        self.0.fetch_add(1, Ordering::Relaxed) + 1 >= self.1
    }
}

#[test]
fn a_clustered_solve_can_be_cancelled() {
    let s = unit_cornell_box();
    // Count the polls of a whole solve, then cancel at several of them
    // (most of them are the clustered solver's).
    let count = CancelAt(AtomicU32::new(0), u32::MAX);
    solve_hierarchical(&s, 0.125, 0, &count).expect("solve");
    let polls = count.0.load(Ordering::Relaxed);
    assert!(polls > 8, "{polls} polls");
    for n in [1, polls / 2, polls * 3 / 4, polls] {
        let r = solve_hierarchical(&s, 0.125, 0, &CancelAt(AtomicU32::new(0), n));
        assert!(matches!(r, Err(CoreError::Cancelled)), "at poll {n}");
    }
}
