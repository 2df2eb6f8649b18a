//! Progressive refinement (Cohen, Chen, Wallace and Greenberg, "A
//! Progressive Refinement Approach to Fast Radiosity Image Generation",
//! SIGGRAPH 1988): shooting, one patch at a time, with patches above
//! elements (Cohen, Greenberg, Immel and Brock 1986) and the paper's
//! ambient correction. The equation and the stop criterion are in
//! [`crate::solver`].

use crate::mesh::Element;
use crate::patch::Patches;
use crate::solver::{STALL_WINDOW, SolveOutput, Stopper, power};
use chiaro_core::error::CoreError;
use chiaro_core::progress::{Convergence, Progress};
use glam::Vec3;
use rayon::prelude::*;

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
    let mut out = SolveOutput::start(Vec::new());
    if p0 <= 0.0 {
        return Ok(SolveOutput::start(l));
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
    // A shot per patch and then some must lower the unshot power.
    let window = u32::try_from(patches.len())
        .unwrap_or(u32::MAX)
        .saturating_add(STALL_WINDOW);
    let mut stopper = Stopper::new(tol, max_iter, window);
    for it in 1.. {
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
        if let Some(stop) = stopper.check(out.unshot, it - 1) {
            out.stop = stop;
            out.worst = patches.elements(best).first().map_or(0, |&i| i as usize);
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
