//! Essential and fundamental matrices, and relative pose (docs/design.md §2).
//!
//! - Motion: X2 = R X1 + t. Then E = \[t\]× R and p̂2ᵀ E p̂1 = 0 for normalised points.
//! - F = K2⁻ᵀ E K1⁻¹, so p2ᵀ F p1 = 0 in pixels.
//! - E = U diag(1, 1, 0) Vᵀ has four (R, t) factorisations (Hartley & Zisserman, Result 9.19):
//!   R ∈ {U W Vᵀ, U Wᵀ Vᵀ}, t = ±u₃. Cheirality (points in front of both cameras) picks one.

use crate::camera::Intrinsics;
use crate::error::{GeomError, Result};
use crate::types::{Mat3, Vec2, Vec3, max_abs, power_of_two_normalizer};

/// A relative pose: X2 = R X1 + t.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    /// Rotation.
    pub r: Mat3,
    /// Translation (unit norm when it comes from an essential matrix).
    pub t: Vec3,
}

impl Pose {
    /// E = \[t\]× R.
    pub fn essential(&self) -> Mat3 {
        essential_from_pose(&self.r, &self.t)
    }
}

/// The cross-product matrix: `skew(t) * v = t × v`.
#[inline]
pub fn skew(t: &Vec3) -> Mat3 {
    Mat3::new(0.0, -t.z, t.y, t.z, 0.0, -t.x, -t.y, t.x, 0.0)
}

/// E = \[t\]× R.
#[inline]
pub fn essential_from_pose(r: &Mat3, t: &Vec3) -> Mat3 {
    skew(t) * r
}

/// F = K2⁻ᵀ E K1⁻¹.
pub fn fundamental_from_essential(e: &Mat3, k1: &Intrinsics, k2: &Intrinsics) -> Mat3 {
    k2.inverse().transpose() * e * k1.inverse()
}

/// E = K2ᵀ F K1.
pub fn essential_from_fundamental(f: &Mat3, k1: &Intrinsics, k2: &Intrinsics) -> Mat3 {
    k2.matrix().transpose() * f * k1.matrix()
}

/// The four (R, t) factorisations of `e`, with unit t, in the order
/// (U W Vᵀ, u₃), (U W Vᵀ, −u₃), (U Wᵀ Vᵀ, u₃), (U Wᵀ Vᵀ, −u₃).
///
/// A noisy `e` (rank 3, unequal singular values) is read through its SVD, which amounts to
/// projecting it onto the essential manifold first.
pub fn decompose_essential(e: &Mat3) -> Result<[Pose; 4]> {
    if e.iter().any(|v| !v.is_finite()) {
        return Err(GeomError::NonFinite {
            what: "E",
            index: 0,
        });
    }
    // R and t do not depend on E's scale: factor E · r (r a power of two, exact) so that the
    // SVD neither overflows for huge E nor loses a tiny one to underflow.
    let e = e * power_of_two_normalizer(max_abs(e.iter()));
    let svd = e.svd(true, true);
    let (mut u, mut v_t) = (svd.u.unwrap(), svd.v_t.unwrap());
    // nalgebra's SVD does not sort singular values: bring the smallest to the last column.
    let s = svd.singular_values;
    let k = (0..3).min_by(|&a, &b| s[a].total_cmp(&s[b])).unwrap();
    if s.max() == 0.0 {
        return Err(GeomError::Degenerate {
            what: "E",
            reason: "it is zero",
        });
    }
    if k != 2 {
        u.swap_columns(k, 2);
        v_t.swap_rows(k, 2);
    }
    // Proper rotations: flipping the sign of the null vectors changes neither E's null spaces
    // nor the factorisation's validity.
    if u.determinant() < 0.0 {
        u.column_mut(2).neg_mut();
    }
    if v_t.determinant() < 0.0 {
        v_t.row_mut(2).neg_mut();
    }
    let w = Mat3::new(0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0);
    let r1 = u * w * v_t;
    let r2 = u * w.transpose() * v_t;
    let t: Vec3 = u.column(2).into_owned();
    Ok([
        Pose { r: r1, t },
        Pose { r: r1, t: -t },
        Pose { r: r2, t },
        Pose { r: r2, t: -t },
    ])
}

