//! The signed Sampson residual and its use in Levenberg–Marquardt, shared by the fundamental
//! and relative-pose refinements.
//!
//! With e = p2ᵀ F p1 and d = (F p1)₁² + (F p1)₂² + (Fᵀ p2)₁² + (Fᵀ p2)₂², the residual is
//! r = e / √d (so r² = SD_P, DESIGN.md §3) and
//! ∂r/∂F_mn = p2_m p1_n / √d − e / (2 d^{3/2}) · ∂d/∂F_mn, with
//! ∂d/∂F_mn = 2 (F p1)_m p1_n [m < 2] + 2 (Fᵀ p2)_n p2_m [n < 2].
//! A model with tangent basis ∂F/∂θ_k (k < dof) then has Jacobian rows J_k = ⟨∂r/∂F, ∂F/∂θ_k⟩.

use super::Correspondences;
use crate::refine::{Loss, Mat9, Vec9};
use affcorr_geom::Mat3;

/// r and ∂r/∂F (row-major) of one correspondence.
#[inline(always)]
fn residual_and_gradient(f: &Mat3, x1: [f64; 2], x2: [f64; 2]) -> (f64, [f64; 9]) {
    let p1 = [x1[0], x1[1], 1.0];
    let p2 = [x2[0], x2[1], 1.0];
    let mut l1 = [0.0; 3]; // F p1
    let mut l2 = [0.0; 3]; // Fᵀ p2
    for m in 0..3 {
        for n in 0..3 {
            l1[m] += f[(m, n)] * p1[n];
            l2[n] += f[(m, n)] * p2[m];
        }
    }
    let e = p2[0] * l1[0] + p2[1] * l1[1] + l1[2];
    let d = l1[0] * l1[0] + l1[1] * l1[1] + l2[0] * l2[0] + l2[1] * l2[1];
    if d <= 0.0 {
        return (0.0, [0.0; 9]);
    }
    let inv_sqrt_d = 1.0 / d.sqrt();
    let r = e * inv_sqrt_d;
    let c = r * inv_sqrt_d * inv_sqrt_d; // e / d^{3/2}
    let mut g = [0.0; 9];
    for m in 0..3 {
        for n in 0..3 {
            let mut dd = 0.0;
            if m < 2 {
                dd += l1[m] * p1[n];
            }
            if n < 2 {
                dd += l2[n] * p2[m];
            }
            // ∂d = 2·dd, so the second term is e/(2 d^{3/2})·2·dd = c·dd.
            g[3 * m + n] = p2[m] * p1[n] * inv_sqrt_d - c * dd;
        }
    }
    (r, g)
}

/// Σ ρ(SD_P) over `indices` under `f`.
pub(crate) fn cost(data: &Correspondences, f: &Mat3, indices: &[usize], loss: &Loss) -> f64 {
    indices
        .iter()
        .map(|&i| {
            let (r, _) = residual_and_gradient(
                f,
                [data.x1[i].x, data.x1[i].y],
                [data.x2[i].x, data.x2[i].y],
            );
            loss.cost(r * r)
        })
        .sum()
}

/// Adds JᵀWJ and JᵀWr for the tangent `basis` (∂F/∂θ_k) and returns the cost.
pub(crate) fn normal_equations(
    data: &Correspondences,
    f: &Mat3,
    basis: &[Mat3],
    indices: &[usize],
    loss: &Loss,
    jtj: &mut Mat9,
    jtr: &mut Vec9,
) -> f64 {
    let dof = basis.len();
    let flat: Vec<[f64; 9]> = basis.iter().map(affcorr_geom::types::mat3_to_row).collect();
    let mut cost = 0.0;
    for &i in indices {
        let (r, g) = residual_and_gradient(
            f,
            [data.x1[i].x, data.x1[i].y],
            [data.x2[i].x, data.x2[i].y],
        );
        let s = r * r;
        cost += loss.cost(s);
        let w = loss.weight(s);
        if w == 0.0 {
            continue;
        }
        let mut j = [0.0; 9];
        for k in 0..dof {
            j[k] = (0..9).map(|q| g[q] * flat[k][q]).sum();
        }
        for a in 0..dof {
            jtr[a] += w * j[a] * r;
            for b in 0..=a {
                jtj[(a, b)] += w * j[a] * j[b];
            }
        }
    }
    for a in 0..dof {
        for b in 0..a {
            jtj[(b, a)] = jtj[(a, b)];
        }
    }
    cost
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gradient_matches_central_differences() {
        let f = Mat3::new(1e-6, -3e-5, 0.01, 2e-5, 4e-6, -0.02, -0.012, 0.018, 0.4);
        let (x1, x2) = ([123.0, 456.0], [150.0, 430.0]);
        let (r, g) = residual_and_gradient(&f, x1, x2);
        for q in 0..9 {
            let h = 1e-6 * f[(q / 3, q % 3)].abs().max(1e-6);
            let (mut fp, mut fm) = (f, f);
            fp[(q / 3, q % 3)] += h;
            fm[(q / 3, q % 3)] -= h;
            let fd = (residual_and_gradient(&fp, x1, x2).0 - residual_and_gradient(&fm, x1, x2).0)
                / (2.0 * h);
            assert!(
                (fd - g[q]).abs() < 1e-6 * g[q].abs().max(1.0),
                "F[{q}]: {fd} vs {}",
                g[q]
            );
        }
        // r² is SD_P.
        let sd = affcorr_geom::sampson::sampson_point(
            &f,
            &affcorr_geom::PointCorrespondence {
                x1: x1.into(),
                x2: x2.into(),
            },
        );
        assert!((r * r - sd).abs() < 1e-12 * sd.max(1e-300));
    }
}
