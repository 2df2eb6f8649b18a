//! The full-matrix solvers (Jacobi, Gauss-Seidel) and progressive
//! refinement (shooting).
//!
//! All of them solve the radiosity equation in *radiance* units (see the
//! crate docs): `L_j = E_j + rho_j sum_i F_ji L_i`, with `E_j` the emitted
//! radiance plus the reflected direct light of point-like lights. The stop
//! criterion is the same for all: the *unshot fraction*
//! `sum_j A_j |dL_j|_1 / sum_j A_j |E_j|_1`, i.e. the power still to be
//! distributed (the last update for the iterative solvers, the unshot
//! radiosity for shooting) over the emitted power.

use crate::formfactor::FormFactor;
use crate::mesh::Element;
use crate::patch::Patches;
use chiaro_core::error::CoreError;
use chiaro_core::progress::{Convergence, Progress};
use glam::Vec3;
use rayon::prelude::*;

/// Largest element count for which a full `N x N` matrix is stored (1 GiB of f32).
pub const MAX_MATRIX_ELEMENTS: usize = 16_384;

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

fn power(elements: &[Element], v: &[Vec3]) -> f32 {
    elements
        .iter()
        .zip(v)
        .map(|(e, x)| e.area * x.abs().element_sum())
        .sum()
}

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
enum Sweep {
    /// Every row from the previous iterate (rows in parallel).
    Jacobi,
    /// Rows in order, in place, so later rows already use the new values
    /// (about twice as fast to converge).
    GaussSeidel,
}

/// Jacobi iteration `L <- E + rho (F L)` from `L = E`.
pub(crate) fn jacobi(
    elements: &[Element],
    e: &[Vec3],
    m: &[f32],
    tol: f32,
    max_iter: u32,
    progress: &dyn Progress,
) -> Result<SolveOutput, CoreError> {
    iterate(elements, e, m, tol, max_iter, progress, Sweep::Jacobi)
}

/// Gauss-Seidel iteration: like [`jacobi`] but each `L_j` is updated in
/// place, so later rows already use the new values (about twice as fast).
pub(crate) fn gauss_seidel(
    elements: &[Element],
    e: &[Vec3],
    m: &[f32],
    tol: f32,
    max_iter: u32,
    progress: &dyn Progress,
) -> Result<SolveOutput, CoreError> {
    iterate(elements, e, m, tol, max_iter, progress, Sweep::GaussSeidel)
}

