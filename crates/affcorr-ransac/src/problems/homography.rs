//! Homography estimation, p2 ~ H p1 in pixels.
//!
//! - Minimal samples: 4 points ([`homography_4pt`]) or 2 ACs ([`homography_2ac`]).
//! - Non-minimal fit (local optimisation): the normalised DLT on the inliers
//!   ([`homography_lsq`]), or on their ACs when fewer than 4.
//! - Residual (px²): the transfer error ‖x2 − π(H p1)‖², plus, with `affine_weight` λ > 0,
//!   λ·‖A − A_H(x1)‖²_F, where A_H(x1) is the AC H induces (DESIGN.md §2). λ is in px²: with
//!   λ = ρ²/2 the affine term is the mean squared displacement of a circle of radius ρ px mapped
//!   by A instead of A_H.

use super::{Correspondences, SampleKind};
use crate::problem::Problem;
use crate::refine::{LeastSquares, LmOptions, Loss, Mat9, Vec9, levenberg_marquardt};
use affcorr_geom::{AffineCorrespondence, Mat2, Mat3, Vec2};
use affcorr_solvers::homography::{
    homography_2ac, homography_4pt, homography_ac_lsq, homography_lsq,
};

/// A homography problem over a set of correspondences.
pub struct HomographyProblem<'a> {
    data: &'a Correspondences,
    kind: SampleKind,
    affine_weight: f64,
}

impl<'a> HomographyProblem<'a> {
    /// `data` sampled as `kind`, scored with `affine_weight` λ (0: points only). The caller has
    /// validated that affine samples/weights come with affine data.
    pub fn new(data: &'a Correspondences, kind: SampleKind, affine_weight: f64) -> Self {
        Self {
            data,
            kind,
            affine_weight,
        }
    }
}

/// Squared transfer error of one point and the projected point's homogeneous scale.
#[inline(always)]
fn transfer(h: &Mat3, x1: &Vec2, x2: &Vec2) -> (f64, Vec2, f64) {
    let w = h[(2, 0)] * x1.x + h[(2, 1)] * x1.y + h[(2, 2)];
    let inv_w = 1.0 / w;
    let u = (h[(0, 0)] * x1.x + h[(0, 1)] * x1.y + h[(0, 2)]) * inv_w;
    let v = (h[(1, 0)] * x1.x + h[(1, 1)] * x1.y + h[(1, 2)]) * inv_w;
    let (du, dv) = (u - x2.x, v - x2.y);
    (du * du + dv * dv, Vec2::new(u, v), inv_w)
}

