//! Helpers shared by the solver tests.

use affcorr_geom::synthetic::gaussian;
use affcorr_geom::{AffineCorrespondence, Mat2, Mat3, Vec2};
use rand::Rng;

/// Distance of the closest candidate to `truth`, both scaled to unit Frobenius norm and
/// sign-aligned.
pub fn best_error(candidates: &[Mat3], truth: &Mat3) -> f64 {
    let t = truth / truth.norm();
    candidates
        .iter()
        .map(|m| {
            let m = m / m.norm();
            (m - t).norm().min((m + t).norm())
        })
        .fold(f64::INFINITY, f64::min)
}

/// The point parts of `acs`.
#[allow(dead_code)]
pub fn points(acs: &[AffineCorrespondence]) -> (Vec<Vec2>, Vec<Vec2>) {
    (
        acs.iter().map(|a| a.x1).collect(),
        acs.iter().map(|a| a.x2).collect(),
    )
}

/// `acs` with Gaussian noise of `pixels` on x1 and x2 and of `affine`·‖A‖ on A's entries.
#[allow(dead_code)]
pub fn perturb<R: Rng>(
    rng: &mut R,
    acs: &[AffineCorrespondence],
    pixels: f64,
    affine: f64,
) -> Vec<AffineCorrespondence> {
    acs.iter()
        .map(|ac| {
            let mut n = *ac;
            n.x1 += Vec2::new(gaussian(rng), gaussian(rng)) * pixels;
            n.x2 += Vec2::new(gaussian(rng), gaussian(rng)) * pixels;
            n.a += Mat2::from_fn(|_, _| gaussian(rng)) * affine * ac.a.norm();
            n
        })
        .collect()
}