/// Depths (λ1, λ2) of the point seen at normalised x1, x2 under `pose`, from the least-squares
/// solution of λ2·x̂2 = λ1·R·x̂1 + t (the midpoint form, exact for noise-free data).
/// Returns `None` when the rays are parallel.
#[inline]
pub fn triangulate_depths(pose: &Pose, x1: &Vec2, x2: &Vec2) -> Option<(f64, f64)> {
    let a = pose.r * Vec3::new(x1.x, x1.y, 1.0);
    let b = Vec3::new(x2.x, x2.y, 1.0);
    // Normal equations of min ‖λ1 a − λ2 b + t‖².
    let (aa, ab, bb) = (a.dot(&a), a.dot(&b), b.dot(&b));
    let (at, bt) = (a.dot(&pose.t), b.dot(&pose.t));
    let det = aa * bb - ab * ab;
    if det <= 1e-14 * aa * bb {
        return None;
    }
    let l1 = (ab * bt - bb * at) / det;
    let l2 = (aa * bt - ab * at) / det;
    Some((l1, l2))
}

/// Where the point seen at normalised x1, x2 lies under a pose ([`cheirality`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Cheirality {
    /// In front of both cameras: both depths of [`triangulate_depths`] positive.
    InFront,
    /// Behind either camera.
    Behind,
    /// The rays are parallel (a point at infinity): [`triangulate_depths`] gives `None`.
    Parallel,
}

/// The signs of [`triangulate_depths`]' depths without its divisions: they share the positive
/// determinant of the normal equations, so each depth has its numerator's sign. Without
/// divisions, and its three outcomes are selects, so that loops over many correspondences
/// vectorise.
///
/// ```
/// use affcorr_geom::{Mat3, Vec2, Vec3, epipolar::{Cheirality, Pose, cheirality}};
/// let pose = Pose { r: Mat3::identity(), t: Vec3::new(1.0, 0.0, 0.0) };
/// // A point at (0, 0, 4) in camera 1 is at (1, 0, 4) in camera 2; at (0, 0, -4), behind.
/// assert_eq!(cheirality(&pose, &Vec2::zeros(), &Vec2::new(0.25, 0.0)), Cheirality::InFront);
/// assert_eq!(cheirality(&pose, &Vec2::zeros(), &Vec2::new(-0.25, 0.0)), Cheirality::Behind);
/// assert_eq!(cheirality(&pose, &Vec2::zeros(), &Vec2::zeros()), Cheirality::Parallel);
/// ```
#[inline(always)]
pub fn cheirality(pose: &Pose, x1: &Vec2, x2: &Vec2) -> Cheirality {
    let a = pose.r * Vec3::new(x1.x, x1.y, 1.0);
    let b = Vec3::new(x2.x, x2.y, 1.0);
    let (aa, ab, bb) = (a.dot(&a), a.dot(&b), b.dot(&b));
    let (at, bt) = (a.dot(&pose.t), b.dot(&pose.t));
    let det = aa * bb - ab * ab;
    let (n1, n2) = (ab * bt - bb * at, aa * bt - ab * at);
    if det <= 1e-14 * aa * bb {
        Cheirality::Parallel
    } else if n1 > 0.0 && n2 > 0.0 {
        Cheirality::InFront
    } else {
        Cheirality::Behind
    }
}

/// Number of correspondences (normalised coordinates) in front of both cameras under `pose`.
pub fn count_in_front(pose: &Pose, x1: &[Vec2], x2: &[Vec2]) -> usize {
    x1.iter()
        .zip(x2)
        .map(|(a, b)| usize::from(cheirality(pose, a, b) == Cheirality::InFront))
        .sum()
}