impl Problem for HomographyProblem<'_> {
    type Model = Mat3;

    fn len(&self) -> usize {
        self.data.len()
    }

    fn sample_size(&self) -> usize {
        match self.kind {
            SampleKind::Points => 4,
            SampleKind::Affine => 2,
        }
    }

    fn fit_minimal(&self, sample: &[usize], out: &mut Vec<Mat3>) {
        let mut h = [Mat3::zeros(); 1];
        let n = match self.kind {
            SampleKind::Points => {
                let x1: [Vec2; 4] = std::array::from_fn(|k| self.data.x1[sample[k]]);
                let x2: [Vec2; 4] = std::array::from_fn(|k| self.data.x2[sample[k]]);
                homography_4pt(&x1, &x2, &mut h)
            }
            SampleKind::Affine => {
                let acs: [AffineCorrespondence; 2] =
                    std::array::from_fn(|k| self.data.ac(sample[k]));
                homography_2ac(&acs, &mut h)
            }
        };
        out.extend_from_slice(&h[..n]);
    }

    fn fit_nonminimal(&self, indices: &[usize], _weights: Option<&[f64]>) -> Option<Mat3> {
        let mut h = [Mat3::zeros(); 1];
        let n = if indices.len() >= 4 {
            let x1: Vec<Vec2> = indices.iter().map(|&i| self.data.x1[i]).collect();
            let x2: Vec<Vec2> = indices.iter().map(|&i| self.data.x2[i]).collect();
            homography_lsq(&x1, &x2, &mut h)
        } else if self.data.has_affine() {
            let acs: Vec<AffineCorrespondence> = indices.iter().map(|&i| self.data.ac(i)).collect();
            homography_ac_lsq(&acs, &mut h)
        } else {
            0
        };
        (n == 1).then_some(h[0])
    }

    fn residuals(&self, h: &Mat3, start: usize, out: &mut [f64]) {
        let end = start + out.len();
        let (x1, x2) = (&self.data.x1[start..end], &self.data.x2[start..end]);
        if self.affine_weight == 0.0 {
            for ((o, p), q) in out.iter_mut().zip(x1).zip(x2) {
                *o = transfer(h, p, q).0;
            }
            return;
        }
        let a = &self.data.a[start..end];
        for (k, o) in out.iter_mut().enumerate() {
            let (r2, x2h, inv_w) = transfer(h, &x1[k], &x2[k]);
            // A_H(x1) = (H[0:2,0:2] − x2·H[2,0:2]) / w at the projected x2.
            let a_h = Mat2::new(
                h[(0, 0)] - x2h.x * h[(2, 0)],
                h[(0, 1)] - x2h.x * h[(2, 1)],
                h[(1, 0)] - x2h.y * h[(2, 0)],
                h[(1, 1)] - x2h.y * h[(2, 1)],
            ) * inv_w;
            *o = r2 + self.affine_weight * (a[k] - a_h).norm_squared();
        }
    }

    /// Levenberg–Marquardt of the transfer error on the unit sphere of H (8 degrees of freedom).
    fn refine(
        &self,
        model: &Mat3,
        inliers: &[usize],
        loss: &Loss,
        max_iterations: usize,
    ) -> Option<Mat3> {
        let h = model / model.norm();
        let options = LmOptions {
            max_iterations,
            ..Default::default()
        };
        Some(levenberg_marquardt(self, &h, inliers, loss, &options).0)
    }
}

/// An orthonormal basis of the tangent space of the unit sphere at vec(H): the last 8 columns of
/// the Householder reflection that maps vec(H) to ±e₁.
fn tangent_basis(h: &Mat3) -> [Vec9; 8] {
    let v = Vec9::from_iterator((0..9).map(|k| h[(k / 3, k % 3)]));
    let sign = if v[0] >= 0.0 { 1.0 } else { -1.0 };
    let mut u = v;
    u[0] += sign * v.norm();
    let uu = u.norm_squared();
    std::array::from_fn(|c| {
        // Column c + 1 of I − 2uuᵀ/uᵀu.
        let mut col = u * (-2.0 * u[c + 1] / uu);
        col[c + 1] += 1.0;
        col
    })
}

