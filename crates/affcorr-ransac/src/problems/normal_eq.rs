//! Normal equations accumulated over the 9 entries of a 3×3 model (F, E or H, row-major) and
//! projected onto the model's tangent basis once, after the data: JᵀWJ = Bᵀ (Σ w g gᵀ) B and
//! JᵀWr = Bᵀ Σ w r g for g = ∂r/∂(entries) and B the basis. Σ w g gᵀ is symmetric, so only its
//! upper triangle (45 sums) is kept while the data are visited.

use crate::refine::{Mat9, Vec9};

/// Σ w r g and the upper triangle (row-major) of Σ w g gᵀ over the residuals added so far.
#[derive(Debug, Clone, Copy)]
pub(crate) struct EntrySums {
    pub g_sum: [f64; 9],
    pub gg: [f64; 45],
}

impl EntrySums {
    pub(crate) fn new() -> Self {
        Self {
            g_sum: [0.0; 9],
            gg: [0.0; 45],
        }
    }

    /// Adds one residual `r` with gradient `g` and weight `w` (the reference the blocked
    /// kernels are tested against).
    #[cfg(test)]
    pub(crate) fn add(&mut self, g: &[f64; 9], w: f64, r: f64) {
        let mut k = 0;
        for a in 0..9 {
            self.g_sum[a] += w * r * g[a];
            let wg = w * g[a];
            for b in a..9 {
                self.gg[k] += wg * g[b];
                k += 1;
            }
        }
    }

    /// Adds Bᵀ G B to `jtj` and Bᵀ g to `jtr` for the flattened (row-major) tangent `basis`
    /// B (its length is the model's degrees of freedom).
    pub(crate) fn project(&self, basis: &[Vec9], jtj: &mut Mat9, jtr: &mut Vec9) {
        let mut full = Mat9::zeros();
        let mut k = 0;
        for a in 0..9 {
            for b in a..9 {
                full[(a, b)] = self.gg[k];
                full[(b, a)] = self.gg[k];
                k += 1;
            }
        }
        let g_sum = Vec9::from_column_slice(&self.g_sum);
        for (a, ba) in basis.iter().enumerate() {
            let ga = full * ba;
            jtr[a] += ba.dot(&g_sum);
            for (b, bb) in basis.iter().enumerate() {
                jtj[(a, b)] += bb.dot(&ga);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_sums_project_to_the_normal_equations_of_the_projected_jacobian() {
        // Three residuals with gradients over the 9 entries, and a 2-dimensional basis:
        // J = G B (rows gᵢᵀ B), so JᵀWJ and JᵀWr computed directly must match.
        let grads = [
            [1.0, -2.0, 0.5, 0.0, 3.0, 1.0, -1.0, 0.25, 2.0],
            [0.0, 1.0, 1.0, -1.5, 0.0, 2.0, 1.0, -0.5, 0.0],
            [2.0, 0.0, -1.0, 1.0, 1.0, 0.0, 0.5, 1.0, -2.0],
        ];
        let (w, r) = ([0.5, 2.0, 1.5], [0.3, -1.2, 0.7]);
        let basis = [
            Vec9::from_column_slice(&[1.0, 0.0, 0.0, 0.5, 0.0, -1.0, 0.0, 2.0, 0.0]),
            Vec9::from_column_slice(&[0.0, 1.0, -1.0, 0.0, 0.25, 0.0, 1.0, 0.0, 3.0]),
        ];
        let mut sums = EntrySums::new();
        for i in 0..3 {
            sums.add(&grads[i], w[i], r[i]);
        }
        let (mut jtj, mut jtr) = (Mat9::zeros(), Vec9::zeros());
        sums.project(&basis, &mut jtj, &mut jtr);
        for a in 0..2 {
            let ja = |i: usize| Vec9::from_column_slice(&grads[i]).dot(&basis[a]);
            let want_r: f64 = (0..3).map(|i| w[i] * r[i] * ja(i)).sum();
            assert!((jtr[a] - want_r).abs() < 1e-12);
            for b in 0..2 {
                let jb = |i: usize| Vec9::from_column_slice(&grads[i]).dot(&basis[b]);
                let want: f64 = (0..3).map(|i| w[i] * ja(i) * jb(i)).sum();
                assert!((jtj[(a, b)] - want).abs() < 1e-12, "({a}, {b})");
            }
        }
        // Only the basis's dof × dof block is touched.
        assert_eq!(jtj[(2, 2)], 0.0);
        assert_eq!(jtr[2], 0.0);
    }
}
