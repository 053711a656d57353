//! The signed Sampson residual and its use in Levenberg–Marquardt, shared by the fundamental
//! and relative-pose refinements.
//!
//! With e = p2ᵀ F p1 and d = (F p1)₁² + (F p1)₂² + (Fᵀ p2)₁² + (Fᵀ p2)₂², the residual is
//! r = e / √d (so r² = SD_P, docs/design.md §3) and
//! ∂r/∂F_mn = p2_m p1_n / √d − e / (2 d^{3/2}) · ∂d/∂F_mn, with
//! ∂d/∂F_mn = 2 (F p1)_m p1_n [m < 2] + 2 (Fᵀ p2)_n p2_m [n < 2].
//! A model with tangent basis ∂F/∂θ_k (k < dof) then has Jacobian rows J_k = ⟨∂r/∂F, ∂F/∂θ_k⟩.

use super::Correspondences;
use super::simd::{BLOCK, dispatch, dot};
use crate::loss::Loss;
use crate::refine::{Mat9, Vec9};
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
    // r = 0 and g = 0 where d ≤ 0; a select, not a branch, so that blocks vectorise.
    let inv_sqrt_d = if d > 0.0 { 1.0 / d.sqrt() } else { 0.0 };
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

/// Σ ρ(SD_P) over `indices` under `f`, block by block like [`normal_equations`] (LM calls it
/// once per trial step).
pub(crate) fn cost(data: &Correspondences, f: &Mat3, indices: &[usize], loss: &Loss) -> f64 {
    dispatch(
        #[inline(always)]
        || {
            let mut cost = 0.0;
            let (mut x, mut y, mut u, mut v) =
                ([0.0; BLOCK], [0.0; BLOCK], [0.0; BLOCK], [0.0; BLOCK]);
            let mut s = [0.0; BLOCK];
            for chunk in indices.chunks(BLOCK) {
                for (j, &i) in chunk.iter().enumerate() {
                    (x[j], y[j]) = (data.x1[i].x, data.x1[i].y);
                    (u[j], v[j]) = (data.x2[i].x, data.x2[i].y);
                }
                for j in 0..BLOCK {
                    let (r, _) = residual_and_gradient(f, [x[j], y[j]], [u[j], v[j]]);
                    s[j] = r * r;
                }
                cost += s[..chunk.len()]
                    .iter()
                    .map(|&sj| loss.cost(sj))
                    .sum::<f64>();
            }
            cost
        },
    )
}

/// Adds JᵀWJ and JᵀWr for the tangent `basis` (∂F/∂θ_k) and returns the cost.
///
/// The robust normal equations are accumulated once in the 9 entries of F (G = Σ w g gᵀ, 45
/// distinct products, and Σ w r g) and projected onto the basis at the end: JᵀWJ = Bᵀ G B and
/// JᵀWr = Bᵀ (Σ w r g), cheaper per datum than projecting every gradient (9·dof products) and
/// accumulating dof² terms. The accumulation runs over blocks of [`BLOCK`] data in structure-
/// of-arrays form so that the residuals, gradients and the 54 sums vectorise (4 lanes of f64
/// with AVX2, chosen at run time; 2 with the baseline SSE2).
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
    let mut g_sum = [0.0; 9];
    let mut gg = [0.0; 45];
    let cost = dispatch(
        #[inline(always)]
        || accumulate(data, f, indices, loss, &mut g_sum, &mut gg),
    );
    let mut full = Mat9::zeros();
    let mut k = 0;
    for a in 0..9 {
        for b in a..9 {
            full[(a, b)] = gg[k];
            full[(b, a)] = gg[k];
            k += 1;
        }
    }
    let g_sum = Vec9::from_column_slice(&g_sum);
    let flat: [Vec9; 9] = std::array::from_fn(|k| {
        if k < dof {
            Vec9::from_column_slice(&affcorr_geom::types::mat3_to_row(&basis[k]))
        } else {
            Vec9::zeros()
        }
    });
    for a in 0..dof {
        let ga = full * flat[a];
        jtr[a] += flat[a].dot(&g_sum);
        for b in 0..dof {
            jtj[(a, b)] += flat[b].dot(&ga);
        }
    }
    cost
}

