//! Gathering: the full form-factor matrix, solved by Jacobi or Gauss-Seidel
//! iteration (Cohen and Greenberg 1985, "The Hemi-Cube"; Cohen and Wallace,
//! *Radiosity and Realistic Image Synthesis*, 1993, chapter 5).
//!
//! Each iteration gathers, for every element, the light of all others
//! through one row of the matrix; memory is O(N^2), so the matrix is
//! capped at [`MAX_MATRIX_ELEMENTS`]. The equation and the stop criterion
//! are in [`crate::solver`].

use crate::formfactor::FormFactor;
use crate::mesh::Element;
use crate::solver::{STALL_WINDOW, SolveOutput, Stopper, power};
use chiaro_core::error::CoreError;
use chiaro_core::progress::{Convergence, Progress};
use glam::Vec3;
use rayon::prelude::*;

/// Largest element count for which a full `N x N` matrix is stored (1 GiB of f32).
pub const MAX_MATRIX_ELEMENTS: usize = 16_384;

/// The form-factor matrix `m[j * n + i] = F_ji`. Column methods are made
/// exactly reciprocal by averaging the two estimates of each pair:
/// `A_j F_ji = A_i F_ij = (A_j F~_ji + A_i F~_ij) / 2`; row methods (the
/// hemicube) are used as they are (their rows sum to one).
///
/// # Errors
/// [`CoreError::Unsupported`] above [`MAX_MATRIX_ELEMENTS`];
/// [`CoreError::Cancelled`] when the progress asks.
pub(crate) fn build_matrix(
    elements: &[Element],
    ff: &dyn FormFactor,
    progress: &dyn Progress,
) -> Result<Vec<f32>, CoreError> {
    let n = elements.len();
    if n > MAX_MATRIX_ELEMENTS {
        return Err(CoreError::Unsupported(format!(
            "radiosity: {n} elements is too many for a full form-factor matrix \
             (at most {MAX_MATRIX_ELEMENTS}); use solver \"progressive\" or \"hierarchical\", \
             or raise radiosity.patch_size"
        )));
    }
    progress.begin("radiosity form factors", n as u64);
    let mut m = vec![0.0f32; n * n];
    if ff.row(0, &mut m[..n]) {
        // Row methods (hemicube): use the rows as they are, so they sum to one.
        for (j, row) in m.chunks_mut(n).enumerate() {
            if progress.cancelled() {
                return Err(CoreError::Cancelled);
            }
            ff.row(j, row);
            progress.advance(1);
        }
        return Ok(m);
    }
    // k[i * n + j] = A_j F_ji (column i of F scaled to a coupling).
    let mut k = vec![0.0f32; n * n];
    let mut col = vec![0.0f32; n];
    for i in 0..n {
        if progress.cancelled() {
            return Err(CoreError::Cancelled);
        }
        ff.column(i, &mut col);
        for (j, c) in col.iter().enumerate() {
            k[i * n + j] = elements[j].area * c;
        }
        progress.advance(1);
    }
    m.par_chunks_mut(n).enumerate().for_each(|(j, row)| {
        let aj = elements[j].area;
        for (i, r) in row.iter_mut().enumerate() {
            let kij = 0.5 * (k[i * n + j] + k[j * n + i]);
            *r = if aj > 0.0 { kij / aj } else { 0.0 };
        }
    });
    Ok(m)
}

/// How one iteration of `L <- E + rho (F L)` updates `L`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Sweep {
    /// Jacobi: every row from the previous iterate (rows in parallel).
    Jacobi,
    /// Gauss-Seidel: rows in order, in place, so later rows already use
    /// the new values (about twice as fast to converge).
    GaussSeidel,
}

/// The full-matrix gathering solver: Jacobi or Gauss-Seidel iteration
/// (`sweep`) of `L <- E + rho (F L)` from `L = E`, with `m` the matrix of
/// [`build_matrix`], until the power of an iteration's change falls below
/// `tol` times the emitted power or after `max_iter` iterations.
///
/// # Errors
/// [`CoreError::Cancelled`] when the progress asks.
pub(crate) fn iterate(
    elements: &[Element],
    e: &[Vec3],
    m: &[f32],
    tol: f32,
    max_iter: u32,
    progress: &dyn Progress,
    sweep: Sweep,
) -> Result<SolveOutput, CoreError> {
    let n = elements.len();
    let p0 = power(elements, e);
    let mut l = e.to_vec();
    let mut out = SolveOutput::start(Vec::new());
    if p0 <= 0.0 {
        return Ok(SolveOutput::start(l));
    }
    let name = match sweep {
        Sweep::Jacobi => "jacobi",
        Sweep::GaussSeidel => "gauss-seidel",
    };
    let mut bar = Convergence::begin(progress, &format!("radiosity {name}"), tol);
    // Row j of the system: E_j + rho_j sum_i F_ji L_i.
    let gather = |j: usize, l: &[Vec3]| {
        let row = &m[j * n..(j + 1) * n];
        let g: Vec3 = row.iter().zip(l).map(|(f, x)| *f * *x).sum();
        e[j] + elements[j].rho * g
    };
    let mut stopper = Stopper::new(tol, max_iter, STALL_WINDOW);
    for it in 1.. {
        if progress.cancelled() {
            return Err(CoreError::Cancelled);
        }
        let before = l.clone();
        let change = match sweep {
            Sweep::Jacobi => {
                let next: Vec<Vec3> = (0..n).into_par_iter().map(|j| gather(j, &l)).collect();
                let diff: Vec<Vec3> = next.iter().zip(&l).map(|(a, b)| *a - *b).collect();
                l = next;
                power(elements, &diff)
            }
            Sweep::GaussSeidel => {
                let mut change = 0.0f32;
                for j in 0..n {
                    let v = gather(j, &l);
                    change += elements[j].area * (v - l[j]).abs().element_sum();
                    l[j] = v;
                }
                change
            }
        };
        out.unshot = change / p0;
        out.iterations = it;
        bar.update(progress, out.unshot);
        progress.message(&format!(
            "{name}: iteration {it}, residual {:.3e}",
            out.unshot
        ));
        if let Some(stop) = stopper.check(out.unshot, it) {
            out.stop = stop;
            // The element whose radiance changed the most in the last sweep.
            out.worst = (0..n)
                .max_by(|&a, &b| {
                    let d = |j: usize| elements[j].area * (l[j] - before[j]).abs().element_sum();
                    d(a).total_cmp(&d(b))
                })
                .unwrap_or(0);
            break;
        }
    }
    bar.finish(progress);
    out.l = l;
    Ok(out)
}