/// Transfer error r = π(H p1) − x2 (2 residuals per datum); ∂u/∂h₁ = p1/w, ∂u/∂h₃ = −u p1/w,
/// ∂v/∂h₂ = p1/w, ∂v/∂h₃ = −v p1/w, accumulated in the 9 entries of H and projected onto the
/// tangent basis once.
impl LeastSquares for HomographyProblem<'_> {
    type Model = Mat3;

    fn dof(&self) -> usize {
        8
    }

    fn cost(&self, h: &Mat3, indices: &[usize], loss: &Loss) -> f64 {
        indices
            .iter()
            .map(|&i| loss.cost(transfer(h, &self.data.x1[i], &self.data.x2[i]).0))
            .sum()
    }

    fn normal_equations(
        &self,
        h: &Mat3,
        indices: &[usize],
        loss: &Loss,
        jtj: &mut Mat9,
        jtr: &mut Vec9,
    ) -> f64 {
        let (mut a, mut g) = (Mat9::zeros(), Vec9::zeros());
        let mut cost = 0.0;
        for &i in indices {
            let (x1, x2) = (&self.data.x1[i], &self.data.x2[i]);
            let (r2, proj, inv_w) = transfer(h, x1, x2);
            cost += loss.cost(r2);
            let w = loss.weight(r2);
            if w == 0.0 {
                continue;
            }
            let p = [x1.x * inv_w, x1.y * inv_w, inv_w];
            let mut ju = [0.0; 9];
            let mut jv = [0.0; 9];
            for k in 0..3 {
                ju[k] = p[k];
                jv[3 + k] = p[k];
                ju[6 + k] = -proj.x * p[k];
                jv[6 + k] = -proj.y * p[k];
            }
            let (ru, rv) = (proj.x - x2.x, proj.y - x2.y);
            for r in 0..9 {
                g[r] += w * (ju[r] * ru + jv[r] * rv);
                for c in 0..=r {
                    a[(r, c)] += w * (ju[r] * ju[c] + jv[r] * jv[c]);
                }
            }
        }
        for r in 0..9 {
            for c in 0..r {
                a[(c, r)] = a[(r, c)];
            }
        }
        let basis = tangent_basis(h);
        for r in 0..8 {
            let ab = a * basis[r];
            jtr[r] += basis[r].dot(&g);
            for c in 0..8 {
                jtj[(r, c)] += basis[c].dot(&ab);
            }
        }
        cost
    }

    fn retract(&self, h: &Mat3, delta: &Vec9) -> Mat3 {
        let basis = tangent_basis(h);
        let mut v = Vec9::from_iterator((0..9).map(|k| h[(k / 3, k % 3)]));
        for k in 0..8 {
            v += basis[k] * delta[k];
        }
        let v = v / v.norm();
        Mat3::from_fn(|r, c| v[3 * r + c])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use affcorr_geom::synthetic::{NoiseModel, PlaneScene, noisy_correspondences};
    use rand::SeedableRng;

    #[test]
    fn tangent_basis_is_orthonormal_and_tangent() {
        let h = Mat3::new(0.7, -0.3, 225.0, 0.33, 1.01, -77.0, 3e-4, -1e-5, 1.0);
        let h = h / h.norm();
        let v = Vec9::from_iterator((0..9).map(|k| h[(k / 3, k % 3)]));
        let b = tangent_basis(&h);
        for i in 0..8 {
            assert!(b[i].dot(&v).abs() < 1e-14);
            for j in 0..8 {
                let expected = if i == j { 1.0 } else { 0.0 };
                assert!((b[i].dot(&b[j]) - expected).abs() < 1e-14);
            }
        }
    }

    #[test]
    fn refinement_lowers_the_transfer_error_of_the_linear_fit() {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(5);
        let scene = PlaneScene::random(&mut rng);
        let noise = NoiseModel {
            planes: 1,
            outlier_ratio: 0.0,
            pixel_noise: 1.0,
            affine_noise: 0.0,
        };
        let (acs, _) = noisy_correspondences(&mut rng, &scene, 200, &noise);
        let rows: Vec<[f64; 8]> = acs.iter().map(|a| a.to_row()).collect();
        let data = Correspondences::from_ac_rows(&rows).unwrap();
        let problem = HomographyProblem::new(&data, SampleKind::Points, 0.0);
        let all: Vec<usize> = (0..200).collect();
        let linear = problem.fit_nonminimal(&all, None).unwrap();
        let refined = problem.refine(&linear, &all, &Loss::Squared, 50).unwrap();
        let (c0, c1) = (
            problem.cost(&linear, &all, &Loss::Squared),
            problem.cost(&refined, &all, &Loss::Squared),
        );
        assert!(c1 < c0, "{c1} vs {c0}");
        // The geometric optimum leaves ~χ²(2N − 8)·σ² of residual: about 392 px² here.
        assert!(c1 > 300.0 && c1 < 500.0, "{c1}");
        assert!((refined.norm() - 1.0).abs() < 1e-12);
    }
}
