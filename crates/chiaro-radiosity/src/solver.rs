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