/// Σ ρ(r²) over `indices`, and adds Σ w r g to `g_sum` and the upper triangle of Σ w g gᵀ to
/// `gg` (row-major), block by block: gather, residuals and gradients lane-wise (the formulas of
/// [`residual_and_gradient`]), the loss per datum, then the sums as dot
/// products over the block.
#[inline(always)]
fn accumulate(
    data: &Correspondences,
    f: &Mat3,
    indices: &[usize],
    loss: &Loss,
    g_sum: &mut [f64; 9],
    gg: &mut [f64; 45],
) -> f64 {
    let mut cost = 0.0;
    let (mut x, mut y, mut u, mut v) = ([0.0; BLOCK], [0.0; BLOCK], [0.0; BLOCK], [0.0; BLOCK]);
    let mut r = [0.0; BLOCK];
    let mut g = [[0.0; BLOCK]; 9];
    let (mut w, mut wr) = ([0.0; BLOCK], [0.0; BLOCK]);
    for chunk in indices.chunks(BLOCK) {
        let len = chunk.len();
        for (j, &i) in chunk.iter().enumerate() {
            (x[j], y[j]) = (data.x1[i].x, data.x1[i].y);
            (u[j], v[j]) = (data.x2[i].x, data.x2[i].y);
        }
        for j in 0..BLOCK {
            let (rj, gj) = residual_and_gradient(f, [x[j], y[j]], [u[j], v[j]]);
            r[j] = rj;
            for a in 0..9 {
                g[a][j] = gj[a];
            }
        }
        for j in 0..len {
            let (c, wj) = loss.cost_and_weight(r[j] * r[j]);
            cost += c;
            w[j] = wj;
            wr[j] = wj * r[j];
        }
        // The tail of a short last block (stale but finite values) must not count.
        w[len..].fill(0.0);
        wr[len..].fill(0.0);
        let mut k = 0;
        for a in 0..9 {
            g_sum[a] += dot(&wr, &g[a]);
            let wg: [f64; BLOCK] = std::array::from_fn(|j| w[j] * g[a][j]);
            for b in a..9 {
                gg[k] += dot(&wg, &g[b]);
                k += 1;
            }
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

    #[test]
    fn normal_equations_equal_the_projected_jacobians() {
        let f = Mat3::new(1e-6, -3e-5, 0.01, 2e-5, 4e-6, -0.02, -0.012, 0.018, 0.4);
        let mut data = Correspondences::default();
        for k in 0..30 {
            let t = k as f64;
            data.x1
                .push(affcorr_geom::Vec2::new(10.0 + 17.0 * t, 400.0 - 9.0 * t));
            data.x2.push(affcorr_geom::Vec2::new(
                30.0 + 15.0 * t,
                380.0 - 11.0 * t + (t * 0.7).sin(),
            ));
        }
        let basis = [
            Mat3::new(1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
            Mat3::new(0.0, 0.3, 0.0, -0.2, 0.0, 0.0, 0.0, 0.0, 0.1),
            Mat3::new(0.0, 0.0, 1e-3, 0.0, 0.5, 0.0, 0.2, 0.0, 0.0),
        ];
        let idx: Vec<usize> = (0..30).collect();
        let loss = Loss::Cauchy { scale_sq: 2.0 };
        let (mut jtj, mut jtr) = (Mat9::zeros(), Vec9::zeros());
        let cost = normal_equations(&data, &f, &basis, &idx, &loss, &mut jtj, &mut jtr);
        let (mut ejtj, mut ejtr, mut ecost) = (Mat9::zeros(), Vec9::zeros(), 0.0);
        for &i in &idx {
            let (r, g) = residual_and_gradient(
                &f,
                [data.x1[i].x, data.x1[i].y],
                [data.x2[i].x, data.x2[i].y],
            );
            let w = loss.weight(r * r);
            ecost += loss.cost(r * r);
            let j: Vec<f64> = basis
                .iter()
                .map(|b| (0..9).map(|q| g[q] * b[(q / 3, q % 3)]).sum())
                .collect();
            for a in 0..3 {
                ejtr[a] += w * j[a] * r;
                for b in 0..3 {
                    ejtj[(a, b)] += w * j[a] * j[b];
                }
            }
        }
        assert!((cost - ecost).abs() < 1e-12 * ecost);
        assert!((jtj - ejtj).norm() < 1e-10 * ejtj.norm(), "{jtj} vs {ejtj}");
        assert!((jtr - ejtr).norm() < 1e-10 * ejtr.norm().max(1e-300));
        // The baseline build of the kernel (the one non-AVX2 CPUs run) agrees with the
        // dispatched one, short last block included (30 = 16 + 14).
        let (mut s1, mut g1, mut s2, mut g2) = ([0.0; 9], [0.0; 45], [0.0; 9], [0.0; 45]);
        let c1 = accumulate(&data, &f, &idx, &loss, &mut s1, &mut g1);
        let c2 = dispatch(|| accumulate(&data, &f, &idx, &loss, &mut s2, &mut g2));
        assert!((c1 - c2).abs() < 1e-12 * c1);
        for (a, b) in s1.iter().zip(&s2).chain(g1.iter().zip(&g2)) {
            assert!((a - b).abs() <= 1e-12 * a.abs().max(1e-300), "{a} vs {b}");
        }
    }
}