/// The factorisation of `e` that puts the most correspondences in front of both cameras.
///
/// ```
/// use affcorr_geom::{Mat3, Vec2, Vec3, epipolar::{Pose, pose_from_essential}};
/// let truth = Pose { r: Mat3::identity(), t: Vec3::new(1.0, 0.0, 0.0) };
/// // A point at (0, 0, 4) in camera 1 is at (1, 0, 4) in camera 2.
/// let (x1, x2) = (vec![Vec2::new(0.0, 0.0)], vec![Vec2::new(0.25, 0.0)]);
/// let (pose, n) = pose_from_essential(&truth.essential(), &x1, &x2).unwrap();
/// assert_eq!(n, 1);
/// assert!((pose.r - truth.r).norm() < 1e-12 && (pose.t - truth.t).norm() < 1e-12);
/// ```
/// Returns the pose and that count. Ties go to the first candidate in
/// [`decompose_essential`]'s order.
pub fn pose_from_essential(e: &Mat3, x1: &[Vec2], x2: &[Vec2]) -> Result<(Pose, usize)> {
    if x1.len() != x2.len() {
        return Err(GeomError::LengthMismatch {
            what: "x2",
            expected: x1.len(),
            got: x2.len(),
        });
    }
    // A NaN point is never "in front", so it would silently lower the counts.
    for (what, pts) in [("x1", x1), ("x2", x2)] {
        if let Some(index) = pts
            .iter()
            .position(|p| !(p.x.is_finite() && p.y.is_finite()))
        {
            return Err(GeomError::NonFinite { what, index });
        }
    }
    let candidates = decompose_essential(e)?;
    let mut best = (candidates[0], 0);
    for pose in candidates {
        let n = count_in_front(&pose, x1, x2);
        if n > best.1 {
            best = (pose, n);
        }
    }
    Ok(best)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synthetic::{random_pose, random_rotation};
    use rand::SeedableRng;

    #[test]
    fn decomposition_contains_the_true_pose_and_cheirality_finds_it() {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(1);
        for _ in 0..200 {
            let truth = random_pose(&mut rng);
            let e = truth.essential();
            let cands = decompose_essential(&e).unwrap();
            let t_unit = truth.t.normalize();
            let hits = cands
                .iter()
                .filter(|p| (p.r - truth.r).norm() < 1e-10 && (p.t - t_unit).norm() < 1e-10)
                .count();
            assert_eq!(hits, 1);
            for p in &cands {
                assert!((p.r.determinant() - 1.0).abs() < 1e-12);
                // Every candidate reproduces E up to sign and scale.
                let ep = p.essential();
                let s = e.norm() / ep.norm();
                assert!((ep * s - e).norm().min((ep * s + e).norm()) < 1e-10 * e.norm());
            }
            // Points in front of camera 1 at depths 2..6.
            let mut x1 = Vec::new();
            let mut x2 = Vec::new();
            for i in 0..10 {
                let xw = Vec3::new(
                    0.1 * i as f64 - 0.5,
                    0.05 * i as f64 - 0.2,
                    2.0 + 0.4 * i as f64,
                );
                let xc2 = truth.r * xw + truth.t;
                if xc2.z > 0.0 {
                    x1.push(Vec2::new(xw.x / xw.z, xw.y / xw.z));
                    x2.push(Vec2::new(xc2.x / xc2.z, xc2.y / xc2.z));
                }
            }
            let (pose, n) = pose_from_essential(&e, &x1, &x2).unwrap();
            assert_eq!(n, x1.len());
            assert!((pose.r - truth.r).norm() < 1e-10 && (pose.t - t_unit).norm() < 1e-10);
        }
        let _ = random_rotation(&mut rng);
    }

    #[test]
    fn fundamental_and_essential_convert_both_ways() {
        let k1 = Intrinsics::from_focal(800.0, 700.0, 320.0, 240.0).unwrap();
        let k2 = Intrinsics::from_focal(600.0, 650.0, 300.0, 200.0).unwrap();
        let mut rng = rand_pcg::Pcg64::seed_from_u64(2);
        let e = random_pose(&mut rng).essential();
        let f = fundamental_from_essential(&e, &k1, &k2);
        assert!((essential_from_fundamental(&f, &k1, &k2) - e).norm() < 1e-12);
    }

    #[test]
    fn degenerate_essential_is_an_error() {
        assert!(decompose_essential(&Mat3::zeros()).is_err());
        assert!(decompose_essential(&Mat3::from_element(f64::NAN)).is_err());
    }
}
