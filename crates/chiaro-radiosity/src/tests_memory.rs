//! The hierarchical solver's memory estimate (`hierarchical::memory`)
//! against what a solve held, and the budget check that refuses a solve
//! before its quadtrees, links and clusters are built.

use super::*;
use crate::tests_cluster::hierarchical_settings;
use chiaro_core::budget::ByteSize;
use chiaro_core::progress::NoProgress;
use chiaro_testkit::scenes::unit_cornell_box;

/// The estimate for `s` meshed at `patch` and the bytes the solve's nodes,
/// links and clusters held (by the solution's counts and the per-item
/// sizes), with clusters above `cluster_above` source triangles.
fn estimate_and_held(s: &Scene, patch: f32, cluster_above: usize) -> (u64, u64) {
    let r = hierarchical_settings(patch);
    let ctx = RenderContext::new(s, &r, &NoProgress).expect("context");
    let sources = mesh::source_triangles(ctx.tessellated()).len() as u64;
    let sol = solve_clustering(&ctx, true, cluster_above).expect("solve");
    let clustered = sources > cluster_above.max(1) as u64;
    let mut e = Estimate::default();
    hierarchical::memory(sources, sol.stats.elements as u64, clustered, &mut e);
    // A binary cluster tree over the sources' quadtree roots.
    let clusters = if clustered { sources - 1 } else { 0 };
    let nodes = sol.stats.nodes as u64 - clusters;
    let mut held =
        nodes * hierarchical::NODE_BYTES + sol.stats.links as u64 * hierarchical::LINK_BYTES;
    if clustered {
        held += clusters * cluster::CLUSTER_BYTES + sources * cluster::ROOT_BYTES;
    }
    eprintln!(
        "patch {patch}, clusters above {cluster_above}: {sources} sources, {} elements, {} nodes, {} links; estimate {} held {}",
        sol.stats.elements,
        sol.stats.nodes,
        sol.stats.links,
        e.total(),
        held
    );
    (e.total(), held)
}

#[test]
fn the_hierarchy_estimate_is_within_a_factor_of_what_a_solve_holds() {
    let cases = [
        (unit_cornell_box(), 0.125, usize::MAX),
        (unit_cornell_box(), 0.125, 0),
        (unit_cornell_box(), 0.25, usize::MAX),
        (
            crate::tests::furnace(0.6, Vec3::new(1.0, 0.5, 0.25)),
            0.34,
            0,
        ),
    ];
    let all: Vec<_> = cases
        .iter()
        .map(|(s, patch, above)| estimate_and_held(s, *patch, *above))
        .collect();
    for ((_, patch, above), (estimate, held)) in cases.iter().zip(all) {
        let ratio = estimate as f64 / held as f64;
        assert!(
            (1.0 / 3.0..=3.0).contains(&ratio),
            "patch {patch}, clusters above {above}: estimate {estimate} against {held} held ({ratio:.2})"
        );
    }
}

#[test]
fn a_budget_below_the_hierarchy_is_refused_before_it_is_built() {
    let s = unit_cornell_box();
    let mut r = hierarchical_settings(0.125);
    // Room for everything but the hierarchy: the render's shared estimate.
    r.memory_limit = Some(ByteSize(
        chiaro_core::context::memory_estimate(&s, &r).total() + 1024,
    ));
    let ctx = RenderContext::new(&s, &r, &NoProgress).expect("context");
    let err = solve_clustering(&ctx, true, usize::MAX).expect_err("refused");
    let msg = err.to_string();
    chiaro_testkit::assert_contains_all(&msg, &["radiosity quadtrees", "memory limit"]);
}

#[test]
fn the_up_front_estimate_counts_the_hierarchy_only_for_its_solver() {
    let s = unit_cornell_box();
    let names = |solver: Solver| {
        let mut r = hierarchical_settings(0.125);
        r.radiosity.solver = solver;
        let mut e = Estimate::default();
        solver_memory(&s, &r, &mut e);
        e.items
            .into_iter()
            .map(|(w, _)| w)
            .collect::<Vec<_>>()
            .join("; ")
    };
    let h = names(Solver::Hierarchical);
    chiaro_testkit::assert_contains_all(&h, &["radiosity quadtrees", "radiosity links"]);
    // Pairwise below the clustering threshold: no clusters.
    assert!(!h.contains("clusters"), "{h}");
    // `auto` on a small scene is progressive refinement: nothing counted.
    assert_eq!(names(Solver::Auto), "");
}