/// The full-matrix gathering solver behind [`jacobi`] and
/// [`gauss_seidel`]: iterates from `L = E` until the power of an
/// iteration's change falls below `tol` times the emitted power.
fn iterate(
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
    let mut out = SolveOutput {
        l: Vec::new(),
        iterations: 0,
        unshot: 0.0,
    };
    if p0 <= 0.0 {
        out.l = l;
        return Ok(out);
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
    for it in 1..=max_iter {
        if progress.cancelled() {
            return Err(CoreError::Cancelled);
        }
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
        if out.unshot < tol {
            break;
        }
    }
    bar.finish(progress);
    out.l = l;
    Ok(out)
}

/// What one shot of [`progressive`] computes: `shoot(p, unshot, f, g)`
/// writes, for every element `j`, `f[j] = F_{j <- p}` and `g[j] = sum_{i in
/// p} F_{j <- i} dL_i` for the shooting patch `p`.
pub(crate) type Shoot<'a> = dyn Fn(usize, &[Vec3], &mut [f32], &mut [Vec3]) + Sync + 'a;

/// Progressive refinement (Cohen, Chen, Wallace and Greenberg 1988) with
/// patches above elements (Cohen et al. 1986): shoot the unshot radiance
/// of the patch with the most unshot power to every element, until the
/// unshot fraction falls below `tol`. Form factors are computed one shot
/// at a time (no matrix), so memory is O(N). The result includes
/// the paper's ambient correction `rho_j * R * sum_i A_i dL_i / sum_i A_i`,
/// `R = 1 / (1 - rho_avg)`, which estimates the light not yet shot, scaled
/// for open scenes by the measured share of shot light that stays in them.
#[allow(clippy::too_many_arguments)]
pub(crate) fn progressive(
    elements: &[Element],
    patches: &Patches,
    e: &[Vec3],
    shoot: &Shoot<'_>,
    tol: f32,
    max_iter: u32,
    progress: &dyn Progress,
) -> Result<SolveOutput, CoreError> {
    let n = elements.len();
    let p0 = power(elements, e);
    let mut l = e.to_vec();
    let mut unshot = e.to_vec();
    let mut out = SolveOutput {
        l: Vec::new(),
        iterations: 0,
        unshot: 0.0,
    };
    if p0 <= 0.0 {
        out.l = l;
        return Ok(out);
    }
    let mut col = vec![0.0f32; n];
    let mut gathered = vec![Vec3::ZERO; n];
    // Per-element data the per-shot passes read, packed so that a pass over
    // a million elements streams a few bytes per element instead of the
    // whole element; `epow[j]` is the unshot power `A_j sum(dL_j)`, kept up
    // to date by the update.
    let area: Vec<f32> = elements.iter().map(|e| e.area).collect();
    let rho: Vec<Vec3> = elements.iter().map(|e| e.rho).collect();
    let mut epow: Vec<f32> = area
        .iter()
        .zip(&unshot)
        .map(|(a, u)| *a * u.element_sum())
        .collect();
    let (mut shot_power, mut landed_power) = (0.0f32, 0.0f32);
    let mut bar = Convergence::begin(progress, "radiosity progressive", tol);
    out.unshot = 1.0;
    for it in 1..=max_iter {
        if progress.cancelled() {
            return Err(CoreError::Cancelled);
        }
        // The shooter: most unshot power.
        let (mut best, mut best_p, mut total) = (0usize, -1.0f32, 0.0f32);
        for p in 0..patches.len() {
            let pw = match patches.elements(p) {
                [i] => epow[*i as usize],
                m => m.iter().map(|&i| epow[i as usize]).sum(),
            };
            total += pw;
            if pw > best_p {
                (best, best_p) = (p, pw);
            }
        }
        out.unshot = total / p0;
        if out.unshot < tol {
            break;
        }
        shoot(best, &unshot, &mut col, &mut gathered);
        // The share of the shot power that lands on elements: sum_j F_pj =
        // sum_j F_jp A_j / A_p (below 1 where light leaves an open scene).
        let landed: f32 = col.iter().zip(&area).map(|(f, a)| f * a).sum::<f32>()
            / patches.area[best].max(f32::MIN_POSITIVE);
        shot_power += best_p;
        landed_power += best_p * landed.clamp(0.0, 1.0);
        for &i in patches.elements(best) {
            unshot[i as usize] = Vec3::ZERO;
        }
        l.par_iter_mut()
            .zip(unshot.par_iter_mut())
            .zip(epow.par_iter_mut())
            .zip(rho.par_iter().zip(&area))
            .zip(gathered.par_iter())
            .for_each(|((((lj, uj), pj), (r, a)), g)| {
                let d = *r * *g;
                *lj += d;
                *uj += d;
                *pj = *a * uj.element_sum();
            });
        out.iterations = it;
        bar.update(progress, out.unshot);
        if it % 64 == 0 {
            progress.message(&format!(
                "progressive: shot {it}, unshot energy {:.3e}",
                out.unshot
            ));
        }
    }
    bar.finish(progress);
    // Ambient correction (Cohen et al. 1988, section 4), for a scene that
    // keeps the share `c` of shot light measured above (the paper's closed
    // environment has c = 1): each bounce of the unshot light lands with
    // share c, so the reflected total is `rho_j c U / (1 - c rho_avg)`.
    let area: f32 = elements.iter().map(|e| e.area).sum();
    let c = if shot_power > 0.0 {
        landed_power / shot_power
    } else {
        1.0
    };
    if area > 0.0 {
        let rho_avg: Vec3 = elements.iter().map(|e| e.rho * e.area).sum::<Vec3>() / area;
        let unshot_avg: Vec3 = elements
            .iter()
            .zip(&unshot)
            .map(|(e, u)| *u * e.area)
            .sum::<Vec3>()
            / area;
        let r = Vec3::ONE / (Vec3::ONE - c * rho_avg).max(Vec3::splat(1e-3));
        let ambient = c * r * unshot_avg;
        for (lj, el) in l.iter_mut().zip(elements) {
            *lj += el.rho * ambient;
        }
    }
    progress.message(&format!(
        "progressive: {} shots, unshot energy {:.3e}",
        out.iterations, out.unshot
    ));
    out.l = l;
    Ok(out)
}
