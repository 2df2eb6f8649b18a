//! What every radiosity solver shares: its output and the stop criterion.
//!
//! All solvers ([`crate::gathering`]: Jacobi and Gauss-Seidel;
//! [`crate::progressive`]: progressive refinement; [`crate::hierarchical`])
//! solve the radiosity equation in *radiance* units (see the
//! crate docs): `L_j = E_j + rho_j sum_i F_ji L_i`, with `E_j` the emitted
//! radiance plus the reflected direct light of point-like lights. The stop
//! criterion is the same for all: the *unshot fraction*
//! `sum_j A_j |dL_j|_1 / sum_j A_j |E_j|_1`, i.e. the power still to be
//! distributed (the last update for the iterative solvers, the unshot
//! radiosity for shooting) over the emitted power.

use crate::mesh::Element;
use glam::Vec3;

/// What a solver returns.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct SolveOutput {
    /// Radiance of each element.
    pub l: Vec<Vec3>,
    /// Iterations (sweeps or shots).
    pub iterations: u32,
    /// The final unshot fraction.
    pub unshot: f32,
    /// Why the solver stopped.
    pub stop: Stop,
    /// The element holding the most unshot power when it stopped (the
    /// most recently changed one for the iterative solvers).
    pub worst: usize,
}

impl SolveOutput {
    /// Radiance `l` before any iteration: converged, nothing unshot (the
    /// start of every solver, and its result when nothing emits).
    pub(crate) fn start(l: Vec<Vec3>) -> Self {
        Self {
            l,
            iterations: 0,
            unshot: 0.0,
            stop: Stop::Converged,
            worst: 0,
        }
    }
}

/// The power `sum_j A_j |v_j|_1` of a radiance vector over the elements
/// (the numerator and denominator of the unshot fraction).
pub(crate) fn power(elements: &[Element], v: &[Vec3]) -> f32 {
    elements
        .iter()
        .zip(v)
        .map(|(e, x)| e.area * x.abs().element_sum())
        .sum()
}

/// Why a solver stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub(crate) enum Stop {
    /// The unshot fraction fell below the tolerance.
    #[default]
    Converged,
    /// `max_iterations` sweeps or shots were spent first.
    Budget,
    /// The unshot fraction stopped falling (light trapped between
    /// coincident faces, or an albedo of 1 in a closed scene).
    Stalled,
    /// The unshot fraction became infinite or NaN.
    Diverged,
}

/// Sweeps or shots over which the unshot fraction must fall by
/// [`STALL_DROP`] (relative) at least once, in addition to one per
/// shooting patch (a progressive solve needs about one shot per patch to
/// make progress everywhere).
pub(crate) const STALL_WINDOW: u32 = 64;
/// The relative fall of the unshot fraction that counts as progress.
pub(crate) const STALL_DROP: f32 = 0.01;

/// The stop criterion every solver shares: below the tolerance, out of the
/// iteration budget, no progress for a window of iterations, or not
/// finite. Counts iterations only, never time, so a solve is deterministic.
#[derive(Debug, Clone)]
pub(crate) struct Stopper {
    tol: f32,
    max_iter: u32,
    window: u32,
    best: f32,
    since_best: u32,
    iterations: u32,
}

impl Stopper {
    /// A criterion for tolerance `tol` and at most `max_iter` iterations;
    /// `window` iterations without a fall of [`STALL_DROP`] is a stall.
    pub fn new(tol: f32, max_iter: u32, window: u32) -> Self {
        Self {
            tol,
            max_iter,
            window: window.max(1),
            best: f32::INFINITY,
            since_best: 0,
            iterations: 0,
        }
    }

    /// Records the unshot fraction with `done` iterations (sweeps or shots)
    /// performed; returns why to stop, or `None` to go on.
    pub fn check(&mut self, unshot: f32, done: u32) -> Option<Stop> {
        self.iterations = done;
        if !unshot.is_finite() {
            return Some(Stop::Diverged);
        }
        if unshot < self.tol {
            return Some(Stop::Converged);
        }
        if unshot < self.best * (1.0 - STALL_DROP) || self.best.is_infinite() {
            self.best = unshot;
            self.since_best = 0;
        } else {
            self.since_best += 1;
            if self.since_best >= self.window {
                return Some(Stop::Stalled);
            }
        }
        (done >= self.max_iter).then_some(Stop::Budget)
    }
}

/// The warning for a solve that stopped before converging, naming the
/// solver, the count, the unshot fraction against the tolerance, the
/// reason, and `culprit` (the object holding the most unshot power);
/// `None` for a converged solve.
pub(crate) fn stop_warning(
    stop: Stop,
    solver: &str,
    iterations: u32,
    unshot: f32,
    tol: f32,
    culprit: Option<&str>,
) -> Option<String> {
    let why = match stop {
        Stop::Converged => return None,
        Stop::Budget => "it reached radiosity.max_iterations",
        Stop::Stalled => {
            "the light still to distribute stopped falling (coincident or duplicated faces, \
             or an albedo of 1 in a closed scene, keep it in play)"
        }
        Stop::Diverged => "the light still to distribute grew without bound",
    };
    let unit = if solver == "progressive" {
        "shots"
    } else {
        "iterations"
    };
    let culprit = culprit
        .map(|c| format!("; most of it is on {c}"))
        .unwrap_or_default();
    let left = if unshot.is_finite() {
        format!("{:.2} %", unshot * 100.0)
    } else {
        "an unbounded share".to_string()
    };
    Some(format!(
        "radiosity did not converge: the {solver} solver stopped after {iterations} {unit} \
         with {left} of the emitted power not yet distributed (tolerance {:.2} %) because \
         {why}{culprit}; the picture shows the solution so far",
        tol * 100.0
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_stop_criterion_cannot_stall() {
        let mut s = Stopper::new(0.01, 1000, 5);
        assert_eq!(s.check(0.5, 0), None);
        assert_eq!(s.check(0.005, 1), Some(Stop::Converged));
        let mut s = Stopper::new(0.01, 1000, 5);
        let stops: Vec<_> = (0..10).map(|i| s.check(0.5, i)).collect();
        assert_eq!(stops[4], None);
        assert_eq!(stops[5], Some(Stop::Stalled));
        let mut s = Stopper::new(0.01, 3, 100);
        assert_eq!(s.check(0.5, 1), None);
        assert_eq!(s.check(0.4, 2), None);
        assert_eq!(s.check(0.3, 3), Some(Stop::Budget));
        assert_eq!(
            Stopper::new(0.01, 9, 9).check(f32::NAN, 1),
            Some(Stop::Diverged)
        );
        let w = stop_warning(
            Stop::Stalled,
            "progressive",
            70,
            0.3,
            0.01,
            Some("object \"m\""),
        )
        .expect("warns");
        assert!(
            w.contains("after 70 shots with 30.00 %") && w.contains("object \"m\""),
            "{w}"
        );
        assert_eq!(
            stop_warning(Stop::Converged, "jacobi", 3, 0.0, 0.01, None),
            None
        );
    }
}
