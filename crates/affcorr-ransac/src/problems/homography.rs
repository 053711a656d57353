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
}
